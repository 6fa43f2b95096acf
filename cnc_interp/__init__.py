"""cnc-interp: G-code in, jerk-limited axis setpoints out.

::

    import cnc_interp as ci
    m = ci.load_machine("generic-mill")
    traj = ci.plan(ci.fit(ci.read_program("samples/gcode/mill-contour.ngc", machine=m)), m)
    assert ci.verify(traj, m).ok
    ci.write(traj, "plan.csv")

The package is a pipeline, one subpackage per stage::

    gcode  ->  fit  ->  plan  ->  export
                  \\->  fpga

with the public calls in ``api`` (re-exported here) and the command line (``cli``) on
top. Importing the package is cheap: the API's names are loaded on first use (PEP 562),
and nothing heavy (matplotlib, USB, numba) is imported here. It only checks (about
20 ms) that numba's cached kernels are not older than a module they call
(``_kernel_cache``), and asks numba for LLVM optimisation level ``NUMBA_OPT_LEVEL``
unless ``NUMBA_OPT`` is set or numba is already imported.
"""

__version__ = "0.1.0"

#: public names -> the module that defines them (loaded on first attribute access)
_LAZY = {
    "load_machine": "api",
    "read_program": "api",
    "verify": "api",
    "write": "api",
    "run": "api",
    "estimate": "api",
    "Estimate": "plan.breakdown",
    "PlanResult": "api",
    "DEFAULT_PLANNER": "api",
    "CncInterpError": "errors",
    "GCodeError": "errors",
    "MachineError": "errors",
    "FitError": "errors",
    "PlanError": "errors",
    "UsageError": "errors",
    "Machine": "machine.model",
    "Program": "gcode.program",
    "FitResult": "fit.result",
    "Trajectory": "plan.trajectory",
    "VerifyReport": "plan.verify",
    "PLANNER_NAMES": "plan.planners",
    # typed settings the API takes (``fit(settings=...)``, ``plan(settings=...)``)
    "FitSettings": "fit.settings",
    "PlanSettings": "plan.settings",
    "OptimalOptions": "plan.settings",
    "VpopOptions": "plan.settings",
    "Paper000Options": "plan.settings",
}

#: the stage packages that are also calls (``_stage_call``): ``fit(program)``, ``plan(...)``
_STAGE_CALLS = ("fit", "plan")

__all__ = ["__version__", *_LAZY, *_STAGE_CALLS]


def __getattr__(name: str):
    import importlib

    if name in _STAGE_CALLS:  # importing the package sets the attribute itself
        return importlib.import_module(f"{__name__}.{name}")
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'cnc_interp' has no attribute {name!r}")

    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(__all__)


def _refresh_kernel_cache() -> None:
    import os

    from ._kernel_cache import refresh

    try:
        refresh(os.path.dirname(os.path.abspath(__file__)))
    except OSError:  # a read-only or vanishing tree: numba copes, the import must not fail
        pass


#: numba's LLVM optimisation level for the package's kernels (``NUMBA_OPT``). Level 1
#: compiles them in ~12 % less time than numba's default 3 (a first run's ~95 CPU-s) and
#: the plans are the same bytes; the planners ran no slower at level 1 on the project's
#: 2-core machine (zigzag_0.002_0.001 and stellabee1)
NUMBA_OPT_LEVEL = "1"


def _numba_opt_level() -> None:
    import os
    import sys

    if "numba" not in sys.modules:  # numba reads it once, at its import
        os.environ.setdefault("NUMBA_OPT", NUMBA_OPT_LEVEL)


_numba_opt_level()
_refresh_kernel_cache()
