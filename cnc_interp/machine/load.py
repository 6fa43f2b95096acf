"""Load a ``Machine`` from a TOML file, a LinuxCNC INI file or a built-in preset.

TOML form (DESIGN.md)::

    name = "My mill"          # optional (default: the file name)
    dt = 0.001                # sample period, s (optional, default 0.001)
    kinematics = "trivial"    # or a table: [kinematics] type = "xyzac-trt", z_offset = 12.5
    tol = 0.001               # optional default fit tolerance, mm
    [start]                   # optional machine position before the program
    Z = 50.0
    [axes.X]                  # one table per axis, in machine order
    vmax = 500.0              # mm/s   (deg/s for A, B, C)
    amax = 2500.0             # mm/s^2 (deg/s^2)
    jmax = 5000.0             # mm/s^3 (deg/s^3)

LinuxCNC INI: axis letters from ``[TRAJ] COORDINATES`` (duplicates, i.e. gantry
joints, count once; without it, the ``[AXIS_*]`` sections present, else the first
``[TRAJ] AXES`` letters of XYZABCUVW); limits from ``[AXIS_<letter>]`` (LinuxCNC >= 2.8), else the
old ``[AXIS_<n>]`` (n = index of the letter in XYZABCUVW), else ``[JOINT_<n>]``
(n = position in COORDINATES): ``MAX_VELOCITY``, ``MAX_ACCELERATION`` and, if
present, ``MAX_JERK`` in machine units per s, s^2, s^3. ``[TRAJ] LINEAR_UNITS``
(mm / inch / a number of units per mm) and ``ANGULAR_UNITS`` (degree / radian /
grad) are converted to mm and deg; ``LINEAR_UNITS`` also gives the units a program starts
in (``Machine.program_units``: inch, or a unit nearer 1 inch than 1 mm, starts it in G20;
anything else in G21), as LinuxCNC starts one in the machine's units. ``[TRAJ]
MAX_LINEAR_VELOCITY`` (else ``MAX_VELOCITY``, its name before LinuxCNC 2.8), machine
units per s, is the path speed limit over the linear axes (``Machine.max_path_mm_s``).
``[EMCMOT] SERVO_PERIOD`` (ns) gives dt.
Where the INI has no jerk limit the axis gets
``jmax = DEFAULT_JERK_PER_ACCEL_1_S * amax`` (10/s: full acceleration is reached in
0.1 s, a common S-curve setting for small machines; LinuxCNC's own trajectory
planner is not jerk-limited, so the INI files usually have none).

Every value the source leaves out and the reader fills in (the jerk above, dt, the
name, the start, ...) is named with its value and reason in ``Machine.defaults``;
``describe_machine`` / ``format_machine`` (``cnc-interp machines FILE``) show them.

Every error is a ``MachineError`` with the file, line and column of the
offending key where it can be found.
"""

from __future__ import annotations

import math
import os
import re
import stat

from collections.abc import Callable
from typing import Any

import numpy as np

from ..constants import ALL_AXES, DEFAULT_DT_S, MM_PER_INCH, PROGRAM_UNITS_MM, ROTARY_AXES
from ..errors import MachineError, SourceLocation
from .kinematics import KINEMATICS, normalise_params
from .model import (
    DT_MAX_S,
    DT_MIN_S,
    LIMIT_MAX,
    LIMIT_MIN,
    START_MAX,
    TOL_MAX_MM,
    Machine,
    noop_mcode_problem,
    ramp_problem,
)
from .presets import DEFAULT_PRESET, PRESETS


#: default jerk (per axis, as a multiple of amax per second) when a LinuxCNC INI has none
DEFAULT_JERK_PER_ACCEL_1_S = 10.0
#: an INI's linear unit longer than this (mm) starts programs in inches, a shorter one in
#: mm: the midpoint of 1 mm and 1 inch, so that the nearer of the two wins (LINEAR_UNITS
#: = inch or 0.03937 units per mm: inch; mm, 1 or 0.1 (cm): mm)
PROGRAM_INCH_ABOVE_MM = (1.0 + MM_PER_INCH) / 2
#: [TRAJ] keys of the path speed limit, newest first (LinuxCNC 2.8 renamed MAX_VELOCITY)
_PATH_SPEED_KEYS = ("MAX_LINEAR_VELOCITY", "MAX_VELOCITY")

__all__ = [
    "load_machine",
    "machine_from_data",
    "preset_table",
    "format_presets",
    "describe_machine",
    "format_machine",
    "DEFAULT_PRESET",
    "PRESETS",
]

_TOP_KEYS = ("name", "dt", "kinematics", "tol", "start", "axes", "description", "gcode")
_GCODE_KEYS = ("noop_mcodes", "program_units")
#: LinuxCNC's user M-codes: a program file named M100 to M199 in the INI's search folders
USER_MCODES = range(100, 200)
_AXIS_KEYS = ("vmax", "amax", "jmax")
_LIMIT_NAMES = {"vmax": "velocity", "amax": "acceleration", "jmax": "jerk"}
#: longest sample period accepted (s); anything longer is certainly a unit mistake
_MAX_DT_S = DT_MAX_S
#: largest machine file read, bytes (real TOML/INI machine files are a few kB)
MACHINE_FILE_MAX_BYTES = 1 << 20
#: digits of the longest integer Python's int() converts (sys.int_info.default_max_str_digits):
#: a longer TOML integer makes tomllib raise a plain ValueError
_INT_MAX_DIGITS = 4300


