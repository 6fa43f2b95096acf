"""cnc-interp: G-code in, jerk-limited axis setpoints out.

The package is a pipeline, one subpackage per stage::

    gcode  ->  fit  ->  plan  ->  export
                  \\->  fpga

Importing the package is cheap: no stage, and nothing heavy (matplotlib, USB,
numba), is imported here.
"""

__version__ = "0.1.0"
