"""Shared test set-up: where the samples and the corpus are, one CLI runner, program files.

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

needs_corpus = pytest.mark.skipif(not HAVE_CORPUS, reason=f"corpus not found at {CORPUS}")


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


@pytest.fixture
def gcode_file(tmp_path):
    """Write a part program: ``gcode_file("G1 X1 F600", name="p.ngc")`` -> its path. A
    program without ``M2``/``M30`` gets one."""

    def make(text: str, name: str = "part.ngc"):
        if "M2" not in text.upper() and "M30" not in text.upper():
            text = text.rstrip("\n") + "\nM2\n"
        path = tmp_path / name
        path.write_text(text if text.endswith("\n") else text + "\n")
        return path

    return make
