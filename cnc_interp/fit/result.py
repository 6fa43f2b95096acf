"""``FitResult``: the fit stage's output for a whole program, as a timeline."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..gcode.program import Dwell, Program, Stop
from .path import Path

if TYPE_CHECKING:
    from ..errors import FitError

#: one entry of the fitted timeline
FittedItem = Path | Dwell | Stop


@dataclass(frozen=True)
class FitResult:
    """A program's timeline with every run replaced by fitted paths.

    ``items`` keeps program order. A ``Path`` is planned from rest to rest: two
    consecutive paths mean the machine stops between them (a sharp corner, a
    rapid move, an exact-stop node). Each path starts exactly where the previous
    item left the machine. Rapid moves are paths with ``rapid=True``, one straight
    segment each, in joint space.

    ``stats`` holds fit statistics (nodes in, segments out, max node deviation in
    mm, max continuity residuals...) as plain JSON-able values.
    """

    program: Program
    items: tuple[FittedItem, ...]
    stats: dict[str, Any] = field(default_factory=dict)

    @property
    def paths(self) -> tuple[Path, ...]:
        return tuple(it for it in self.items if isinstance(it, Path))


def require_within_tolerance(result: FitResult) -> FitResult:
    """``result`` unchanged when every fitted path is within its tolerance; otherwise
    ``FitError`` (exit 1) naming the first source line where it is not: a fit status is
    an outcome, never just a line of the report."""
    st = result.stats
    if st.get("within_tolerance", True):
        return result
    run: dict[str, Any] = next((r for r in st.get("runs", []) if r.get("outside_lines")), {})
    raise fit_outside_error(run, result.program.source, st)


def fit_outside_error(run_info: dict[str, Any], source: str, stats: dict[str, Any] | None = None) -> "FitError":
    """The ``FitError`` (exit 1) for a run whose fit misses its tolerance (``run_info``:
    the fit's per-run statistics; ``stats``: the program's, for its worst ratios)."""
    from ..errors import FitError, SourceLocation

    st = stats if stats is not None else run_info
    lines = run_info.get("outside_lines") or [0, 0]
    span = f"lines {lines[0]}-{lines[1]}" if lines[1] != lines[0] else f"line {lines[0]}"
    return FitError(
        f"the fitted path misses the tolerance on {span} (path deviation "
        f"{st.get('max_path_dev_ratio', 0.0):.3f}, rotary {st.get('max_path_dev_rot_ratio', 0.0):.3f} "
        f"of the tolerance) and could not be repaired; please report it",
        SourceLocation(file=source, line=int(lines[0])),
    )
