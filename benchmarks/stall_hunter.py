"""Stall hunter: seeded short rotary and near-degenerate programs, planned and checked.

Usage: python benchmarks/stall_hunter.py [--count N] [--seed S] [--planner P] [--machine M ...]
                                         [--out DIR] [--keep K] [--no-write]

A stall of the step loop ("VPOp made no progress", met on a Vectric 4-axis XZA file) must
end in the safe fallback, never in an error. This generates ``--count`` short programs
(``generate(seed, index)``: the same program for the same seed and index, whatever the
count) of the moves that make the step loop stall: tiny linear moves with large rotary
steps, rotary-only moves, axis reversals, moves of 1e-6..1e-3 mm (some below the printed
quantum: zero length after the fit), repeated points, G0/G1 mixes with F from 1 to 100,000
mm/min and inverse-time feeds, on machines whose limits are those of real ones
(``MACHINES``: a Vectric 4-axis job's XZA and XYZA machines, the XYZA and XYZAC example
files, the presets). Each program is planned through the public API (``cnc_interp.run``) and
must plan (no exception), hold every limit (``report.ok``) and end on its last programmed
point.

Prints the counts (ok, failed, violations, off the end point, safe fallbacks) and writes
the first ``--keep`` failing programs to ``--out`` (each with its machine as a TOML file
beside it and the error in a comment); appends its figures to ``benchmarks/RESULTS.md``
("Stall hunter, PLANNER" section, one per planner and mode) unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import math
import os
import random
import sys
import time
from dataclasses import dataclass, field

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)

_LIN = {"vmax": 200.0, "amax": 2000.0, "jmax": 50000.0}
_ROT = {"vmax": 180.0, "amax": 1800.0, "jmax": 45000.0}

#: name -> TOML-shaped machine data (``machine_from_data``), or a preset / example file
MACHINES: dict[str, dict | str] = {
    # a user's rotary machine: 200 mm/s, 2000 mm/s², 50000 mm/s³; A 180 °/s, 1800 °/s², 45000 °/s³
    "xza-rotary": {"name": "XZA rotary", "dt": 0.001, "axes": {"X": _LIN, "Z": _LIN, "A": _ROT}},
    "xyza-rotary": {"name": "XYZA rotary", "dt": 0.001, "axes": {"X": _LIN, "Y": _LIN, "Z": _LIN, "A": _ROT}},
    "xyza-example": "examples/machines/mill-4axis-xyza.toml",
    "xyzac-trt-example": "examples/machines/5axis-xyzac-trt.toml",
    "mikron-ucp710": "mikron-ucp710",
    "generic-mill": "generic-mill",
    "xz-lathe": "xz-lathe",
}
#: how often each machine is drawn (the rotary machines most)
MACHINE_WEIGHTS = {
    "xza-rotary": 4,
    "xyza-rotary": 3,
    "xyza-example": 2,
    "xyzac-trt-example": 2,
    "mikron-ucp710": 2,
    "generic-mill": 1,
    "xz-lathe": 1,
}
#: moves per program (short: thousands of programs run in minutes)
MIN_MOVES, MAX_MOVES = 2, 7
#: the longest a feed move may take at its programmed feed, s
MAX_MOVE_S = 5.0


def load(name: str):
    """The ``Machine`` named in ``MACHINES``."""
    from cnc_interp.errors import SourceLocation
    from cnc_interp.machine.load import load_machine, machine_from_data

    spec = MACHINES[name]
    if isinstance(spec, dict):
        return machine_from_data(spec, source=f"hunter:{name}", locate=lambda *a: SourceLocation(f"hunter:{name}"))
    path = os.path.join(REPO, spec)
    return load_machine(path if os.path.exists(path) else spec)


@dataclass
class Generated:
    """One program: its text, the machine's name, the last programmed point (program
    coordinates, machine axis order) and what the generator put in it."""

    text: str
    machine: str
    end: list[float]
    kinds: list[str] = field(default_factory=list)


def _fmt(x: float, digits: int) -> str:
    s = f"{x:.{digits}f}"
    if "." in s:
        s = s.rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def generate(seed: int, index: int, machine: str | None = None) -> Generated:
    """The program ``index`` of ``seed`` (see the module docstring); ``machine`` forces
    the machine, else it is drawn by ``MACHINE_WEIGHTS``."""
    rng = random.Random(f"stall-hunter:{seed}:{index}")
    names = list(MACHINE_WEIGHTS)
    name = machine or rng.choices(names, weights=[MACHINE_WEIGHTS[n] for n in names])[0]
    m = load(name)
    axes = m.axes
    lin = [a for a in axes if a not in "ABC"]
    rot = [a for a in axes if a in "ABC"]
    digits = rng.choice([3, 4, 4, 5, 6])
    pos = {a: float(m.start[i]) for i, a in enumerate(axes)}
    lines = [f"(stall hunter seed {seed} program {index} machine {name})", "G21 G90 G94 G17"]
    mode = rng.random()
    if mode < 0.4:
        lines.append(f"G64 P{rng.choice(['0.001', '0.01', '0.05', '0.1'])}")
    elif mode < 0.5:
        lines.append("G61")
    kinds: list[str] = []

    def emit(word: str, target: dict[str, float], extra: str = "") -> None:
        parts = [word]
        for a in axes:
            if a in target:
                v = float(_fmt(target[a], digits))
                parts.append(f"{a}{_fmt(v, digits)}")
                pos[a] = v
        lines.append(" ".join(parts) + extra)

    # a first point near the start (rapid), as a CAM file positions before cutting
    first = {a: pos[a] + rng.uniform(-5, 5) for a in lin}
    for a in rot:
        first[a] = pos[a] + rng.choice([0.0, rng.uniform(-90, 90)])
    emit("G0", first)
    inverse = rng.random() < 0.1
    if inverse:
        lines.append("G93")
    feed = 0.0
    last_delta: dict[str, float] = {}
    for _ in range(rng.randint(MIN_MOVES, MAX_MOVES)):
        kind = rng.choice(["tiny+rot", "tiny+rot", "rot-only", "reversal", "tiny", "normal", "repeat", "plunge+rot"])
        if kind == "reversal" and not last_delta:
            kind = "tiny+rot"
        kinds.append(kind)
        delta: dict[str, float] = {}
        if kind == "reversal":
            scale = rng.choice([1.0, rng.uniform(0.01, 2.0)])
            delta = {a: -d * scale for a, d in last_delta.items()}
        elif kind != "repeat":
            if kind in ("tiny", "tiny+rot"):
                mag = 10.0 ** rng.uniform(-6, -3)
                moving = rng.sample(lin, rng.randint(1, len(lin)))
            elif kind == "normal":
                mag = 10.0 ** rng.uniform(-2, 0.7)
                moving = rng.sample(lin, rng.randint(1, len(lin)))
            elif kind == "plunge+rot":
                mag = 10.0 ** rng.uniform(-4, -1)
                moving = ["Z"] if "Z" in lin else lin[:1]
            else:
                mag, moving = 0.0, []
            for a in moving:
                delta[a] = mag * rng.choice([-1.0, 1.0]) * rng.uniform(0.3, 1.0)
            if rot and kind in ("tiny+rot", "rot-only", "plunge+rot", "normal"):
                for a in rng.sample(rot, rng.randint(1, len(rot))):
                    big = rng.random() < 0.7 or kind == "rot-only"
                    step = 10.0 ** (rng.uniform(-0.5, 2.3) if big else rng.uniform(-4, -1))
                    delta[a] = step * rng.choice([-1.0, 1.0])
        last_delta = delta or last_delta
        target = {a: pos[a] + delta.get(a, 0.0) for a in axes}
        if rng.random() < 0.15:
            emit("G0", target)
            continue
        extra = ""
        if inverse:  # F: 1/minutes of the move (at most MAX_MOVE_S)
            extra = f" F{_fmt(10.0 ** rng.uniform(math.log10(60.0 / MAX_MOVE_S), 4), 3)}"
        else:
            # F in mm/min (deg/min for a rotary-only move), at least what ends the move
            # within MAX_MOVE_S (a 100° turn at F1 would take 100 min to plan)
            length = _move_length({a: target[a] - pos[a] for a in axes}, lin, rot)
            least = 60.0 * length / MAX_MOVE_S
            if feed <= 0.0 or feed < least or rng.random() < 0.3:
                feed = float(_fmt(max(10.0 ** rng.uniform(0, 5), 1.01 * least), 2))
                extra = f" F{_fmt(feed, 2)}"
        emit("G1", target, extra)
    if inverse:
        lines.append("G94")
    lines.append("M2")
    return Generated("\n".join(lines) + "\n", name, [pos[a] for a in axes], kinds)


def _move_length(delta: dict[str, float], lin: list[str], rot: list[str]) -> float:
    """A move's length by the feed convention: linear distance, else rotary (deg)."""
    d = math.sqrt(sum(delta[a] ** 2 for a in lin))
    return d if d > 0 else math.sqrt(sum(delta[a] ** 2 for a in rot))


