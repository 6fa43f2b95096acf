"""Built-in machine presets (``cnc-interp machines``), in mm, deg and s.

Each preset is the plain data a TOML machine file would hold; ``load``
validates it through the same code path as a file.
"""

from __future__ import annotations

from typing import Any

from ..constants import SECONDS_PER_MINUTE

_DEG_PER_REV = 360.0
_MM_PER_M = 1000.0


def _rpm(x: float) -> float:
    return x * _DEG_PER_REV / SECONDS_PER_MINUTE


#: name -> (one-line description, TOML-shaped data)
PRESETS: dict[str, tuple[str, dict[str, Any]]] = {
    "generic-mill": (
        "typical small 3-axis vertical machining centre, 1 kHz servo",
        {
            "name": "Generic 3-axis mill",
            "dt": 0.001,
            "kinematics": "trivial",
            "axes": {a: {"vmax": 200.0, "amax": 2000.0, "jmax": 50000.0} for a in "XYZ"},
        },
    ),
    "mikron-ucp710": (
        "Mikron UCP 710 5-axis, paper 001 Table 1 (Siemens 840D, 6 ms); xyzac-trt, pivot offsets 0 (not published)",
        {
            "name": "Mikron UCP 710",
            "dt": 0.006,
            # The paper gives no pivot geometry: offsets 0 make the A and C axes
            # pass through the program origin (override in a machine file).
            "kinematics": "xyzac-trt",
            "axes": {
                # 30 m/min; 2.5 / 3 / 2.1 m/s^2; 5 / 5 / 50 m/s^3
                "X": {"vmax": 30 * _MM_PER_M / SECONDS_PER_MINUTE, "amax": 2.5 * _MM_PER_M, "jmax": 5 * _MM_PER_M},
                "Y": {"vmax": 30 * _MM_PER_M / SECONDS_PER_MINUTE, "amax": 3.0 * _MM_PER_M, "jmax": 5 * _MM_PER_M},
                "Z": {"vmax": 30 * _MM_PER_M / SECONDS_PER_MINUTE, "amax": 2.1 * _MM_PER_M, "jmax": 50 * _MM_PER_M},
                # 15 / 20 rpm; 0.83 rev/s^2; 5 / 100 rev/s^3
                "A": {"vmax": _rpm(15), "amax": 0.83 * _DEG_PER_REV, "jmax": 5 * _DEG_PER_REV},
                "C": {"vmax": _rpm(20), "amax": 0.83 * _DEG_PER_REV, "jmax": 100 * _DEG_PER_REV},
            },
        },
    ),
    "xz-lathe": (
        "2-axis XZ lathe, 1 kHz servo",
        {
            "name": "XZ lathe",
            "dt": 0.001,
            "kinematics": "trivial",
            "axes": {a: {"vmax": 100.0, "amax": 1500.0, "jmax": 30000.0} for a in "XZ"},
        },
    ),
}

#: the machine used when a command needs one and none is given
DEFAULT_PRESET = "generic-mill"