# --- entry point -------------------------------------------------------------
def load_machine(spec: str) -> Machine:
    """A ``Machine`` from a TOML path, a LinuxCNC INI path or a preset name."""
    if spec in PRESETS:
        return _preset(spec)
    if not os.path.exists(spec):
        if os.path.splitext(spec)[1] or os.sep in spec:
            raise MachineError("machine file not found", SourceLocation(file=spec))
        raise MachineError(
            f"no machine file or preset named '{spec}' (presets: {', '.join(sorted(PRESETS))})",
            SourceLocation(file=spec),
        )
    text = _machine_text(spec)
    if _is_ini(spec, text):
        return _load_ini(text, spec)
    return _load_toml(text, spec)


def _machine_text(path: str) -> str:
    raw = _read_machine_file(path)
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise MachineError("machine file is not UTF-8 text", SourceLocation(file=path, line=line)) from None


def _is_ini(path: str, text: str) -> bool:
    """Whether ``load_machine`` reads ``path`` as a LinuxCNC INI (else as TOML)."""
    ext = os.path.splitext(path)[1].lower()
    return ext == ".ini" or (ext != ".toml" and _looks_like_ini(text))


def _read_machine_file(path: str) -> bytes:
    """The bytes of a machine file: a regular file of at most ``MACHINE_FILE_MAX_BYTES``
    (a device such as /dev/zero would be read until memory runs out, a FIFO would block)."""
    loc = SourceLocation(file=path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)  # a FIFO must not block the open
    except OSError as exc:
        raise MachineError(f"cannot read machine file: {exc.strerror}", loc) from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):  # before fdopen, which refuses a folder itself
        os.close(fd)
        raise MachineError("machine file is not a regular file", loc)
    with os.fdopen(fd, "rb") as fh:
        st = os.fstat(fh.fileno())
        if st.st_size > MACHINE_FILE_MAX_BYTES:
            raise MachineError(f"machine file is larger than {MACHINE_FILE_MAX_BYTES} bytes", loc)
        try:
            raw = fh.read(MACHINE_FILE_MAX_BYTES + 1)
        except OSError as exc:
            raise MachineError(f"cannot read machine file: {exc.strerror}", loc) from None
    if len(raw) > MACHINE_FILE_MAX_BYTES:
        raise MachineError(f"machine file is larger than {MACHINE_FILE_MAX_BYTES} bytes", loc)
    return raw


def _looks_like_ini(text: str) -> bool:
    return bool(re.search(r"^\s*\[(TRAJ|EMCMOT|EMC|KINS)\]\s*$", text, re.M))


def _preset(name: str) -> Machine:
    _, data = PRESETS[name]
    return machine_from_data(data, source=f"preset:{name}", locate=lambda *a: SourceLocation(f"preset:{name}"))


# --- TOML --------------------------------------------------------------------
def _load_toml(text: str, path: str) -> Machine:
    import tomllib

    try:
        data = tomllib.loads(text)
    except RecursionError:  # arrays or tables nested thousands deep
        raise MachineError("invalid TOML: nested too deeply", SourceLocation(path, 1, 1)) from None
    except tomllib.TOMLDecodeError as exc:
        line = getattr(exc, "lineno", None)
        col = getattr(exc, "colno", None)
        msg = str(exc)
        m = re.search(r"\s*\(at line (\d+), column (\d+)\)\s*$", msg)
        if m:
            line = line or int(m.group(1))
            col = col or int(m.group(2))
            msg = msg[: m.start()]
        elif re.search(r"\(at end of document\)\s*$", msg):
            line = line or text.count("\n") + 1
            msg = msg[: msg.rfind("(at end")].rstrip()
        line = line or 0
        src = _line_text(text, line)
        raise MachineError(f"invalid TOML: {msg}", SourceLocation(path, line, col or 1, src)) from None
    except ValueError:  # int() refuses an integer of more digits than Python's limit (4300)
        m = re.search(r"\d{%d,}" % _INT_MAX_DIGITS, text)
        line = text.count("\n", 0, m.start()) + 1 if m else 0
        col = m.start() - text.rfind("\n", 0, m.start()) if m else 1
        loc = SourceLocation(path, line, col, _line_text(text, line))
        raise MachineError("invalid TOML: a number of thousands of digits", loc) from None
    locator = _TomlLocator(text, path)
    return machine_from_data(data, source=path, locate=locator, default_name=_stem(path))