@dataclass
class Outcome:
    """One program's result: ``what`` is "ok", "error" (an exception), "violation"
    (a limit broken) or "end" (the plan does not end on the program's last point)."""

    what: str
    message: str = ""
    safe: int = 0
    seconds: float = 0.0


def _run_streamed(text: bytes, m, planner: str, name: str):
    """``cnc_interp.run``'s stages with the plan in the windows ``cnc-interp plan``
    streams in (``timeline.Window()``: each path's own buffer bounded, samples handed out
    mid-path), where a stall after samples are out cannot restart the path."""
    import cnc_interp
    from cnc_interp.api import PlanResult
    from cnc_interp.plan.settings import PlanSettings
    from cnc_interp.plan.timeline import Window, plan_program

    program = cnc_interp.read_program(text, machine=m, name=name)
    settings = PlanSettings.from_options(planner=planner, dt_s=None, tol_mm=None, machine=m)
    m = m.with_dt(settings.dt_s)
    fitted = cnc_interp.fit(program, machine=m)
    traj = plan_program(fitted, m, settings, window=Window())
    return PlanResult(program, fitted, traj, cnc_interp.verify(traj, m), m, settings)


def check(gen: Generated, planner: str, name: str = "hunt", stream: bool = False) -> Outcome:
    """Plan ``gen`` through ``cnc_interp.run`` (``stream``: in the CLI's windows) and
    check the three conditions."""
    import numpy as np

    import cnc_interp
    from cnc_interp.errors import CncInterpError
    from cnc_interp.machine.kinematics import make_kinematics

    t0 = time.perf_counter()
    m = load(gen.machine)
    try:
        if stream:
            res = _run_streamed(gen.text.encode(), m, planner, name)
        else:
            res = cnc_interp.run(gen.text.encode(), m, planner=planner, name=name, check=False)
    except CncInterpError as exc:
        return Outcome("error", exc.format(), seconds=time.perf_counter() - t0)
    except Exception as exc:  # a bug: reported, not raised, so that the hunt goes on
        return Outcome("error", f"{type(exc).__name__}: {exc}", seconds=time.perf_counter() - t0)
    dt = time.perf_counter() - t0
    stats = (res.trajectory.settings or {}).get("stats", {})
    safe = int(stats.get("safe", 0))
    if not res.report.ok:
        return Outcome("violation", res.report.format().replace("\n", "; "), safe, dt)
    kin = make_kinematics(res.machine)
    end = np.asarray(gen.end, dtype=float).reshape(1, -1)
    want = end[0] if kin.is_identity else kin.to_joints(end)[0]
    got = res.trajectory.q[-1]
    if not np.allclose(got, want, rtol=0.0, atol=1e-6 * max(1.0, float(np.max(np.abs(want))))):
        return Outcome("end", f"ends at {got.tolist()}, not {want.tolist()}", safe, dt)
    return Outcome("ok", safe=safe, seconds=dt)


