"""cnc-interp: G-code in, jerk-limited axis setpoints out.

The package is a pipeline, one subpackage per stage::

    gcode  ->  fit  ->  plan  ->  export
                  \\->  fpga

Importing the package is cheap: no stage, and nothing heavy (matplotlib, USB,
numba), is imported here. It only checks (about 20 ms) that numba's cached
kernels are not older than a module they call (``_kernel_cache``).
"""

__version__ = "0.1.0"


def _refresh_kernel_cache() -> None:
    import os

    from ._kernel_cache import refresh

    try:
        refresh(os.path.dirname(os.path.abspath(__file__)))
    except OSError:  # a read-only or vanishing tree: numba copes, the import must not fail
        pass


_refresh_kernel_cache()
