"""Cycle time against LinuxCNC 2.9 on the same INI, counted in servo periods on both sides.

    .venv/bin/python benchmarks/linuxcnc.py                       # hard programs, then short ones
    .venv/bin/python benchmarks/linuxcnc.py zigzag_0.002_0.001 bezel   # programs by name substring
    .venv/bin/python benchmarks/linuxcnc.py --max-cycle 60 --budget 900 --json out.json
    .venv/bin/python benchmarks/linuxcnc.py --no-write            # print only
    .venv/bin/python benchmarks/linuxcnc.py --linuxcnc-from old.json   # new cnc-interp, same LinuxCNC
    .venv/bin/python benchmarks/linuxcnc.py --same-tolerance      # every G64 held to 1 µm

Each corpus program (``CNC_CORPUS``) runs on a LinuxCNC configuration made from a corpus INI
(``--ini``, default ``configs/axis_mm.ini``; ``XYZ.ini`` (XYZA), then ``9axis.ini``, for a
program that names an axis it lacks). The configuration is written in LinuxCNC 2.9's form
(``[KINS]``, ``[JOINT_n]``, ``[AXIS_L]``) with the corpus INI's ``[TRAJ]`` section and its axes'
velocity, acceleration and soft limits, ``SERVO_PERIOD = 1000000`` (1 ms), joints that home
at once where they stand (position 0, which is also cnc-interp's start), no tool-change
position (M6 moves nothing), a stand-in tool table (tools 1-99, zero length, as
``plan.py``'s sweep) and ``MAX_JERK = 1e6`` (machine units/s^3) in every axis and joint
section. LinuxCNC 2.9 has no jerk limit and ignores the key; cnc-interp reads it.

The program runs from a copy whose first line puts ``G64 P0.001`` (mm; on an inch INI ``G20``
and the same 1 µm in inch, since LinuxCNC starts in the INI's units and cnc-interp in mm) in
force; the program's own G64/G61 words then apply as written, on both sides, except that
cnc-interp caps every move's tolerance at ``--tol``: a G64 P over 1 µm holds in LinuxCNC only,
and a G64 without P is LinuxCNC's "no tolerance" but ``--tol`` in cnc-interp. The table names
each program's own G64/G61 words. ``--same-tolerance`` compares the same path on both sides:
every G64 of the program (with or without P and Q) is rewritten to ``G64 P<1 µm>`` in the
units in force there (``at_tolerance``), and the table goes to a section of its own.

LinuxCNC side: ``linuxcnc`` runs headless: the HAL is a simulation (``motmod`` on trivkins,
each joint's position command looped to its feedback, E-stop and tool change looped back,
as LinuxCNC's ``core_sim.hal``), and the display is ``_linuxcnc_display.py`` (system python,
``linuxcnc`` module): it leaves E-stop, homes, runs the program in auto mode, resumes pauses
(M0, M60; M1's optional stop is off), waits until the interpreter is idle, the queue empty and
the machine in position, and exits, which shuts LinuxCNC down. A ``sampler`` on the servo thread
records every period's joint position commands (``joint.N.pos-cmd``), read by ``halsampler``
(6 decimals, machine units) with sample numbers, so a missed period is detected.

cnc-interp side: the same INI and program copy, ``--tol 0.001``, dt 1 ms, planners ``vpop``
and ``optimal`` (the default), through ``pipeline.plan_part``; its setpoints are rounded to
6 decimals of machine units as halsampler prints LinuxCNC's.

The cycle on both sides is the moving span: the periods from the first period whose position
differs from the one before to the last such period, inclusive, times the 1 ms period.
Dwells, stops and tool changes between moves count as they come; rest before the first
move and after the last does not. cnc-interp models no time for an M6 or M0 (the machine is
at rest for the samples its timeline holds between motions); LinuxCNC's tool change is
looped back in HAL, so it takes the task's handshake only, and the display's resume after a
pause takes up to a poll (2 ms) more. Both are counted as they fall in LinuxCNC.

LinuxCNC runs in real time, so programs whose cnc-interp vpop cycle is longer than
``--max-cycle`` are skipped, and no program is started once LinuxCNC's wall time reaches
``--budget``. The programs the project knows are hard (``HARD``) run first, then the rest
shortest first. A program that LinuxCNC or cnc-interp refuses is listed with its error.
``--linuxcnc-from`` takes LinuxCNC's results from an earlier run's ``--json`` (they do not depend
on cnc-interp's code) and runs LinuxCNC only for programs it lacks.
Every LinuxCNC process of a run is in its own process group, which is ended (then
``halrun -U``) after each program, on a timeout and on Ctrl-C.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np
from _results import command_line, md_table, write_section
from plan import AXIS_FALLBACK_INIS, CORPUS, corpus_programs, standin_tool_table

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from cnc_interp.constants import MM_PER_INCH  # noqa: E402  (after the path above)

HERE = os.path.dirname(os.path.abspath(__file__))
CONFIGS = os.path.join(CORPUS, "configs")
DISPLAY = os.path.join(HERE, "_linuxcnc_display.py")
#: the python that has LinuxCNC's ``linuxcnc`` module (Debian's linuxcnc-uspace)
SYSTEM_PYTHON = "/usr/bin/python3"

#: servo period of the LinuxCNC configuration (ns) and cnc-interp's dt (s): one sample each
SERVO_PERIOD_NS = 1_000_000
DT_S = SERVO_PERIOD_NS * 1e-9
#: cnc-interp's jerk limit on every axis (machine units/s^3): "no jerk limit" as LinuxCNC 2.9
JERK_UNITS_S3 = 1e6
#: fit tolerance (mm) and the G64 P the program copy starts with (the same 1 µm)
TOL_MM = 0.001
#: halsampler prints floats with %f: positions are compared on this grid (machine units)
POSITION_DECIMALS = 6
#: skip programs whose cnc-interp vpop cycle is longer (s): LinuxCNC runs in real time
DEFAULT_MAX_CYCLE_S = 120.0
#: stop starting LinuxCNC runs once their wall time adds up to this (s)
DEFAULT_BUDGET_S = 1800.0
#: LinuxCNC's time limit per program: this multiple of cnc-interp's vpop cycle, plus the margin (s)
LINUXCNC_TIMEOUT_FACTOR = 3.0
LINUXCNC_TIMEOUT_MARGIN_S = 60.0
#: sampler FIFO depth (samples): halsampler drains it continuously
SAMPLER_DEPTH = 65536
#: the programs the project knows are hard, run first (name substrings)
HARD = ("zigzag_0.002_0.001", "tight-corner-tolerance", "bezel_ex_37tick")
#: left out by default: a 4.5-hour cycle whose plan at 1 µm alone takes minutes
DEFAULT_EXCLUDE = ("stellabee1",)
ALL_AXES = "XYZABCUVW"
PLANNERS = ("vpop", "optimal")
#: [TRAJ] keys of the corpus INI not copied: LinuxCNC 2.9 derives or ignores them here
TRAJ_DROPPED = ("AXES", "HOME", "POSITION_FILE")
#: [AXIS_n] keys copied into the 2.9 axis and joint sections
AXIS_KEYS = ("MAX_VELOCITY", "MAX_ACCELERATION", "MIN_LIMIT", "MAX_LIMIT")
JOINT_KEYS = ("TYPE", "FERROR", "MIN_FERROR", "BACKLASH")


# --- the configuration --------------------------------------------------------------------
def read_ini(path: str) -> dict[str, list[tuple[str, str]]]:
    """Sections of a LinuxCNC INI as ordered (key, value) lists (keys may repeat)."""
    out: dict[str, list[tuple[str, str]]] = {}
    sec = None
    with open(path, encoding="latin-1") as fh:
        for raw in fh:
            line = raw.strip()
            if not line or line[0] in "#;":
                continue
            if line.startswith("[") and line.endswith("]"):
                sec = line[1:-1].strip()
                out.setdefault(sec, [])
            elif sec is not None and "=" in line:
                k, v = line.split("=", 1)
                out[sec].append((k.strip(), v.strip()))
    return out


def first(section: list[tuple[str, str]], key: str) -> str | None:
    return next((v for k, v in section if k == key), None)


def coordinates(ini: dict) -> str:
    return "".join(re.sub(r"[\s,]", "", first(ini["TRAJ"], "COORDINATES") or "XYZ").upper())


def linear_unit_mm(ini: dict) -> float:
    """mm per machine length unit."""
    unit = (first(ini["TRAJ"], "LINEAR_UNITS") or "mm").lower()
    return {"mm": 1.0, "metric": 1.0, "inch": MM_PER_INCH, "imperial": MM_PER_INCH, "in": MM_PER_INCH}.get(
        unit, 1.0 / float(unit) if re.fullmatch(r"[0-9.]+", unit) else 1.0
    )


def axis_section(ini: dict, letter: str, joint: int) -> list[tuple[str, str]]:
    for name in (f"AXIS_{letter}", f"AXIS_{ALL_AXES.index(letter)}", f"JOINT_{joint}"):
        if name in ini:
            return ini[name]
    raise ValueError(f"axis {letter} has no section in the INI")


def write_config(directory: str, corpus_ini: str, program: str, timeout_s: float, same_tolerance: bool = False) -> dict:
    """The LinuxCNC 2.9 configuration (also cnc-interp's machine) and the program copy
    (``same_tolerance``: its G64 words rewritten, ``at_tolerance``)."""
    ini = read_ini(corpus_ini)
    letters = coordinates(ini)
    unit_mm = linear_unit_mm(ini)
    standin_tool_table(directory)  # the INI names it: TOOL_TABLE = standin.tbl
    open(os.path.join(directory, "sim.var"), "w").close()
    # the display: LinuxCNC runs it as ``PROGRAM -ini INIFILE``
    wrapper = os.path.join(directory, "display.sh")
    with open(wrapper, "w") as fh:
        fh.write(f'#!/bin/sh\nexec {SYSTEM_PYTHON} {DISPLAY} "$@"\n')
    os.chmod(wrapper, 0o755)

    n = len(letters)
    cols = "f" * n  # the joint position commands
    hal = [
        "loadrt [KINS]KINEMATICS",
        "loadrt [EMCMOT]EMCMOT servo_period_nsec=[EMCMOT]SERVO_PERIOD num_joints=[KINS]JOINTS",
        "addf motion-command-handler servo-thread",
        "addf motion-controller servo-thread",
        *(f"net j{j}pos joint.{j}.motor-pos-cmd => joint.{j}.motor-pos-fb" for j in range(n)),
        "net estop-loop iocontrol.0.user-enable-out iocontrol.0.emc-enable-in",
        "net tool-prep-loop iocontrol.0.tool-prepare iocontrol.0.tool-prepared",
        "net tool-change-loop iocontrol.0.tool-change iocontrol.0.tool-changed",
        f"loadrt sampler depth={SAMPLER_DEPTH} cfg={cols}",
        "setp sampler.0.enable 0",
        *(f"net j{j}cmd joint.{j}.pos-cmd => sampler.0.pin.{j}" for j in range(n)),
        "addf sampler.0 servo-thread",  # after the motion controller: this period's command
    ]
    with open(os.path.join(directory, "sim.hal"), "w") as fh:
        fh.write("\n".join(hal) + "\n")

    out = [
        "[EMC]",
        "VERSION = 1.1",
        f"MACHINE = {first(ini.get('EMC', []), 'MACHINE') or 'corpus'} (benchmarks/linuxcnc.py)",
        "DEBUG = 0",
        "[DISPLAY]",
        f"DISPLAY = {wrapper}",
        "CYCLE_TIME = 0.100",
        "[TASK]",
        "TASK = milltask",
        f"CYCLE_TIME = {first(ini.get('TASK', []), 'CYCLE_TIME') or '0.001'}",
        "[RS274NGC]",
        "PARAMETER_FILE = sim.var",
        "[EMCMOT]",
        "EMCMOT = motmod",
        "COMM_TIMEOUT = 1.0",
        f"SERVO_PERIOD = {SERVO_PERIOD_NS}",
        "[HAL]",
        "HALFILE = sim.hal",
        "[KINS]",
        f"KINEMATICS = trivkins coordinates={letters}",
        f"JOINTS = {n}",
        "[TRAJ]",
        *(f"{k} = {v}" for k, v in ini["TRAJ"] if k not in TRAJ_DROPPED),
        "[EMCIO]",
        "EMCIO = io",
        "CYCLE_TIME = 0.100",
        "TOOL_TABLE = standin.tbl",
    ]
    for j, letter in enumerate(letters):
        sec = axis_section(ini, letter, j)
        limits = [(k, first(sec, k)) for k in AXIS_KEYS if first(sec, k) is not None]
        out += [f"[AXIS_{letter}]", *(f"{k} = {v}" for k, v in limits), f"MAX_JERK = {JERK_UNITS_S3:g}"]
        out += [f"[JOINT_{j}]", *(f"{k} = {v}" for k, v in limits)]
        out += [f"{k} = {first(sec, k)}" for k in JOINT_KEYS if first(sec, k) is not None]
        out += ["HOME = 0", "HOME_OFFSET = 0", "HOME_SEARCH_VEL = 0", "HOME_LATCH_VEL = 0", "HOME_SEQUENCE = 0"]
        out += [f"MAX_JERK = {JERK_UNITS_S3:g}"]
    copy = os.path.join(directory, "program.ngc")
    samples = os.path.join(directory, "samples.txt")
    result = os.path.join(directory, "result.json")
    out += [
        "[CNC_INTERP_BENCH]",
        f"PROGRAM = {copy}",
        f"SAMPLES = {samples}",
        f"RESULT = {result}",
        f"TIMEOUT_S = {timeout_s:g}",
    ]
    path = os.path.join(directory, "machine.ini")
    with open(path, "w") as fh:
        fh.write("\n".join(out) + "\n")
    write_program_copy(program, copy, unit_mm, same_tolerance)
    return {"ini": path, "program": copy, "samples": samples, "result": result, "axes": letters, "unit_mm": unit_mm}


def write_program_copy(program: str, copy: str, unit_mm: float, same_tolerance: bool = False) -> None:
    """The program with ``G64 P<1 µm>`` in force from its first line (after a leading ``%``);
    ``same_tolerance``: every G64 of its own held to the same 1 µm (``at_tolerance``)."""
    if unit_mm == 1.0:
        head = f"G64 P{TOL_MM:g}\n"
    else:  # LinuxCNC starts in the INI's units and cnc-interp in mm: G20 makes them agree
        head = f"G20 G64 P{TOL_MM / MM_PER_INCH:.10f}\n"
    with open(program, "rb") as fh:
        text = fh.read().decode("latin-1")
    if same_tolerance:
        text = at_tolerance(text, inch=unit_mm != 1.0)
    lines = text.splitlines(keepends=True)
    i = next((k for k, ln in enumerate(lines) if ln.strip()), len(lines))
    at = i + 1 if i < len(lines) and lines[i].strip() == "%" else 0
    with open(copy, "w", encoding="latin-1") as fh:
        fh.write("".join(lines[:at]) + head + "".join(lines[at:]))


#: a comment of a block: parenthesised, or from ";" to the end of the line
_COMMENT = re.compile(r"\([^)]*\)|;.*$")
#: a G word of a block and its number
_G_WORD = re.compile(r"G\s*([0-9]+(?:\.[0-9]*)?)", re.IGNORECASE)
#: a P or Q word with a plain number (G64's tolerances)
_PQ_WORD = re.compile(r"[PQ]\s*[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)", re.IGNORECASE)


def at_tolerance(text: str, inch: bool) -> str:
    """``text`` with every block's G64 (with or without P and Q) rewritten to ``G64 P<1 µm>``
    in the units in force there (G20/G21 followed from ``inch``, the units the program starts
    in): LinuxCNC then holds the tolerance cnc-interp's ``--tol`` holds, instead of blending
    a plain G64 with none and honouring a larger P. The block's comments are dropped with it.
    Raises ``ValueError`` on a G64 block whose P or Q is not a plain number."""
    out = []
    for line in text.splitlines(keepends=True):
        code = _COMMENT.sub("", line.rstrip("\r\n"))
        gs = [float(m.group(1)) for m in _G_WORD.finditer(code)]
        if 20.0 in gs:
            inch = True
        if 21.0 in gs:
            inch = False
        if 64.0 not in gs:
            out.append(line)
            continue
        rest = _PQ_WORD.sub("", _G_WORD.sub(lambda m: "" if float(m.group(1)) == 64.0 else m.group(0), code))
        if re.search(r"[PQ]", rest, re.IGNORECASE):
            raise ValueError(f"G64 with a P or Q that is not a number: {line.strip()!r}")
        p = TOL_MM / MM_PER_INCH if inch else TOL_MM
        end = line[len(line.rstrip("\r\n")) :] or "\n"
        out.append(f"{rest.strip()} G64 P{p:.10f}".strip() + end)
    return "".join(out)


# --- the moving span ---------------------------------------------------------------------
def moving_span(q: np.ndarray) -> tuple[int, int, int]:
    """(periods, first, last): the moving span of positions q (K, n), rounded to the grid halsampler
    prints; a period moves when its position differs from the one before."""
    if q.shape[0] < 2:
        return 0, -1, -1
    r = np.round(q, POSITION_DECIMALS)
    moving = np.flatnonzero(np.any(r[1:] != r[:-1], axis=1)) + 1
    if moving.size == 0:
        return 0, -1, -1
    return int(moving[-1] - moving[0] + 1), int(moving[0]), int(moving[-1])


def to_machine_units(q_mm: np.ndarray, axes: str, unit_mm: float) -> np.ndarray:
    """cnc-interp's setpoints (mm, deg) in the INI's units (rotary axes stay in degrees)."""
    scale = np.array([1.0 if a in "ABC" else 1.0 / unit_mm for a in axes])
    return q_mm * scale


def program_facts(cfg: dict) -> dict:
    """How the program copy's own G64/G61 words set its tolerance: ``plain_g64`` when a move has a
    G64 without P (LinuxCNC blends it with no tolerance, up to a quarter of the shorter move, and
    cnc-interp at ``--tol``), and ``g64`` a label: "no P", the largest P over 1 µm (LinuxCNC
    honours it, cnc-interp caps it at ``--tol``), "G61", or "-" (the 1 µm of the first line)."""
    import cnc_interp as ci

    prog = ci.read_program(cfg["program"], machine=cfg["ini"])
    tols = np.concatenate([np.asarray(r.tol_mm[1:], dtype=float) for r in prog.runs] or [np.zeros(0)])
    plain = bool(np.any(np.isnan(tols)))
    finite = tols[np.isfinite(tols)]
    label = ["no P"] if plain else []
    if finite.size and finite.max() > TOL_MM * (1 + 1e-6):
        label.append(f"P {finite.max():.3g} mm")
    if finite.size and np.any(finite == 0):
        label.append("G61")
    return {"plain_g64": plain, "g64": ", ".join(label) or "-"}


# --- cnc-interp ---------------------------------------------------------------------------
def plan_cnc_interp(cfg: dict, planner: str) -> dict:
    from cnc_interp.errors import CncInterpError
    from cnc_interp.pipeline import plan_part

    t0 = time.perf_counter()
    try:
        out = plan_part(cfg["program"], cfg["ini"], planner, DT_S, tol_mm=TOL_MM)
    except CncInterpError as exc:
        return {"status": "error", "message": _reason(exc.format()), "wall_s": time.perf_counter() - t0}
    traj = out.trajectory
    q = to_machine_units(traj.q, traj.axes, cfg["unit_mm"])
    periods, _, _ = moving_span(q)
    return {
        "status": "ok",
        "cycle_s": periods * DT_S,
        "duration_s": traj.duration_s,
        "end": np.round(q[-1], POSITION_DECIMALS).tolist() if q.shape[0] else [],
        "worst_ratio": out.report.worst_ratio,
        "wall_s": time.perf_counter() - t0,
    }


# --- LinuxCNC -----------------------------------------------------------------------------
def _lcnc_env(directory: str) -> dict:
    env = dict(os.environ)
    env["HOME"] = directory  # LinuxCNC's ~/ files (.linuxcncrc, fifo) stay in the run's folder
    env["RTAPI_FIFO_PATH"] = os.path.join(directory, "rtapi_fifo")
    env.pop("DISPLAY", None)  # headless: no X dialogs
    if os.geteuid() == 0:
        env["RTAPI_UID"] = "65534"  # rtapi_app refuses root without a user to drop to
    return env


def _end_group(proc: subprocess.Popen, env: dict) -> None:
    """End a LinuxCNC run's process group (TERM, then KILL) and unload what HAL left."""
    for sig, wait_s in ((signal.SIGTERM, 20.0), (signal.SIGKILL, 10.0)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(wait_s)
        except subprocess.TimeoutExpired:
            continue
    subprocess.run(["halrun", "-U"], env=env, capture_output=True, timeout=60)
    for pid in _run_processes(env["RTAPI_FIFO_PATH"]):  # rtapi_app starts a session of its own
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def _run_processes(fifo_path: str) -> list[int]:
    """Processes of one LinuxCNC run: those whose environment has its RTAPI_FIFO_PATH."""
    mark = f"RTAPI_FIFO_PATH={fifo_path}".encode()
    pids = []
    for entry in os.listdir("/proc"):
        if entry.isdigit() and int(entry) != os.getpid():
            try:
                with open(f"/proc/{entry}/environ", "rb") as fh:
                    if mark in fh.read().split(b"\0"):
                        pids.append(int(entry))
            except OSError:
                continue
    return pids


def run_linuxcnc(cfg: dict, directory: str, timeout_s: float) -> dict:
    env = _lcnc_env(directory)
    for stale in (cfg["result"], cfg["samples"]):  # a retry's
        if os.path.exists(stale):
            os.unlink(stale)
    os.chmod(directory, 0o777)  # rtapi_app drops to an unprivileged user: its fifo folder
    log_path = os.path.join(directory, "linuxcnc.log")
    before = set(glob.glob("/tmp/linuxcnc.debug.*") + glob.glob("/tmp/linuxcnc.print.*"))
    t0 = time.monotonic()
    with open(log_path, "w") as log:
        proc = subprocess.Popen(
            ["linuxcnc", "-r", cfg["ini"]],
            cwd=directory,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        try:
            proc.wait(timeout_s + LINUXCNC_TIMEOUT_MARGIN_S)
            timed_out = False
        except subprocess.TimeoutExpired:
            timed_out = True
        finally:
            _end_group(proc, env)
    wall = time.monotonic() - t0
    for f in set(glob.glob("/tmp/linuxcnc.debug.*") + glob.glob("/tmp/linuxcnc.print.*")) - before:
        os.unlink(f)
    with open(log_path, encoding="utf-8", errors="replace") as fh:
        log_text = fh.read()
    rec: dict = {"wall_s": wall}
    try:
        with open(cfg["result"]) as fh:
            res = json.load(fh)
    except (OSError, ValueError):
        res = {"status": "error", "errors": ["no result from the display"]}
    if timed_out:
        res = {**res, "status": "error", "errors": [*res.get("errors", []), "LinuxCNC did not exit in time"]}
    if res.get("status") != "ok":
        tail = [ln for ln in log_text.splitlines() if ln.strip()][-3:]
        rec.update(status="error", message="; ".join(res.get("errors", []) or tail)[:300])
        return rec
    data = np.loadtxt(cfg["samples"], ndmin=2)
    tags, q = data[:, 0].astype(np.int64), data[:, 1:]
    gaps = int(np.count_nonzero(np.diff(tags) != 1))
    periods, _, _ = moving_span(q)
    rec.update(
        status="ok" if gaps == 0 else "error",
        cycle_s=periods * DT_S,
        samples=int(q.shape[0]),
        end=np.round(q[-1], POSITION_DECIMALS).tolist(),
        run_wall_s=res.get("wall_s"),
    )
    if gaps:
        rec["message"] = f"sampler lost samples at {gaps} places (overruns {res.get('overruns')})"
    return rec


def linuxcnc_version() -> str:
    """The version the ``linuxcnc`` script names (Debian's linuxcnc-uspace)."""
    try:
        with open(shutil.which("linuxcnc") or "", encoding="utf-8", errors="replace") as fh:
            m = re.search(r'LINUXCNCVERSION="([^"]+)"', fh.read())
    except OSError:
        m = None
    return m.group(1) if m else "?"


# --- the benchmark ------------------------------------------------------------------------
def plan_first(path: str, ini: str, same_tolerance: bool = False) -> dict:
    """cnc-interp vpop on ``ini``, or on the first fallback INI that has the program's axes."""
    rec: dict = {"program": os.path.relpath(path, CORPUS), "path": path, "same_tolerance": same_tolerance}
    for candidate in [ini] + [os.path.join(CONFIGS, n) for n in AXIS_FALLBACK_INIS]:
        work = tempfile.mkdtemp(prefix="cnc-interp-lcnc-")
        try:
            vpop = plan_cnc_interp(write_config(work, candidate, path, 0.0, same_tolerance), "vpop")
        finally:
            shutil.rmtree(work, ignore_errors=True)
        if vpop["status"] == "ok" or "is not on this machine" not in vpop["message"]:
            break
    rec.update(ini_path=candidate, ini=os.path.basename(candidate), vpop=vpop)
    return rec


def measure(rec: dict, args, budget_left_s: float) -> dict:
    """LinuxCNC (and the optimal planner) on a program ``plan_first`` planned, if it is short enough."""
    vpop = rec["vpop"]
    if vpop["status"] != "ok":
        rec["status"] = "cnc-interp error"
        return rec
    if vpop["cycle_s"] > args.max_cycle and not rec.get("hard"):
        rec["status"] = f"skipped: vpop cycle over {args.max_cycle:g} s"
        return rec
    earlier = args.reuse.get((rec["program"], rec["ini"]))
    if budget_left_s <= 0 and not earlier:
        rec["status"] = "skipped: LinuxCNC time budget spent"
        return rec
    timeout = LINUXCNC_TIMEOUT_FACTOR * vpop["cycle_s"] + LINUXCNC_TIMEOUT_MARGIN_S
    work = tempfile.mkdtemp(prefix="cnc-interp-lcnc-")
    try:
        try:
            cfg = write_config(work, rec["ini_path"], rec["path"], timeout, args.same_tolerance)
        except ValueError as exc:  # a G64 at_tolerance cannot rewrite
            rec["status"] = f"skipped: {exc}"
            return rec
        if args.same_tolerance:  # the G64 words as the program wrote them, not as rewritten
            as_written = os.path.join(work, "as_written.ngc")
            write_program_copy(rec["path"], as_written, cfg["unit_mm"])
            facts = program_facts({**cfg, "program": as_written})
        else:
            facts = program_facts(cfg)
        rec.update(facts)
        if "optimal" in args.planners:
            rec["optimal"] = plan_cnc_interp(cfg, "optimal")
        if earlier:  # LinuxCNC's cycle does not depend on cnc-interp's code
            rec["linuxcnc"] = {**earlier, "reused": True}
        else:
            rec["linuxcnc"] = run_linuxcnc(cfg, work, timeout)
        if "servo thread stopped" in rec["linuxcnc"].get("message", "") and not earlier:
            # another process unloaded HAL under the run: once more
            first_try = rec["linuxcnc"]
            rec["linuxcnc"] = {**run_linuxcnc(cfg, work, timeout), "retried": first_try}
        if args.keep:
            rec["work"] = work
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)
    rec["status"] = "ok" if rec["linuxcnc"]["status"] == "ok" else "LinuxCNC error"
    if rec["status"] == "ok":  # the same program read the same way ends at the same place
        rec["ends_agree"] = all(
            rec[p]["end"] == rec["linuxcnc"]["end"] for p in PLANNERS if rec.get(p, {}).get("status") == "ok"
        )
    return rec


def select(args) -> list[str]:
    every = [f for f in corpus_programs() if not any(x in f for x in args.exclude)]
    if args.programs:
        return [f for f in every if any(p in f for p in args.programs)]
    hard = [f for h in HARD for f in every if h in f]
    return hard + [f for f in every if f not in hard]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("programs", nargs="*", help="corpus programs whose path contains one of these (default: all)")
    ap.add_argument("--ini", default=os.path.join(CONFIGS, "axis_mm.ini"), help="corpus INI (default axis_mm.ini)")
    ap.add_argument("--max-cycle", type=float, default=DEFAULT_MAX_CYCLE_S, metavar="S")
    ap.add_argument("--budget", type=float, default=DEFAULT_BUDGET_S, metavar="S", help="LinuxCNC wall time, s")
    ap.add_argument("--exclude", action="append", default=list(DEFAULT_EXCLUDE), metavar="TEXT")
    ap.add_argument("--planners", nargs="+", default=list(PLANNERS), choices=PLANNERS)
    ap.add_argument("--keep", action="store_true", help="keep each run's folder (printed)")
    ap.add_argument("--json", default=None)
    ap.add_argument(
        "--linuxcnc-from",
        default=None,
        metavar="OLD.json",
        help="take LinuxCNC's result of a program (and INI) from an earlier run's --json instead of "
        "running LinuxCNC again: measures a new cnc-interp against the same LinuxCNC in minutes",
    )
    ap.add_argument(
        "--same-tolerance",
        action="store_true",
        help="hold every G64 of the program to the same 1 µm on both sides (at_tolerance); "
        "the table goes to its own section",
    )
    ap.add_argument("--no-write", action="store_true", help="print only; leave RESULTS.md alone")
    args = ap.parse_args(argv)
    args.reuse = {}
    if args.linuxcnc_from:
        with open(args.linuxcnc_from) as fh:
            args.reuse = {
                (r["program"], r["ini"]): r["linuxcnc"]
                for r in json.load(fh)
                if r.get("linuxcnc") and bool(r.get("same_tolerance")) == args.same_tolerance
            }
    # Ctrl-C and kill end the run the same way (LinuxCNC shut down, the table so far written),
    # also when the shell started the script in the background with SIGINT ignored
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, _interrupt)
    if shutil.which("linuxcnc") is None:
        sys.exit("linuxcnc.py: needs LinuxCNC 2.9 (Debian: linuxcnc-uspace)")
    programs = select(args)
    rows, spent = [], 0.0
    try:
        # vpop first on every program: after the hard ones, the short ones run on LinuxCNC first
        planned = [plan_first(path, args.ini, args.same_tolerance) for path in programs]
        hard = [r for r in planned if any(h in r["path"] for h in HARD)]
        for r in hard:
            r["hard"] = True  # run whatever their cycle: they are what the comparison is for
        rest = sorted((r for r in planned if r not in hard), key=lambda r: r["vpop"].get("cycle_s", 0.0))
        for rec in hard + rest:
            rows.append(measure(rec, args, args.budget - spent))
            if not rec.get("linuxcnc", {}).get("reused"):
                spent += rec.get("linuxcnc", {}).get("wall_s", 0.0)
            _print(rec)
    except KeyboardInterrupt:
        print("interrupted: the table has the programs measured so far", flush=True)
    ok = [r for r in rows if r["status"] == "ok"]
    summary = _summary(ok, args.planners)
    print(summary)
    print(f"LinuxCNC wall time {spent:.0f} s")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)
    if not args.no_write and rows:
        _write(args, argv, rows, summary)


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def _ratio(r: dict, planner: str) -> float | None:
    p, lc = r.get(planner, {}), r.get("linuxcnc", {})
    if p.get("status") != "ok" or lc.get("status") != "ok" or lc["cycle_s"] <= 0:
        return None
    return p["cycle_s"] / lc["cycle_s"]