def hunt(
    count: int,
    seed: int,
    planner: str,
    machines=None,
    out: str | None = None,
    keep: int = 10,
    log=print,
    stream: bool = False,
):
    """Generate and check ``count`` programs; returns the figures (a dict)."""
    counts = {"ok": 0, "error": 0, "violation": 0, "end": 0}
    safe_programs = 0
    messages: dict[str, int] = {}
    per_machine: dict[str, list[int]] = {}
    kept: list[str] = []
    slowest = (0.0, -1)
    t0 = time.perf_counter()
    for i in range(count):
        gen = generate(seed, i, rng_machine(machines, seed, i))
        o = check(gen, planner, name=f"hunt-{seed}-{i}.ngc", stream=stream)
        counts[o.what] += 1
        safe_programs += o.safe > 0
        row = per_machine.setdefault(gen.machine, [0, 0])
        row[0] += 1
        if o.seconds > slowest[0]:
            slowest = (o.seconds, i)
        if o.what == "ok":
            continue
        row[1] += 1
        key = _message_key(o.message)
        messages[key] = messages.get(key, 0) + 1
        if out and len(kept) < keep:
            kept.append(_keep(out, gen, seed, i, planner, o))
        log(f"program {i} ({gen.machine}): {o.what}: {o.message}")
    wall = time.perf_counter() - t0
    return {
        "count": count,
        "seed": seed,
        "planner": planner,
        "counts": counts,
        "failed": count - counts["ok"],
        "safe_programs": safe_programs,
        "messages": messages,
        "per_machine": per_machine,
        "kept": kept,
        "wall_s": wall,
        "slowest": slowest,
    }


def rng_machine(machines, seed: int, i: int) -> str | None:
    """The machine of program i when ``machines`` restricts them (drawn in turn), else None."""
    if not machines:
        return None
    return machines[i % len(machines)]