class _TomlLocator:
    """Finds the line of ``[table] key`` in TOML text (best effort, for messages)."""

    _HEADER = re.compile(r"^\s*\[\s*([^\[\]]+?)\s*\]\s*(#.*)?$")

    def __init__(self, text: str, path: str):
        self.path = path
        self.lines = text.splitlines()
        self.tables: list[tuple[int, tuple[str, ...]]] = []  # (line index, table path)
        for i, line in enumerate(self.lines):
            m = self._HEADER.match(line)
            if m:
                parts = tuple(p.strip().strip("\"'") for p in m.group(1).split("."))
                self.tables.append((i, parts))

    def __call__(self, table: tuple[str, ...] = (), key: str | None = None) -> SourceLocation:
        # the root table runs up to the first header
        spans: list[tuple[int, int, tuple[str, ...]]] = [(0, len(self.lines), ())]
        if self.tables:
            spans = [(0, self.tables[0][0], ())]
        for j, (start, parts) in enumerate(self.tables):
            end = self.tables[j + 1][0] if j + 1 < len(self.tables) else len(self.lines)
            spans.append((start + 1, end, parts))
        want = tuple(table)
        for start, end, parts in spans:
            if tuple(parts) != want:  # TOML keys are case-sensitive
                continue
            if key is None:
                return self._loc(start - 1) if parts else SourceLocation(self.path)
            pat = re.compile(r"^\s*[\"']?" + re.escape(key) + r"[\"']?\s*=", re.I)
            for i in range(start, end):
                if pat.match(self.lines[i]):
                    return self._loc(i)
            if parts:
                return self._loc(start - 1)
        # dotted or inline forms (axes.X.vmax = .., axes = {X = {..}}): search the key text
        needle = key or (want[-1] if want else None)
        if needle:
            pat = re.compile(r"(^|[\s.{,])[\"']?" + re.escape(needle) + r"[\"']?\s*[=.\]]", re.I)
            for i, line in enumerate(self.lines):
                if pat.search(line):
                    return self._loc(i)
        return SourceLocation(self.path)

    def _loc(self, i: int) -> SourceLocation:
        if not (0 <= i < len(self.lines)):
            return SourceLocation(self.path)
        line = self.lines[i]
        col = len(line) - len(line.lstrip()) + 1
        return SourceLocation(self.path, i + 1, col, line.strip())


def _line_text(text: str, line: int) -> str:
    lines = text.splitlines()
    return lines[line - 1].strip() if 1 <= line <= len(lines) else ""


def _stem(path: str) -> str:
    return os.path.splitext(os.path.basename(path))[0]


# --- validation shared by TOML files and presets ----------------------------
def _number(
    value: object,
    what: str,
    loc: SourceLocation,
    positive: bool = True,
    most: float | None = None,
    least: float | None = None,
) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise MachineError(f"{what} must be a number, not {type(value).__name__}", loc)
    try:
        v = float(value)
    except OverflowError:  # a TOML integer beyond float64
        raise MachineError(f"{what} is out of range", loc) from None
    if not math.isfinite(v):
        raise MachineError(f"{what} must be finite, not {value}", loc)
    if positive and v <= 0:
        raise MachineError(f"{what} must be positive, not {value}", loc)
    if most is not None and abs(v) > most:
        raise MachineError(f"{what} = {value} is out of range (at most {most:g})", loc)
    if least is not None and v < least:
        raise MachineError(f"{what} = {value} is out of range (at least {least:g})", loc)
    return v


