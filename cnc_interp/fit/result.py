"""``FitResult``: the fit stage's output for a whole program, as a timeline."""

from __future__ import annotations

from dataclasses import dataclass, field

from ..gcode.program import Dwell, Program, Stop
from .path import Path

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
    stats: dict = field(default_factory=dict)

    @property
    def paths(self) -> tuple[Path, ...]:
        return tuple(it for it in self.items if isinstance(it, Path))
