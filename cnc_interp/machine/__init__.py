"""The machine tool: ``Machine`` (per-axis limits, sample period, start, tolerance),
its kinematics and the readers that build it.

* ``model.Machine`` is the type every stage takes (the G-code reader its axes, start and
  tool table, the fit its tolerance, the planners and ``verify`` its limits, the FPGA
  stage its fixed-point scales);
* ``load.load_machine(spec)`` reads a TOML file, a LinuxCNC INI file or a built-in
  preset (``presets``) and checks every value, naming the file's line on an error;
* ``kinematics`` maps program coordinates to the machine's joints (``trivial``,
  ``xyzac-trt``).

This package is on the bottom floor with ``errors`` and ``constants``: it imports
nothing else of ``cnc_interp``, so every stage can use it. Nothing heavy is imported
here; ``Machine``, ``load_machine`` and ``DEFAULT_PRESET`` load on first use (PEP 562).
"""

from typing import Any

#: public names -> the submodule that defines them
_LAZY = {"Machine": "model", "load_machine": "load", "DEFAULT_PRESET": "presets"}

__all__ = list(_LAZY)


def __getattr__(name: str) -> Any:
    import importlib

    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
