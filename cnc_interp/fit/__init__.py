"""The fit stage: runs of G-code nodes -> G2-continuous piecewise quintic ``Path``s.

``fit_program(program, settings) -> FitResult`` is what the pipeline calls;
``fit_run(run, settings) -> list[Path]`` fits one run. See ``fitter.py`` for which
method handles which run, ``planar.py`` (paper 000), ``nodes.py`` (N-axis),
``curves.py`` (arcs / NURBS) and ``corners.py`` (where paths split).
"""

from .fitter import fit_program, fit_run
from .path import Path, PlanarSegments
from .result import FitResult
from .settings import FitSettings

__all__ = ["fit_program", "fit_run", "FitSettings", "Path", "PlanarSegments", "FitResult"]

from .._stage_call import make_callable  # noqa: E402

make_callable(__name__)  # ``cnc_interp.fit(program, tol_mm=...)`` is ``api.fit``
