"""Shared test set-up: where the samples and the corpus are, program factories and one
CLI runner.

Module constants (importable as ``from conftest import CORPUS``, since pytest puts this
folder on ``sys.path``) for parametrisation at collection time; fixtures for the rest.
"""

from __future__ import annotations

import os

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
SAMPLES = os.path.join(REPO, "samples", "gcode")
EXAMPLES = os.path.join(REPO, "examples")
#: LinuxCNC's G-code corpus beside the repository (``../shared``), or CNC_CORPUS
CORPUS = os.environ.get("CNC_CORPUS") or os.path.normpath(os.path.join(REPO, "..", "shared", "corpus", "linuxcnc"))
CORPUS_ROOT = os.path.dirname(CORPUS)  # holds ``linuxcnc/`` (names in reports start there)
HAVE_CORPUS = os.path.isdir(CORPUS)

#: the corpus lane: tests that read the external corpus. Marked ``corpus`` (by hand, or
#: here for a parametrized case whose arguments name a corpus file) and skipped, with
#: CORPUS_SKIP_REASON, where the corpus is absent; ``-m corpus`` runs the lane
needs_corpus = pytest.mark.corpus
CORPUS_SKIP_REASON = (
    f"needs LinuxCNC's G-code corpus at {CORPUS} (../shared beside the clone, or CNC_CORPUS): the corpus lane"
)


def _names_corpus(value) -> bool:
    if isinstance(value, str | os.PathLike):
        return os.path.abspath(os.fspath(value)).startswith(CORPUS_ROOT + os.sep)
    if isinstance(value, tuple | list):
        return any(_names_corpus(v) for v in value)
    return False


@pytest.hookimpl(tryfirst=True)  # before ``-m`` selects by marker
def pytest_collection_modifyitems(config, items):
    skip = pytest.mark.skip(reason=CORPUS_SKIP_REASON)
    for item in items:
        spec = getattr(item, "callspec", None)
        if spec is not None and any(_names_corpus(v) for v in spec.params.values()):
            item.add_marker(pytest.mark.corpus)
        if not HAVE_CORPUS and item.get_closest_marker("corpus") is not None:
            item.add_marker(skip)


@pytest.fixture(scope="session", autouse=True)
def _kernels_compiled():
    """A first run's compile, once for the session (``precompile.ensure``): on a fresh
    clone the pytest-xdist workers would each compile every kernel on its first call; under
    the cache's lock one compiles them on both cores and the others wait, then load them."""
    from cnc_interp import precompile

    precompile.ensure("optimal")


def program_of(text: str, source: str = "t.ngc", **kw):
    """The ``Program`` of G-code ``text`` (``read_program(text, source, **kw)``: ``axes``,
    ``start``, ``tool_table``)."""
    from cnc_interp.gcode import read_program

    return read_program(text, source, **kw)


def fitted_of(text: str, source: str = "t.ngc", axes: str | None = None, **settings):
    """The ``FitResult`` of G-code ``text`` fitted with ``FitSettings(**settings)``."""
    from cnc_interp.fit import FitSettings, fit_program

    kw = {} if axes is None else {"axes": axes}
    return fit_program(program_of(text, source, **kw), FitSettings(**settings))


@pytest.fixture
def cli():
    """Invoke ``cnc-interp`` in process: ``cli("plan", path, "-o", out)`` -> click Result
    (``exit_code``, ``output``, ``exception``: the ``CncInterpError`` for error exits)."""
    from click.testing import CliRunner

    from cnc_interp.cli import main

    runner = CliRunner()

    def invoke(*args, **kwargs):
        return runner.invoke(main, [str(a) for a in args], **kwargs)

    return invoke