def machine_from_data(
    data: dict[str, Any],
    source: str,
    locate: Callable[[tuple[str, ...], str | None], SourceLocation],
    default_name: str = "machine",
) -> Machine:
    """Validate TOML-shaped ``data`` into a ``Machine``.

    ``locate(table_path, key)`` returns the ``SourceLocation`` used in errors.
    """
    unknown = [k for k in data if k not in _TOP_KEYS]
    if unknown:
        raise MachineError(f"unknown key '{unknown[0]}' (allowed: {', '.join(_TOP_KEYS)})", locate((), unknown[0]))
    defaults: dict[str, str] = {}  # Machine.defaults: what this source leaves out
    name = data.get("name", default_name)
    if not isinstance(name, str):
        raise MachineError("name must be a string", locate((), "name"))
    if "name" not in data:
        defaults["name"] = f"'{name}', the file name (no name key)"

    dt_s = DEFAULT_DT_S
    if "dt" not in data:
        defaults["dt"] = f"{DEFAULT_DT_S:g} s (no dt key)"
    else:
        dt_s = _number(data["dt"], "dt (sample period, s)", locate((), "dt"))
        if dt_s < DT_MIN_S:
            raise MachineError(f"dt = {dt_s} s is shorter than {DT_MIN_S:g} s", locate((), "dt"))
        if dt_s > _MAX_DT_S:
            raise MachineError(f"dt = {dt_s} s is longer than {_MAX_DT_S} s (dt is in seconds)", locate((), "dt"))

    kind, params = "trivial", {}
    if "kinematics" not in data:
        defaults["kinematics"] = "trivial (no kinematics key)"
    kin = data.get("kinematics", "trivial")
    if isinstance(kin, str):
        kind = kin
        kin_loc = locate((), "kinematics")
    elif isinstance(kin, dict):
        params = dict(kin)
        kind = params.pop("type", None)
        kin_loc = locate(("kinematics",), "type")
        if not isinstance(kind, str):
            raise MachineError('[kinematics] needs type = "trivial" or "xyzac-trt"', locate(("kinematics",), None))
    else:
        raise MachineError("kinematics must be a name or a table", locate((), "kinematics"))
    if kind not in KINEMATICS:
        raise MachineError(f"unknown kinematics '{kind}' (known: {', '.join(KINEMATICS)})", kin_loc)
    given = {key.replace("-", "_").lower() for key in params}
    try:
        params = normalise_params(kind, params)
    except MachineError as exc:
        bad = re.search(r"'([^']+)'", exc.message)
        raise MachineError(exc.message, locate(("kinematics",), bad.group(1) if bad else None)) from None
    for key in params:
        if key not in given:
            defaults[f"kinematics.{key}"] = f"{params[key]:g} mm (not in the [kinematics] table)"

    axes_data = data.get("axes")
    if axes_data is None:
        raise MachineError("no [axes.X] tables: the machine needs at least one axis", locate((), None))
    if not isinstance(axes_data, dict) or not axes_data:
        raise MachineError("axes must hold one table per axis, e.g. [axes.X]", locate((), "axes"))
    letters: list[str] = []
    limits: dict[str, list[float]] = {k: [] for k in _AXIS_KEYS}
    for raw_letter, table in axes_data.items():
        letter = raw_letter.upper()
        where = ("axes", raw_letter)
        if len(letter) != 1 or letter not in ALL_AXES:
            raise MachineError(f"unknown axis '{raw_letter}' (axes are {', '.join(ALL_AXES)})", locate(where, None))
        if letter in letters:
            raise MachineError(f"axis {letter} is defined twice", locate(where, None))
        if not isinstance(table, dict):
            raise MachineError(f"axis {letter} must be a table with vmax, amax, jmax", locate(("axes",), raw_letter))
        for key in table:
            if key not in _AXIS_KEYS:
                raise MachineError(
                    f"unknown key '{key}' in axis {letter} (allowed: vmax, amax, jmax)", locate(where, key)
                )
        unit = "deg" if letter in ROTARY_AXES else "mm"
        for key in _AXIS_KEYS:
            if key not in table:
                raise MachineError(f"axis {letter} has no {key} ({_LIMIT_NAMES[key]} limit)", locate(where, None))
            power = "/s" if key == "vmax" else "/s^2" if key == "amax" else "/s^3"
            what = f"axis {letter} {key} ({unit}{power})"
            limits[key].append(_number(table[key], what, locate(where, key), most=LIMIT_MAX[key], least=LIMIT_MIN[key]))
        _, why = ramp_problem(limits["vmax"][-1], limits["amax"][-1], limits["jmax"][-1], dt_s)
        if why:
            raise MachineError(f"axis {letter} {why}", locate(where, None))
        letters.append(letter)
    axes = "".join(letters)
    if kind == "xyzac-trt":
        missing = [a for a in "XYZAC" if a not in axes]
        if missing:
            raise MachineError(
                f"kinematics 'xyzac-trt' needs axes X, Y, Z, A, C; missing {', '.join(missing)}", kin_loc
            )

    start = np.zeros(len(axes))
    if "start" not in data:
        defaults["start"] = "0 on every axis (no [start] table)"
    else:
        st = data["start"]
        if not isinstance(st, dict):
            raise MachineError("start must be a table of axis positions, e.g. start = {Z = 50}", locate((), "start"))
        for key, value in st.items():
            if key.upper() not in axes:
                raise MachineError(
                    f"start position for '{key}', which is not an axis of this machine ({axes})",
                    locate(("start",), key),
                )
            start[axes.index(key.upper())] = _number(
                value, f"start {key}", locate(("start",), key), positive=False, most=START_MAX
            )
        unnamed = [a for a in axes if a not in {key.upper() for key in st}]
        if unnamed:
            defaults["start"] = f"0 on {', '.join(unnamed)} (not in the [start] table)"

    tol_mm = None
    if "tol" not in data:
        defaults["tol"] = "none: the fit's default tolerance or --tol (no tol key)"
    else:
        tol_mm = _number(data["tol"], "tol (mm)", locate((), "tol"), most=TOL_MAX_MM)
    if "description" in data and not isinstance(data["description"], str):
        raise MachineError("description must be a string", locate((), "description"))
    noop_mcodes = _toml_noop_mcodes(data.get("gcode"), locate)
    program_units = _toml_program_units(data.get("gcode"), locate)

    return Machine(
        name=name,
        axes=axes,
        vmax=np.asarray(limits["vmax"], dtype=float),
        amax=np.asarray(limits["amax"], dtype=float),
        jmax=np.asarray(limits["jmax"], dtype=float),
        dt_s=dt_s,
        kinematics=kind,
        kinematics_params=params,
        start=start,
        tol_mm=tol_mm,
        source=source,
        defaults=defaults,
        noop_mcodes=noop_mcodes,
        program_units=program_units,
    )