def _message_key(msg: str) -> str:
    """An error message without its file, line and numbers (to count kinds of failures)."""
    import re

    msg = msg.split(" error: ", 1)[-1]
    return re.sub(r"[-+]?\d[\d.e+-]*", "#", msg)[:120]


def _keep(out: str, gen: Generated, seed: int, i: int, planner: str, o: Outcome) -> str:
    os.makedirs(out, exist_ok=True)
    base = os.path.join(out, f"{planner}-{seed}-{i}-{gen.machine}")
    with open(base + ".ngc", "w", encoding="utf-8") as fh:
        fh.write(f"({o.what}: {o.message.replace('(', '[').replace(')', ']')})\n")
        fh.write(gen.text)
    spec = MACHINES[gen.machine]
    if isinstance(spec, dict):
        with open(base + ".toml", "w", encoding="utf-8") as fh:
            fh.write(_toml(spec))
    else:
        with open(base + ".machine", "w", encoding="utf-8") as fh:
            fh.write(spec + "\n")
    return base + ".ngc"


def _toml(data: dict) -> str:
    lines = [f'name = "{data["name"]}"', f"dt = {data['dt']}"]
    for a, lim in data["axes"].items():
        lines += ["", f"[axes.{a}]"] + [f"{k} = {v}" for k, v in lim.items()]
    return "\n".join(lines) + "\n"


def write_results(fig: dict, command: str) -> str:
    """RESULTS.md's section "Stall hunter, PLANNER" (``_results.write_section``: one
    current table per planner and mode, the commit, machine and command above it)."""
    from _results import md_table, write_section

    c = fig["counts"]
    kinds = "; ".join(f"{k} ×{n}" for k, n in sorted(fig["messages"].items(), key=lambda kv: -kv[1])[:3]) or "none"
    header = [
        "seed",
        "programs",
        "ok",
        "failed",
        "errors",
        "violations",
        "off end",
        "safe fallback",
        "wall",
        "failures",
    ]
    row = [
        fig["seed"],
        fig["count"],
        c["ok"],
        fig["failed"],
        c["error"],
        c["violation"],
        c["end"],
        fig["safe_programs"],
        f"{fig['wall_s']:.0f} s",
        kinds,
    ]
    notes = (
        "Short rotary and near-degenerate programs on the machines of `MACHINES`, "
        "planned through `cnc_interp.run` (streamed: in the windows `cnc-interp plan` uses); "
        "failed = errors + violations + plans off the last point; safe fallback = programs "
        "with a path planned by `plan/safe.py`."
    )
    return write_section(f"Stall hunter, {fig['planner']}", "stall_hunter.py", command, md_table(header, [row]), notes)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--count", type=int, default=1000, help="programs to generate (default 1000)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the generator (default 0)")
    ap.add_argument("--planner", default="vpop", help="vpop (default), optimal, constant or variable")
    ap.add_argument("--machine", action="append", choices=sorted(MACHINES), help="only these machines (repeatable)")
    ap.add_argument("--out", default=os.path.join("/tmp", "stall_hunter"), help="folder for failing programs")
    ap.add_argument("--keep", type=int, default=10, help="failing programs written to --out (default 10)")
    ap.add_argument("--stream", action="store_true", help="plan in the windows `cnc-interp plan` streams in")
    ap.add_argument("--no-write", action="store_true", help="print only; leave RESULTS.md alone")
    args = ap.parse_args(argv)
    sys.path.insert(0, HERE)
    import _results  # noqa: F401  (the load average before the measurement)

    fig = hunt(args.count, args.seed, args.planner, args.machine, args.out, args.keep, stream=args.stream)
    fig["planner"] += " (streamed)" if args.stream else ""
    c = fig["counts"]
    print(
        f"{args.planner}: {fig['count']} programs (seed {args.seed}): ok {c['ok']}, failed {fig['failed']} "
        f"(errors {c['error']}, violations {c['violation']}, off the end {c['end']}); "
        f"{fig['safe_programs']} planned a path by the safe fallback; in {fig['wall_s']:.1f} s; "
        f"slowest {fig['slowest'][0]:.2f} s (program {fig['slowest'][1]})"
    )
    for k, n in sorted(fig["messages"].items(), key=lambda kv: -kv[1]):
        print(f"  {n:6d}  {k}")
    for name, (n, bad) in sorted(fig["per_machine"].items()):
        print(f"  {name}: {n} programs, {bad} failed")
    for p in fig["kept"]:
        print(f"  kept {p}")
    if not args.no_write:
        from _results import command_line

        write_results(fig, command_line("stall_hunter.py", argv))
    return 0 if fig["failed"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
