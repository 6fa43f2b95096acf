"""Every program of the shared corpus parses, or ends in a clean, located CncInterpError.

The corpus lives outside the repository (``../shared/corpus``, see its README). The
table below lists the programs known to use a construct this reader rejects on
purpose; every other program must parse. A traceback (any other exception) fails.
"""

from __future__ import annotations

import glob
import os

import numpy as np
import pytest

from cnc_interp.errors import CncInterpError
from cnc_interp.gcode import Run, read_program

from .conftest import CORPUS_ROOT as CORPUS  # noqa: E402

FILES = sorted(glob.glob(os.path.join(CORPUS, "**", "*.ngc"), recursive=True))

#: program (relative to the corpus) -> text its error message must contain
EXPECTED_ERRORS = {
    # G2.2 is no RS274NGC code (LinuxCNC rejects it too)
    "linuxcnc/nurbs-g5/Curva_Stella #1=1_G5.ngc": "unknown G-code G2.2",
    # a lathe tapping cycle: G7 diameter mode, then spindle-synchronised G33.1
    "linuxcnc/violation_checks/tap-discrimant-error-orig.ngc": "G7 lathe diameter mode",
    # radii differ by 0.68 %: LinuxCNC 2.9 refuses it too (its limit is 0.1 %)
    "linuxcnc/violation_checks/spreadsheeterrors.ngc": "not on the circle",
}


def _rel(path: str) -> str:
    return os.path.relpath(path, CORPUS).replace(os.sep, "/")


@pytest.mark.corpus
def test_corpus_is_there():
    assert len(FILES) >= 100


@pytest.mark.corpus
@pytest.mark.parametrize("path", FILES, ids=[_rel(f) for f in FILES])
def test_corpus_program(path):
    rel = _rel(path)
    with open(path, "rb") as fh:
        data = fh.read()
    expected = EXPECTED_ERRORS.get(rel)
    try:
        prog = read_program(data, source=rel)
    except CncInterpError as exc:
        assert expected is not None, f"unexpected error: {exc.format()}"
        assert expected in exc.message, exc.format()
        loc = exc.location
        assert loc.file == rel and loc.line > 0 and loc.col > 0
        return
    assert expected is None, f"expected an error containing {expected!r}"
    for it in prog.items:
        if isinstance(it, Run):
            assert it.nodes.shape[1] == len(prog.axes)
            assert np.all(np.isfinite(it.nodes))
            assert np.all(it.feed_mm_s > 0)
            assert it.n_nodes >= 2
            assert it.line.shape == (it.n_nodes,)
            for cp in it.curves:
                assert 0 <= cp.first < cp.last < it.n_nodes
