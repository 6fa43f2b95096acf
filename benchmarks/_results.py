"""``benchmarks/RESULTS.md``: one current table per benchmark, written by the scripts.

A script calls :func:`write_section` with its table; the section
``## TITLE (`benchmarks/SCRIPT`)`` is replaced (or added) and every other section is left as it
is. Each section starts with the line ``commit X, <arch> with N cores, load L before; command
`...```: the load is the one-minute load average when this module was imported (import it before
measuring). Sections are kept in the order of :data:`ORDER` (the scripts' order in
``docs/performance.md``), then by title, whatever ran last; the file is rewritten atomically
under a lock, so two scripts that finish together do not lose each other's section. History
lives in git.
"""

from __future__ import annotations

import fcntl
import os
import platform
import re
import shlex
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
RESULTS = os.path.join(HERE, "RESULTS.md")
PREAMBLE = (
    "# Benchmark results\n\n"
    "One current table per benchmark, written by the script named in its heading (`--no-write` "
    "prints only). Each names the commit, the machine and the command that made it; earlier "
    "figures are in this file's git history.\n"
)
#: the scripts in the order of their sections
ORDER = (
    "first_run.py",
    "plan.py",
    "optimality.py",
    "e2e.py",
    "estimate.py",
    "planners.py",
    "polyline_vs_exact.py",
    "parse.py",
    "gcode_blocks.py",
    "fit.py",
    "vpop_table.py",
    "verify_csv.py",
    "csv_write.py",
    "export_mcap.py",
    "batch.py",
    "fpga_roundtrip.py",
    "fpga_widths.py",
    "hdl.py",
    "stall_hunter.py",
)
#: the load average before the measurement: taken when the script imports this module
LOAD_BEFORE = os.getloadavg()[0]
_HEADING = re.compile(r"^## (?P<title>.*) \(`benchmarks/(?P<script>[^`]+)`\)\s*$")


def command_line(script: str, argv: list[str] | None = None) -> str:
    """``python benchmarks/SCRIPT ARGS`` as the user typed it (``argv`` default: sys.argv[1:])."""
    args = sys.argv[1:] if argv is None else list(argv)
    return shlex.join(["python", f"benchmarks/{script}", *args])


def commit() -> str:
    """The short commit, with ``+ uncommitted changes`` when tracked files other than RESULTS.md
    differ from it (the figures then belong to the working tree)."""

    def git(*args: str) -> str:
        r = subprocess.run(["git", *args], cwd=REPO, capture_output=True, text=True)
        return r.stdout if r.returncode == 0 else ""

    head = git("rev-parse", "--short", "HEAD").strip() or "unknown"
    changed = [
        ln for ln in git("status", "--porcelain", "--untracked-files=no").splitlines() if not ln.endswith("RESULTS.md")
    ]
    return head + (" + uncommitted changes" if changed else "")


def machine_line(command: str) -> str:
    return (
        f"commit {commit()}, {platform.machine()} with {os.cpu_count()} cores, load {LOAD_BEFORE:.2f} before; "
        f"command `{command}`"
    )


def md_table(header: list[str], rows: list[list]) -> str:
    """A markdown table; cells are written with ``str`` (``|`` escaped)."""

    def cell(v) -> str:
        return str(v).replace("|", "\\|").replace("\n", " ")

    out = ["| " + " | ".join(cell(h) for h in header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(cell(v) for v in row) + " |" for row in rows]
    return "\n".join(out)


def _split(text: str) -> tuple[str, list[tuple[str, str, str]]]:
    """(preamble, [(title, script, section text)]) of RESULTS.md."""
    parts = re.split(r"(?m)^(?=## )", text)
    preamble, sections = parts[0], []
    for part in parts[1:]:
        m = _HEADING.match(part.splitlines()[0])
        title, script = (m["title"], m["script"]) if m else (part.splitlines()[0][3:], "")
        sections.append((title, script, part.rstrip() + "\n"))
    return preamble, sections


def _rank(script: str) -> int:
    return ORDER.index(script) if script in ORDER else len(ORDER)


def write_section(title: str, script: str, command: str, table_markdown: str, notes: str = "") -> str:
    """Replace or add the section ``## TITLE (`benchmarks/SCRIPT`)`` of RESULTS.md; returns its path.

    ``notes``: text printed under the table (what a column means, what was left out)."""
    body = [f"## {title} (`benchmarks/{script}`)", "", machine_line(command), "", table_markdown.strip()]
    if notes.strip():
        body += ["", notes.strip()]
    new = "\n".join(body) + "\n"
    with open(os.path.join(tempfile.gettempdir(), "cnc-interp-benchmarks-results.lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            with open(RESULTS, encoding="utf-8") as fh:
                preamble, sections = _split(fh.read())
        except FileNotFoundError:
            preamble, sections = PREAMBLE, []
        if preamble.strip() == PREAMBLE.splitlines()[0]:
            preamble = PREAMBLE
        sections = [s for s in sections if (s[0], s[1]) != (title, script)] + [(title, script, new)]
        sections.sort(key=lambda s: (_rank(s[1]), s[1], s[0]))  # the same order whatever ran last
        text = preamble.rstrip() + "\n\n" + "\n".join(s[2] for s in sections)
        fd, tmp = tempfile.mkstemp(prefix=".RESULTS.", suffix=".md", dir=HERE)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as fh:
                fh.write(text)
            os.chmod(tmp, 0o644)
            os.replace(tmp, RESULTS)
        except BaseException:
            os.unlink(tmp)
            raise
    print(f"wrote section {title!r} of {os.path.relpath(RESULTS, os.getcwd())}")
    return RESULTS