def _toml_program_units(table: object, locate: Callable[[tuple[str, ...], str | None], SourceLocation]) -> str:
    """``[gcode] program_units = "inch"``: the units a program starts in (default mm);
    ``_toml_noop_mcodes`` has checked the table."""
    if not isinstance(table, dict) or "program_units" not in table:
        return "mm"
    units = table["program_units"]
    if not isinstance(units, str) or units not in PROGRAM_UNITS_MM:
        known = " or ".join(f'"{u}"' for u in PROGRAM_UNITS_MM)
        raise MachineError(f"program_units must be {known}", locate(("gcode",), "program_units"))
    return str(units)


def _toml_noop_mcodes(table: object, locate: Callable[[tuple[str, ...], str | None], SourceLocation]) -> frozenset[int]:
    """``[gcode] noop_mcodes = [29, 100]``: the M-codes the machine declares no-ops."""
    if table is None:
        return frozenset()
    if not isinstance(table, dict):
        raise MachineError("gcode must be a table, e.g. [gcode] noop_mcodes = [29, 100]", locate((), "gcode"))
    for key in table:
        if key not in _GCODE_KEYS:
            raise MachineError(
                f"unknown key '{key}' in [gcode] (allowed: {', '.join(_GCODE_KEYS)})", locate(("gcode",), key)
            )
    codes = table.get("noop_mcodes", [])
    loc = locate(("gcode",), "noop_mcodes")
    if not isinstance(codes, list) or any(isinstance(c, bool) or not isinstance(c, int) for c in codes):
        raise MachineError("noop_mcodes must be a list of M-code numbers, e.g. [29, 100] for M29 and M100", loc)
    problem = noop_mcode_problem(codes)
    if problem:
        raise MachineError(problem, loc)
    return frozenset(codes)


# --- LinuxCNC INI ------------------------------------------------------------
class _Ini:
    """LinuxCNC INI: sections of ``KEY = value`` (repeated keys kept in order), line numbers."""

    def __init__(self, text: str, path: str):
        self.path = path
        self.lines = text.splitlines()
        self.sections: dict[str, tuple[int, dict[str, list[tuple[str, int]]]]] = {}
        current = None
        for i, raw in enumerate(self.lines, start=1):
            line = raw.strip()
            if not line or line[0] in "#;":
                continue
            if line.startswith("["):
                end = line.find("]")
                if end < 0:
                    raise MachineError("unterminated section header", self.loc(i))
                name = line[1:end].strip().upper()
                current = self.sections.setdefault(name, (i, {}))[1]
                continue
            if "=" not in line or current is None:
                continue  # LinuxCNC ignores such lines too
            key, _, value = line.partition("=")
            current.setdefault(key.strip().upper(), []).append((value.strip(), i))

    def loc(self, line: int) -> SourceLocation:
        text = self.lines[line - 1].strip() if 1 <= line <= len(self.lines) else ""
        raw = self.lines[line - 1] if 1 <= line <= len(self.lines) else ""
        return SourceLocation(self.path, line, len(raw) - len(raw.lstrip()) + 1, text)

    def get(self, section: str, key: str) -> tuple[str, int] | None:
        sec = self.sections.get(section)
        if sec is None or key not in sec[1]:
            return None
        return sec[1][key][0]

    def number(self, section: str, key: str, positive: bool = True) -> float | None:
        item = self.get(section, key)
        if item is None:
            return None
        value, line = item
        token = value.split()[0] if value.split() else ""
        try:
            v = float(token)
        except ValueError:
            raise MachineError(f"[{section}] {key} must be a number", self.loc(line)) from None
        if not math.isfinite(v) or (positive and v <= 0):
            raise MachineError(f"[{section}] {key} must be a positive finite number", self.loc(line))
        return v


_LINEAR_UNITS = {
    "mm": 1.0,
    "metric": 1.0,
    "millimeter": 1.0,
    "millimetre": 1.0,
    "inch": MM_PER_INCH,
    "in": MM_PER_INCH,
    "imperial": MM_PER_INCH,
}
_ANGULAR_UNITS = {
    "degree": 1.0,
    "deg": 1.0,
    "degrees": 1.0,
    "radian": 180.0 / math.pi,
    "rad": 180.0 / math.pi,
    "radians": 180.0 / math.pi,
    "grad": 0.9,
    "gon": 0.9,
}


def _units(ini: _Ini, key: str, table: dict[str, float]) -> float:
    item = ini.get("TRAJ", key)
    if item is None:
        return 1.0
    value, line = item
    word = value.split()[0].lower() if value.split() else ""
    if word in table:
        return table[word]
    try:  # old form: machine units per mm (or per degree)
        per = float(word)
    except ValueError:
        raise MachineError(f"[TRAJ] {key}: unknown unit '{value}' (known: {', '.join(table)})", ini.loc(line)) from None
    if not math.isfinite(per) or per <= 0:
        raise MachineError(f"[TRAJ] {key} must be positive", ini.loc(line))
    return 1.0 / per


