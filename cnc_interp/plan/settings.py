"""``PlanSettings``: which planner runs and at which sample period."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

from ..constants import DEFAULT_DT_S
from ..errors import UsageError

if TYPE_CHECKING:
    from ..machine.model import Machine

#: the planner of ``plan`` and ``batch`` when none is named (``stream`` has its own).
#: VPOp, not ``optimal``: optimal's cycles are 1.3 % shorter over the corpus, but it plans
#: 5.6x slower there and took more than 15 min on stellabee1 (VPOp ~1 min): a default
#: must not make the user wait that long (issue 13's note)
DEFAULT_PLANNER = "vpop"


@dataclass(frozen=True)
class PlanSettings:
    """How a program is planned.

    Attributes:
        planner: ``"optimal"`` (near-time-optimal, ``plan.optimal``), ``"vpop"`` (paper
            001), ``"constant"`` or ``"variable"`` (paper 000).
        dt_s: sample period, s.
        tol_mm: fit tolerance the plan was made for (informational), mm.
        options: planner-specific extras (plain JSON-able values), read with ``get``.
    """

    planner: str = DEFAULT_PLANNER
    dt_s: float = DEFAULT_DT_S
    tol_mm: float | None = None
    options: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        from .planners import PLANNER_NAMES

        if self.planner not in PLANNER_NAMES:
            raise UsageError(f"unknown planner '{self.planner}' (known: {', '.join(PLANNER_NAMES)})")
        if not (isinstance(self.dt_s, (int, float)) and math.isfinite(self.dt_s) and self.dt_s > 0):
            raise UsageError(f"sample period must be a positive number of seconds, got {self.dt_s!r}")

    @classmethod
    def from_options(
        cls,
        planner: str = DEFAULT_PLANNER,
        dt_s: float | None = None,
        tol_mm: float | None = None,
        machine: "Machine | None" = None,
        **options: Any,
    ) -> "PlanSettings":
        """Settings from CLI options: ``--dt`` wins over the machine's period, then the default."""
        if dt_s is None:
            dt_s = float(machine.dt_s) if machine is not None and machine.dt_s else DEFAULT_DT_S
        if tol_mm is None and machine is not None and machine.tol_mm:
            tol_mm = float(machine.tol_mm)
        return cls(planner=planner, dt_s=float(dt_s), tol_mm=tol_mm, options=dict(options))

    def get(self, key: str, default: Any = None) -> Any:
        """A planner option (paper-000 planners read their extras this way)."""
        return self.options.get(key, default)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able form (stored in ``Trajectory.settings``)."""
        return asdict(self)
