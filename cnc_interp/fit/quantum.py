"""The printed precision of a program's coordinates.

CAM output rounds every coordinate to a fixed number of decimals (0.0001 in is
2.54 µm). A printed point is only known to ±½ of that quantum, so a fit held to a
tolerance below it traces the rounding and the planner crawls along its curvature.
``coordinate_quantum`` finds the quantum from the program itself: the coarsest
decimal grid, in mm or in inches, that holds the displacement of every straight
feed move (displacements, not positions, so work offsets and G92 shifts do not
matter; arcs and splines are sampled, not printed, and are left out). Coordinates
computed by expressions fall on no grid and give no quantum.

Only a fine quantum counts (``FIT_QUANTUM_MAX_MM`` / ``FIT_QUANTUM_MAX_DEG``):
coordinates printed to 0.01 mm or 0.001 in (hand-written programs, "X12.5") are
taken as exact, not as ±5 µm samples of something else.
"""

from __future__ import annotations

import numpy as np

from ..constants import LINEAR_AXES, MM_PER_INCH
from ..gcode.program import Program, Run


#: quantum of printed coordinates (fit/quantum.py): decimals tried (10^-D mm and 10^-D in)
FIT_QUANTUM_MAX_DECIMALS = 6

#: only a quantum up to this (mm) widens the tolerance by its half: 0.0001 in (2.54 µm) and
#: 0.001 mm count; coordinates printed to 0.01 mm or 0.001 in are taken as exact values
FIT_QUANTUM_MAX_MM = 0.003

#: the same for rotary axes (deg): 0.001° counts, 0.01° does not
FIT_QUANTUM_MAX_DEG = 0.003

#: a displacement is on a grid q when it is within this many q of a multiple of q (float
#: rounding of inch -> mm and offsets is ~1e-11 q; a random value passes with odds 2e-6)
FIT_QUANTUM_MATCH = 1e-6

#: fewer straight feed moves than this in a program: no quantum is inferred
FIT_QUANTUM_MIN_MOVES = 16

#: displacements tested first, before a candidate grid is checked on all of them
_PROBE = 4096


def _move_displacements(run: Run, lin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nonzero per-axis displacements of the run's straight moves: (linear mm, rotary deg)."""
    nodes = np.asarray(run.nodes, dtype=float)
    if nodes.shape[0] < 2:
        return np.zeros(0), np.zeros(0)
    d = np.diff(nodes, axis=0)
    straight = np.ones(d.shape[0], dtype=bool)
    for cp in run.curves:  # moves inside a curve are samples of it
        straight[cp.first : cp.last] = False
    d = d[straight]
    dl, dr = d[:, lin].ravel(), d[:, ~lin].ravel()
    return dl[dl != 0], dr[dr != 0]


def _on_grid(delta: np.ndarray, q: float) -> bool:
    """Every displacement an integer multiple of q (within float rounding)."""
    if delta.size > _PROBE:
        r = delta[:_PROBE] / q
        if not np.all(np.abs(r - np.rint(r)) <= FIT_QUANTUM_MATCH):
            return False
    r = delta / q
    return bool(np.all(np.abs(r - np.rint(r)) <= FIT_QUANTUM_MATCH))


def _candidates(units: tuple[tuple[float, str], ...]) -> list[tuple[int, float, str]]:
    """Every grid 10^-D x unit considered, coarsest decimals first: (D, quantum, label)."""
    return [
        (dec, factor * 10.0**-dec, f"{10.0**-dec:.{dec}f} {name}")
        for dec in range(FIT_QUANTUM_MAX_DECIMALS + 1)
        for factor, name in units
    ]


class QuantumDetector:
    """The quantum of the printed coordinates of the feed moves seen so far.

    Runs are added in program order (``add_run``); ``result`` is the coarsest decimal
    grid, in mm or in inches (degrees for rotary axes), that holds the displacement of
    every straight feed move added. The state is one flag per candidate grid, so the
    detector needs no memory of the moves and a stream can ask for the quantum before
    the program's end: the fit of a run uses the quantum of the runs up to it (the same
    value in a stream and in a whole-program fit, whatever the stream's windows).
    """

    def __init__(self) -> None:
        self._lin = _candidates(((1.0, "mm"), (MM_PER_INCH, "in")))
        self._rot = _candidates(((1.0, "deg"),))
        self._lin_ok = [True] * len(self._lin)
        self._rot_ok = [True] * len(self._rot)
        self._lin_seen = self._rot_seen = False
        self.n_moves = 0

    def add_run(self, run: Run) -> None:
        """Take in the straight moves of ``run`` (rapid runs are ignored)."""
        if run.kind != "feed":
            return
        lin = np.array([a in LINEAR_AXES for a in run.axes], dtype=bool)
        dl, dr = _move_displacements(run, lin)
        self.n_moves += max(run.n_nodes - 1, 0)
        if dl.size:
            self._lin_seen = True
            self._update(np.abs(dl), self._lin, self._lin_ok)
        if dr.size:
            self._rot_seen = True
            self._update(np.abs(dr), self._rot, self._rot_ok)

    @staticmethod
    def _update(delta: np.ndarray, cands, ok: list[bool]) -> None:
        for k, (_, q, _) in enumerate(cands):
            if ok[k]:
                ok[k] = _on_grid(delta, q)

    @staticmethod
    def _best(seen: bool, cands, ok: list[bool]) -> tuple[float, str]:
        """The coarsest decimals any unit holds; of those, the larger quantum."""
        if not seen:
            return 0.0, ""
        best, best_dec = (0.0, ""), FIT_QUANTUM_MAX_DECIMALS
        for k, (dec, q, label) in enumerate(cands):
            if dec > best_dec:
                break
            if ok[k] and q > best[0]:
                best, best_dec = (q, label), dec
        return best

    def result(self) -> dict:
        """``coordinate_quantum``'s dict for the moves added so far."""
        out = dict(detected_mm=0.0, detected_deg=0.0, label_mm="", label_deg="", quantum_mm=0.0, quantum_deg=0.0)
        if self.n_moves < FIT_QUANTUM_MIN_MOVES:
            return out
        q, label = self._best(self._lin_seen, self._lin, self._lin_ok)
        out.update(detected_mm=q, label_mm=label, quantum_mm=q if q <= FIT_QUANTUM_MAX_MM else 0.0)
        q, label = self._best(self._rot_seen, self._rot, self._rot_ok)
        out.update(detected_deg=q, label_deg=label, quantum_deg=q if q <= FIT_QUANTUM_MAX_DEG else 0.0)
        return out


def coordinate_quantum(program: Program) -> dict:
    """The quantum of the program's printed coordinates.

    Returns a dict: ``detected_mm`` / ``detected_deg`` (the grid found, 0 if none),
    ``label_mm`` / ``label_deg`` (e.g. "0.0001 in"), and ``quantum_mm`` /
    ``quantum_deg``: the quantum the fit allows for (the detected one where it is at
    most ``FIT_QUANTUM_MAX_MM`` / ``_DEG``, else 0).
    """
    det = QuantumDetector()
    for run in program.runs:
        det.add_run(run)
    return det.result()