def _summary(ok: list, planners) -> str:
    parts = [f"{len(ok)} programs measured on both sides."]
    for planner in planners:
        ratios = [(r, x) for r in ok if (x := _ratio(r, planner)) is not None]
        slower = [(r, x) for r, x in ratios if x > 1.0]
        if not ratios:
            continue
        tot = sum(r[planner]["cycle_s"] for r, _ in ratios)
        tot_lc = sum(r["linuxcnc"]["cycle_s"] for r, _ in ratios)
        parts.append(
            f"{planner}: total {tot:.3f} s against LinuxCNC's {tot_lc:.3f} s ({tot / tot_lc:.3f}); "
            f"slower than LinuxCNC on {len(slower)} of {len(ratios)}"
            + (
                ": "
                + ", ".join(f"{os.path.basename(r['program'])} {x:.3f}" for r, x in sorted(slower, key=lambda y: -y[1]))
                if slower
                else ""
            )
            + "."
        )
    return " ".join(parts)


def _write(args, argv, rows: list, summary: str) -> None:
    """The table (programs LinuxCNC ran or refused) and a list of the programs not run."""
    header = ["program", "INI", "own G64/G61", "same end", "LinuxCNC s"]
    for p in args.planners:
        header += [f"{p} s", f"{p} / LinuxCNC"]
    table_rows, not_run = [], []
    for r in rows:
        lc = r.get("linuxcnc")
        if not lc:
            reason = r["vpop"].get("message", "") if r["status"] == "cnc-interp error" else r["status"]
            not_run.append(f"- {r['program']} ({r.get('ini', '')}): {reason[:120]}")
            continue
        agree = r.get("ends_agree")
        row = [r["program"], r.get("ini", ""), r.get("g64", "no P" if r.get("plain_g64") else "-")]
        row.append("-" if agree is None else "yes" if agree else "**no**")
        if lc["status"] == "ok":
            row.append(f"{lc['cycle_s']:.3f}")
        else:
            row.append(f"error: {lc.get('message', '').splitlines()[0][:80]}")
        for p in args.planners:
            x = r.get(p, {})
            if x.get("status") == "ok":
                ratio = _ratio(r, p)
                row += [
                    f"{x['cycle_s']:.3f}",
                    f"**{ratio:.3f}**" if ratio and ratio > 1 else f"{ratio:.3f}" if ratio else "-",
                ]
            else:
                row += [f"error: {x.get('message', '-')[:80]}" if x else "-", "-"]
        table_rows.append(row)
    notes = (
        f"Cycle = the moving span (first to last period whose position changes, on 6 decimals of "
        f"machine units), in 1 ms servo periods on LinuxCNC's side (SERVO_PERIOD = {SERVO_PERIOD_NS}; a "
        f"sampler on the servo thread) and in 1 ms samples on cnc-interp's (--tol {TOL_MM:g}, "
        f"MAX_JERK = {JERK_UNITS_S3:g} units/s^3 on every axis). Dwells and stops between moves count; "
        f"M6 is looped back in HAL and cnc-interp models no time for it. Program copies start with "
        f"G64 P0.001 (1 µm); "
        + (
            "every G64 of the program's own is rewritten to G64 P0.001 in the units in force "
            '(--same-tolerance), so both sides hold 1 µm throughout; "own G64/G61" names what the '
            "program wrote: "
            if args.same_tolerance
            else "the program's own G64/G61 words apply as written on both sides: "
        )
        + f'"own G64/G61": "no P" marks a G64 without P, which LinuxCNC blends with no tolerance '
        f'(up to a quarter of the shorter move) and cnc-interp at --tol; "P x mm" the largest G64 P over '
        f'1 µm, which LinuxCNC honours and cnc-interp caps at --tol; "-": the first line\'s 1 µm holds '
        f'throughout, the same on both sides. "same end": both sides end '
        f'at the same position (6 decimals); "no" means cnc-interp read the program differently. '
        f"Ratio > 1 (bold): cnc-interp slower. LinuxCNC {linuxcnc_version()} uspace, headless, "
        f"simulated HAL, stand-in tool table. " + summary
    )
    reused = sum(1 for r in rows if r.get("linuxcnc", {}).get("reused"))
    if reused:
        notes += (
            f" LinuxCNC's figures of {reused} programs are those of an earlier run (--linuxcnc-from): "
            "LinuxCNC's cycle does not depend on cnc-interp's code."
        )
    if args.exclude:
        notes += f" Left out by name: {', '.join(args.exclude)}."
    if not_run:
        notes += (
            f"\n\nNot run on LinuxCNC (vpop cycle over --max-cycle {args.max_cycle:g} s, time budget "
            f"{args.budget:g} s spent, or refused by cnc-interp):\n\n" + "\n".join(not_run)
        )
    title = "Against LinuxCNC 2.9, same tolerance" if args.same_tolerance else "Against LinuxCNC 2.9"
    write_section(title, "linuxcnc.py", command_line("linuxcnc.py", argv), md_table(header, table_rows), notes)


