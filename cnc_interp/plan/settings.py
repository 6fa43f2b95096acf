"""``PlanSettings``: which planner runs, at which sample period, with which knobs
(``OptimalOptions``, ``VpopOptions``, ``Paper000Options``: typed, checked on construction)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import TYPE_CHECKING, Any

from ..constants import DEFAULT_DT_S
from ..errors import UsageError
from .tuning import OptimalTuning

if TYPE_CHECKING:
    from ..machine.model import Machine

#: the planner of ``plan``, ``estimate``, ``batch`` and the API when none is named
#: (``stream`` has its own): the near-time-optimal one. Over the corpus its cycle is never
#: longer than VPOp's (a path it cannot shorten keeps VPOp's plan) for at most twice
#: VPOp's planning time (``benchmarks/plan.py --sweep``).
DEFAULT_PLANNER = "optimal"


@dataclass(frozen=True)
class OptimalOptions:
    """Knobs of the ``optimal`` planner (``plan.optimal``); ``None`` keeps its default.

    Attributes:
        effort: how much planning time buys cycle time (``OPTIMAL_EFFORTS``).
            ``"fast"``: the feed profile sampled exactly, unrefined at fine periods (below
            ``OptimalTuning.full_refine_dt``), one pass of window refinement at coarse ones.
            ``"normal"`` (``None``): every window refined at coarse periods; at fine ones
            the profile's dips and ends while that pays (the pause rule). ``"max"``:
            every window of every path refined at every period.
        route: ``"profile"`` (the feed-profile LP) or ``"vpop"`` for every path;
            ``None``: the planner chooses per path (``OptimalTuning.route_*``).
        refine_passes: passes of the window refinement over the sampled plan (default: by
            ``effort``); it overrides the effort's number of passes, not which windows.
        compare_s: a profile-routed path whose rough duration is at most this long, s, is
            planned whole (one LP window when short), and also by VPOp, the shorter plan
            kept (default ``OptimalTuning.compare_samples`` periods); 0: neither (every
            sample then depends on at most one profile window ahead).
        chunk_samples: samples per streamed chunk (default ``OPTIMAL_CHUNK``; the plan
            does not depend on it).
        tuning: the planner's internal tunables (``OptimalTuning``; tests and benchmarks
            set them, a user sets the knobs above).
    """

    effort: str | None = None
    route: str | None = None
    refine_passes: int | None = None
    compare_s: float | None = None
    chunk_samples: int | None = None
    tuning: OptimalTuning = field(default_factory=OptimalTuning)

    def __post_init__(self) -> None:
        if not isinstance(self.tuning, OptimalTuning):
            raise UsageError(f"optimal tuning must be an OptimalTuning, got {type(self.tuning).__name__}")
        if self.effort not in (None, *OPTIMAL_EFFORTS):
            raise UsageError(f"optimal effort must be one of {OPTIMAL_EFFORTS}, got {self.effort!r}")
        if self.route not in (None, *OPTIMAL_ROUTES):
            raise UsageError(f"optimal route must be one of {OPTIMAL_ROUTES}, got {self.route!r}")
        for name in ("refine_passes", "chunk_samples"):
            v = getattr(self, name)
            if v is not None and not (isinstance(v, int) and not isinstance(v, bool) and v >= 0):
                raise UsageError(f"{name} must be a whole number >= 0, got {v!r}")
        c = self.compare_s
        if c is not None and not (_is_number(c) and math.isfinite(c) and c >= 0):
            raise UsageError(f"compare_s must be a number of seconds >= 0, got {c!r}")


@dataclass(frozen=True)
class VpopOptions:
    """Knobs of the ``vpop`` planner (``plan.vpop``).

    Attributes:
        exact: exact mode: every brake run of the step loop must reach rest (more
            conservative, a few samples slower). The default, fast mode, ends a brake
            run early once the state is easy and re-plans exactly from the last
            checkpoint where that fails (``plan.vpop``).
    """

    exact: bool = False


@dataclass(frozen=True)
class Paper000Options:
    """Knobs of paper 000's ``constant`` and ``variable`` planners (``plan.paper000``);
    ``None`` keeps the default named in brackets.

    Attributes:
        curv_accel_share: share of each axis's amax the centripetal term may use at
            cruise (``P000_CURV_ACCEL_SHARE``, 0.8), in (0, 1].
        curv_jerk_share: share of each axis's jmax the path-geometry jerk term may use
            (``P000_CURV_JERK_SHARE``, 0.5), in (0, 1].
        cross_jerk_share: share of the jerk left that the cross term may use
            (``P000_CROSS_JERK_SHARE``, 0.5), in (0, 1].
        merge_band: ``variable``: consecutive segments whose feed caps lie within this
            relative band share one profile piece (``P000_MERGE_BAND``, 0.1; 0 = one
            piece per segment), >= 0.
    """

    curv_accel_share: float | None = None
    curv_jerk_share: float | None = None
    cross_jerk_share: float | None = None
    merge_band: float | None = None

    def __post_init__(self) -> None:
        for name in ("curv_accel_share", "curv_jerk_share", "cross_jerk_share", "merge_band"):
            v = getattr(self, name)
            if v is None:
                continue
            ok = _is_number(v) and math.isfinite(v) and (v >= 0 if name == "merge_band" else 0 < v <= 1)
            if not ok:
                raise UsageError(f"{name} out of range: {v!r}")


#: samples per chunk the optimal planner streams (``OptimalOptions.chunk_samples``)
OPTIMAL_CHUNK = 4096
#: ``optimal``'s routes (``OptimalOptions.route``)
OPTIMAL_ROUTES = ("profile", "vpop")
#: ``optimal``'s planning efforts (``OptimalOptions.effort``, ``--effort``)
OPTIMAL_EFFORTS = ("fast", "normal", "max")


def _is_number(v: object) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


@dataclass(frozen=True)
class PlanSettings:
    """How a program is planned.

    Attributes:
        planner: ``"optimal"`` (near-time-optimal, ``plan.optimal``), ``"vpop"`` (paper
            001), ``"constant"`` or ``"variable"`` (paper 000).
        dt_s: sample period, s.
        tol_mm: fit tolerance the plan was made for (informational), mm.
        optimal: the ``optimal`` planner's knobs.
        vpop: the ``vpop`` planner's knobs (also VPOp inside ``optimal``).
        paper000: the ``constant`` and ``variable`` planners' knobs.
    """

    planner: str = DEFAULT_PLANNER
    dt_s: float = DEFAULT_DT_S
    tol_mm: float | None = None
    optimal: OptimalOptions = field(default_factory=OptimalOptions)
    vpop: VpopOptions = field(default_factory=VpopOptions)
    paper000: Paper000Options = field(default_factory=Paper000Options)

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
        *,
        optimal: OptimalOptions | None = None,
        vpop: VpopOptions | None = None,
        paper000: Paper000Options | None = None,
        effort: str | None = None,
    ) -> "PlanSettings":
        """Settings from CLI options: ``--dt`` wins over the machine's period, then the default;
        ``effort`` (``--effort``) sets ``OptimalOptions.effort`` and is the optimal planner's
        only (a ``UsageError`` with another)."""
        if effort is not None:
            if planner != "optimal":
                raise UsageError(f"--effort applies to --planner optimal, not {planner}")
            optimal = replace(optimal or OptimalOptions(), effort=effort)
        if dt_s is None:
            dt_s = float(machine.dt_s) if machine is not None and machine.dt_s else DEFAULT_DT_S
        if tol_mm is None and machine is not None and machine.tol_mm:
            tol_mm = float(machine.tol_mm)
        return cls(
            planner=planner,
            dt_s=float(dt_s),
            tol_mm=tol_mm,
            optimal=optimal or OptimalOptions(),
            vpop=vpop or VpopOptions(),
            paper000=paper000 or Paper000Options(),
        )

    def options(self) -> dict[str, Any]:
        """The planner knobs that differ from their defaults, by their flat names
        (``route``, ``vpop_exact``, ``curv_accel_share``, ...): what ``to_dict`` records."""
        out: dict[str, Any] = {}
        for group, prefix in ((self.optimal, ""), (self.vpop, "vpop_"), (self.paper000, "")):
            default = type(group)()
            for f in fields(group):
                v = getattr(group, f.name)
                if isinstance(v, OptimalTuning):
                    if v.changed():
                        out["tuning"] = v.changed()
                elif v != getattr(default, f.name):
                    out[prefix + f.name] = v
        return out

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able form (stored in ``Trajectory.settings`` and MCAP metadata):
        planner, dt_s, tol_mm and ``options``, the knobs that differ from their defaults."""
        return {"planner": self.planner, "dt_s": self.dt_s, "tol_mm": self.tol_mm, "options": self.options()}