def _load_ini(text: str, path: str) -> Machine:
    ini = _Ini(text, path)
    if "TRAJ" not in ini.sections:
        raise MachineError("LinuxCNC INI file has no [TRAJ] section", SourceLocation(path, 1, 1))
    coords = ini.get("TRAJ", "COORDINATES")
    if coords is not None:
        value, line = coords
        letters = value.replace(",", " ").upper()
        letters = "".join(letters.split())
        bad = [c for c in letters if c not in ALL_AXES]
        if bad or not letters:
            raise MachineError(f"[TRAJ] COORDINATES: '{value}' is not a list of axis letters", ini.loc(line))
        joint_letters = letters
    else:
        # no COORDINATES: the axes with an [AXIS_n] / [AXIS_L] section, in canonical order
        present = set()
        for sec in ini.sections:
            m = re.fullmatch(r"AXIS_(\d|[XYZABCUVW])", sec)
            if m:
                tag = m.group(1)
                present.add(ALL_AXES[int(tag)] if tag.isdigit() and int(tag) < 9 else tag)
        joint_letters = "".join(a for a in ALL_AXES if a in present)
        n_axes = ini.number("TRAJ", "AXES")
        if not joint_letters and n_axes is not None and float(n_axes).is_integer() and n_axes <= 9:
            joint_letters = ALL_AXES[: int(n_axes)]  # old configs: AXES = n means the first n letters
        if not joint_letters:
            raise MachineError(
                "[TRAJ] has no COORDINATES and no [AXIS_n] sections define axes", ini.loc(ini.sections["TRAJ"][0])
            )
    axes = "".join(dict.fromkeys(joint_letters))  # a gantry's second joint is the same axis

    lin = _units(ini, "LINEAR_UNITS", _LINEAR_UNITS)
    ang = _units(ini, "ANGULAR_UNITS", _ANGULAR_UNITS)
    program_units = "inch" if lin > PROGRAM_INCH_ABOVE_MM else "mm"
    defaults: dict[str, str] = {}  # Machine.defaults: what the INI leaves out
    if ini.get("TRAJ", "LINEAR_UNITS") is None and any(a not in ROTARY_AXES for a in axes):
        defaults["linear_units"] = "mm (no [TRAJ] LINEAR_UNITS)"
    if ini.get("TRAJ", "ANGULAR_UNITS") is None and any(a in ROTARY_AXES for a in axes):
        defaults["angular_units"] = "degree (no [TRAJ] ANGULAR_UNITS)"

    vmax, amax, jmax = [], [], []
    for letter in axes:
        candidates = [f"AXIS_{letter}", f"AXIS_{ALL_AXES.index(letter)}", f"JOINT_{joint_letters.index(letter)}"]
        section = next((s for s in candidates if s in ini.sections), None)
        if section is None:
            raise MachineError(
                f"axis {letter} has no [{candidates[0]}] (or [{candidates[1]}], [{candidates[2]}]) section",
                ini.loc(ini.sections["TRAJ"][0]),
            )
        scale = ang if letter in ROTARY_AXES else lin
        v = ini.number(section, "MAX_VELOCITY")
        a = ini.number(section, "MAX_ACCELERATION")
        if v is None or a is None:
            missing = "MAX_VELOCITY" if v is None else "MAX_ACCELERATION"
            raise MachineError(f"[{section}] has no {missing}", ini.loc(ini.sections[section][0]))
        j = ini.number(section, "MAX_JERK")
        vmax.append(v * scale)
        amax.append(a * scale)
        # documented default: full acceleration reached in 1/DEFAULT_JERK_PER_ACCEL_1_S s
        jmax.append(j * scale if j is not None else DEFAULT_JERK_PER_ACCEL_1_S * a * scale)
        if j is None:
            unit = "deg" if letter in ROTARY_AXES else "mm"
            defaults[f"jmax.{letter}"] = (
                f"{DEFAULT_JERK_PER_ACCEL_1_S:g}/s x amax = {jmax[-1]:g} {unit}/s^3 (no MAX_JERK in [{section}])"
            )

    period = ini.number("EMCMOT", "SERVO_PERIOD")
    dt_s = period * 1e-9 if period is not None else DEFAULT_DT_S
    if dt_s > _MAX_DT_S:
        item = ini.get("EMCMOT", "SERVO_PERIOD")
        line = item[1] if item is not None else 0  # period is not None: the key is there
        raise MachineError("[EMCMOT] SERVO_PERIOD is in nanoseconds; this is longer than 1 s", ini.loc(line))
    if period is None:
        defaults["dt"] = f"{DEFAULT_DT_S:g} s (no [EMCMOT] SERVO_PERIOD)"
    name_item = ini.get("EMC", "MACHINE")
    name = name_item[0] if name_item else _stem(path)
    if not name_item:
        defaults["name"] = f"'{name}', the file name (no [EMC] MACHINE)"
    kind = _ini_kinematics(ini, axes)
    if ini.get("KINS", "KINEMATICS") is None:
        defaults["kinematics"] = "trivial (no [KINS] KINEMATICS)"
    params = normalise_params(kind, {})
    for key in params:
        defaults[f"kinematics.{key}"] = "0 mm (LinuxCNC sets pivot offsets by HAL pins, not in the INI)"
    defaults["start"] = "0 on every axis (an INI gives no start position)"
    defaults["tol"] = "none: the fit's default tolerance or --tol (an INI gives no tolerance)"
    table = ini.get("EMCIO", "TOOL_TABLE")
    tool_table = None
    if table is not None and table[0].strip():  # relative to the INI file, as LinuxCNC reads it
        tool_table = os.path.join(os.path.dirname(os.path.abspath(path)), table[0].strip())
    return Machine(
        name=name,
        axes=axes,
        vmax=np.asarray(vmax, dtype=float),
        amax=np.asarray(amax, dtype=float),
        jmax=np.asarray(jmax, dtype=float),
        dt_s=dt_s,
        kinematics=kind,
        kinematics_params=params,
        source=path,
        tool_table=tool_table,
        defaults=defaults,
        noop_mcodes=_ini_user_mcodes(ini, path),
        program_units=program_units,
        max_path_mm_s=_ini_path_speed(ini, lin),
    )


