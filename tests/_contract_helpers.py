"""Helpers for the end-to-end contract tests: run the CLI, read its CSV back.

Two ways to run ``cnc-interp``:

* ``run_inproc`` calls the console-script entry point ``cnc_interp.cli.run`` (the real
  error-to-exit-code mapping) in this process with argv/stdin/stdout/stderr swapped:
  fast, since numba's compiled planner stays loaded between runs;
* ``run_proc`` starts the installed console script in a subprocess (with a timeout),
  for what only a real process shows: pipes, signals, hash randomisation.
"""

from __future__ import annotations

import io
import os
import shutil
import subprocess
import sys
from dataclasses import dataclass

import numpy as np

from .conftest import CORPUS, HERE, REPO, SAMPLES  # noqa: F401  (re-exported to the tests)

#: one plan of a small program, even on a loaded 2-core machine
PROC_TIMEOUT_S = 300


def console_script() -> str:
    """The installed ``cnc-interp`` script beside this interpreter (else on PATH)."""
    cand = os.path.join(os.path.dirname(sys.executable), "cnc-interp")
    if os.path.exists(cand):
        return cand
    found = shutil.which("cnc-interp")
    if found is None:  # pragma: no cover - the package is installed for the tests
        raise RuntimeError("cnc-interp console script not found")
    return found


@dataclass
class Result:
    code: int
    out: bytes
    err: str

    def explain(self) -> str:
        return f"exit {self.code}; stderr:\n{self.err}"


def run_inproc(*args, stdin: bytes = b"") -> Result:
    """Run ``cnc-interp ARGS`` through ``cli.run`` in this process."""
    from cnc_interp import cli

    saved = sys.argv, sys.stdin, sys.stdout, sys.stderr
    out_buf, err_buf = io.BytesIO(), io.BytesIO()
    out = io.TextIOWrapper(out_buf, encoding="utf-8", write_through=True)
    err = io.TextIOWrapper(err_buf, encoding="utf-8", errors="backslashreplace", write_through=True)
    sys.argv = ["cnc-interp", *map(str, args)]
    sys.stdin = io.TextIOWrapper(io.BytesIO(stdin), encoding="utf-8")
    sys.stdout, sys.stderr = out, err
    code = 0
    try:
        cli.run()
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    finally:
        out.flush()
        err.flush()
        sys.argv, sys.stdin, sys.stdout, sys.stderr = saved
    return Result(code, out_buf.getvalue(), err_buf.getvalue().decode("utf-8", "replace"))


def run_proc(
    *args, stdin: bytes | None = None, env: dict | None = None, cwd: str | None = None, timeout: float = PROC_TIMEOUT_S
) -> Result:
    """Run the installed console script in a subprocess."""
    full_env = dict(os.environ)
    full_env.pop("CNC_INTERP_DEBUG", None)
    full_env.update(env or {})
    r = subprocess.run(
        [console_script(), *map(str, args)],
        input=stdin if stdin is not None else b"",
        capture_output=True,
        timeout=timeout,
        env=full_env,
        cwd=cwd,
    )
    return Result(r.returncode, r.stdout, r.stderr.decode("utf-8", "replace"))


@dataclass
class PlanCsv:
    header: list[str]
    fields: list[list[str]]  # the text of every field, row by row
    data: np.ndarray  # (K, 3 + n) float64: t, s, feed, axes...

    @property
    def q(self) -> np.ndarray:
        return self.data[:, 3:]


def parse_plan_csv(raw: bytes) -> PlanCsv:
    """Split a plan CSV strictly: ASCII, ``\\n`` line ends, one header, equal-length rows."""
    text = raw.decode("ascii")
    assert text.endswith("\n"), "CSV must end with a newline"
    assert "\r" not in text, "CSV must use \\n line ends"
    lines = text[:-1].split("\n")
    header = lines[0].split(",")
    fields = [ln.split(",") for ln in lines[1:]]
    bad = [i for i, f in enumerate(fields) if len(f) != len(header)]
    assert not bad, f"row {bad[0] + 2} has {len(fields[bad[0]])} fields, header {len(header)}"
    data = np.array([[float(x) for x in f] for f in fields], dtype=np.float64)
    return PlanCsv(header, fields, data.reshape(len(fields), len(header)))


def one_error_line(res, code: int = 2) -> str:
    """The run failed with ``code`` and exactly one ``...: error: ...`` line, no traceback."""
    assert res.code == code, res.explain()
    lines = [ln for ln in res.err.splitlines() if ln.strip()]
    assert len(lines) == 1 and ": error: " in lines[0], res.explain()
    assert "Traceback" not in res.err and "internal error" not in res.err
    return lines[0]