def _reason(message: str) -> str:
    first_line = message.strip().splitlines()[0] if message.strip() else "?"
    _, sep, rest = first_line.partition("error: ")
    return (rest if sep else first_line)[:200]


def _print(r: dict) -> None:
    lc = r.get("linuxcnc", {})
    parts = [f"{r['program']:48s} {r.get('ini', ''):12s}" + (" plain-G64" if r.get("plain_g64") else "")]
    if lc.get("status") == "ok":
        parts.append(f"LinuxCNC {lc['cycle_s']:9.3f} s (wall {lc['wall_s']:6.1f} s)")
    elif lc:
        parts.append(f"LinuxCNC ERROR {lc.get('message', '')[:120]}")
    else:
        parts.append(f"{r['status']}")
    for p in PLANNERS:
        x = r.get(p)
        if not x:
            continue
        if x["status"] == "ok":
            ratio = _ratio(r, p)
            parts.append(f"{p} {x['cycle_s']:9.3f} s" + (f" ({ratio:.3f})" if ratio is not None else ""))
        else:
            parts.append(f"{p} ERROR {x['message'][:100]}")
    if lc.get("status") == "ok":
        for p in PLANNERS:
            if r.get(p, {}).get("status") == "ok" and r[p]["end"] != lc["end"]:
                parts.append(f"[{p} ends at {r[p]['end']}, LinuxCNC at {lc['end']}]")
    print(" ".join(parts), flush=True)


if __name__ == "__main__":
    main()