def _ini_path_speed(ini: _Ini, mm_per_unit: float) -> float | None:
    """``[TRAJ] MAX_LINEAR_VELOCITY`` (else the older ``MAX_VELOCITY``), machine units per
    s, in mm/s: the tool's path speed limit over the linear axes; None without either."""
    for key in _PATH_SPEED_KEYS:
        v = ini.number("TRAJ", key)
        if v is None:
            continue
        v_mm_s = v * mm_per_unit
        if not LIMIT_MIN["vmax"] <= v_mm_s <= LIMIT_MAX["vmax"]:
            item = ini.get("TRAJ", key)
            line = item[1] if item is not None else 0
            raise MachineError(
                f"[TRAJ] {key} = {v_mm_s:g} mm/s is out of range [{LIMIT_MIN['vmax']:g}, {LIMIT_MAX['vmax']:g}]",
                ini.loc(line),
            )
        return v_mm_s
    return None


def _ini_user_mcodes(ini: _Ini, path: str) -> frozenset[int]:
    """The user M-codes LinuxCNC would run for this INI: M100 to M199 with a program file
    of that name (``M101``) in ``[RS274NGC] USER_M_PATH`` (folders separated by ``:``) or
    ``[DISPLAY] PROGRAM_PREFIX``, relative to the INI's folder. They move no axis the
    planner knows of, so the reader takes them as no-ops."""
    base = os.path.dirname(os.path.abspath(path))
    folders: list[str] = []
    for section, key in (("RS274NGC", "USER_M_PATH"), ("DISPLAY", "PROGRAM_PREFIX")):
        item = ini.get(section, key)
        if item is not None:
            folders += [os.path.join(base, os.path.expanduser(f.strip())) for f in item[0].split(":") if f.strip()]
    found = set()
    for folder in folders:
        try:
            names = os.listdir(folder)
        except OSError:
            continue  # LinuxCNC skips a folder it cannot read too
        for name in names:
            m = re.fullmatch(r"M(\d{3})", name)
            if m and int(m.group(1)) in USER_MCODES and os.path.isfile(os.path.join(folder, name)):
                found.add(int(m.group(1)))
    return frozenset(found)


#: LinuxCNC kinematics module -> ours (pivot offsets are HAL pins, not INI keys: 0 here)
_INI_KINS = {"trivkins": "trivial", "xyzac-trt-kins": "xyzac-trt"}


def _ini_kinematics(ini: _Ini, axes: str) -> str:
    item = ini.get("KINS", "KINEMATICS")
    if item is None:
        return "trivial"
    value, line = item
    module = value.split()[0] if value.split() else "trivkins"
    if module not in _INI_KINS:
        raise MachineError(
            f"[KINS] KINEMATICS: '{module}' is not supported (supported: {', '.join(_INI_KINS)})", ini.loc(line)
        )
    kind = _INI_KINS[module]
    if kind == "xyzac-trt" and any(a not in axes for a in "XYZAC"):
        raise MachineError("xyzac-trt-kins needs axes X, Y, Z, A, C", ini.loc(line))
    return kind


# --- presets listing ---------------------------------------------------------
def preset_table() -> list[dict[str, Any]]:
    """One JSON-able dict per preset: name, description, dt, kinematics, per-axis limits."""
    rows = []
    for key in sorted(PRESETS):
        m = _preset(key)
        d = m.to_dict()
        rows.append(
            {
                "preset": key,
                "description": PRESETS[key][0],
                "name": m.name,
                "axes": m.axes,
                "dt_s": m.dt_s,
                "kinematics": m.kinematics,
                "default": key == DEFAULT_PRESET,
                "limits": d["limits"],
            }
        )
    return rows


def format_presets(table: list[dict[str, Any]]) -> str:
    """Human-readable listing of ``preset_table()``."""
    out = []
    for row in table:
        tag = " (default)" if row.get("default") else ""
        out.append(f"{row['preset']}{tag}: {row['name']} - {row['description']}")
        out.append(f"  axes {row['axes']}, dt {row['dt_s'] * 1000:g} ms, kinematics {row['kinematics']}")
        out.extend(_limit_lines(row["limits"]))
        out.append("")
    return "\n".join(out).rstrip()


def _limit_lines(limits: dict[str, dict[str, Any]]) -> list[str]:
    out = [f"  {'axis':>4} {'vmax':>10} {'amax':>10} {'jmax':>10}  unit"]
    for axis, lim in limits.items():
        u = lim["unit"]
        out.append(
            f"  {axis:>4} {lim['vmax']:>10.6g} {lim['amax']:>10.6g} {lim['jmax']:>10.6g}  {u}/s, {u}/s^2, {u}/s^3"
        )
    return out


# --- one machine, as read ----------------------------------------------------
def describe_machine(spec: str) -> dict[str, Any]:
    """How ``load_machine(spec)`` reads ``spec``, JSON-able: ``Machine.to_dict()`` plus
    ``spec``, ``format`` (``preset``, ``toml`` or ``ini``), ``description`` (a preset's),
    ``tool_table`` and ``defaults`` (``Machine.defaults``: what the reader filled in).
    Raises ``MachineError`` as ``load_machine`` does."""
    m = load_machine(spec)
    if spec in PRESETS:
        fmt, description = "preset", PRESETS[spec][0]
    else:
        fmt, description = ("ini" if _is_ini(spec, _machine_text(spec)) else "toml"), None
    return {
        **m.to_dict(),
        "spec": spec,
        "format": fmt,
        "description": description,
        "tool_table": m.tool_table,
        "defaults": dict(m.defaults),
        "max_path_binds": _path_speed_binds(m),
    }


def _path_speed_binds(m: Machine) -> str | None:
    """Where ``m.max_path_mm_s`` binds against the linear axes' own vmax, as a phrase (None
    without a limit): on every linear move, on moves along some axes, only on diagonal
    moves (the axes' vmax combined), or never."""
    cap = m.max_path_mm_s
    if cap is None:
        return None
    lin = ~m.rotary
    if not lin.any():
        return "never binds: the machine has no linear axis"
    vmax = m.vmax[lin]
    combined = float(np.sqrt((vmax**2).sum()))
    if cap < float(vmax.min()):
        return "binds on every linear move (below every linear axis's vmax)"
    faster = [a for a, v in zip(m.axes, m.vmax) if a not in ROTARY_AXES and v > cap]
    if faster:
        return f"binds on moves along {', '.join(faster)} (below their vmax) and diagonal moves"
    if m.path_speed_cap_mm_s is None:  # the one rule of where the reader applies it
        return f"never binds (at or above the linear axes' combined vmax, {combined:g} mm/s)"
    above = "at or above every linear axis's vmax"
    return f"binds on diagonal moves only ({above}, below their combined {combined:g} mm/s)"


_FORMAT_NAMES = {"preset": "built-in preset", "toml": "TOML machine file", "ini": "LinuxCNC INI file"}


def format_machine(desc: dict[str, Any]) -> str:
    """Human-readable form of ``describe_machine(spec)``."""
    about = f" - {desc['description']}" if desc["description"] else ""
    out = [f"{desc['spec']}: {desc['name']} ({_FORMAT_NAMES[desc['format']]}){about}"]
    out.append(f"  axes {desc['axes']}, dt {desc['dt_s'] * 1000:g} ms, kinematics {desc['kinematics']}")
    if desc["kinematics_params"]:
        params = ", ".join(f"{k} {v:g} mm" for k, v in desc["kinematics_params"].items())
        out.append(f"  kinematics parameters: {params}")
    tol = "not set" if desc["tol_mm"] is None else f"{desc['tol_mm']:g} mm"
    out.append(f"  tol {tol}")
    units = {a: lim["unit"] for a, lim in desc["limits"].items()}
    out.append("  start " + ", ".join(f"{a} {v:g} {units[a]}" for a, v in desc["start"].items()))
    if desc["tool_table"]:
        out.append(f"  tool table {desc['tool_table']}")
    if desc["noop_mcodes"]:
        out.append("  no-op M-codes " + " ".join(f"M{c}" for c in desc["noop_mcodes"]))
    read_in = "inches (G20)" if desc["program_units"] == "inch" else "mm (G21)"
    out.append(f"  program units {desc['program_units']}: a program without G20/G21 is read in {read_in}")
    if desc["max_path_mm_s"] is not None:
        out.append(f"  path speed limit {desc['max_path_mm_s']:g} mm/s over the linear axes: {desc['max_path_binds']}")
    out.extend(_limit_lines(desc["limits"]))
    if desc["defaults"]:
        out.append("  defaults applied (not given by the source):")
        out.extend(f"    {key}: {why}" for key, why in desc["defaults"].items())
    else:
        out.append("  defaults applied: none")
    return "\n".join(out)
