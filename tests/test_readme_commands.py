"""The documentation is tested: the README's command table lists exactly the options each
command's ``--help`` has, every ``cnc-interp ...`` quoted in README.md or docs/*.md names a
command and options it has, and every code block of those files runs (shell commands and
Python; machine files load), except the commands listed in ``SKIPPED`` with their reason."""

from __future__ import annotations

import glob
import os
import re
import shlex

import click
import pytest

from cnc_interp.cli import main

from ._contract_helpers import run_inproc
from .conftest import CORPUS, REPO

README = os.path.join(REPO, "README.md")
DOCS = [README, *sorted(glob.glob(os.path.join(REPO, "docs", "*.md")))]


def readme_rows() -> dict[str, str]:
    text = open(README, encoding="utf-8").read()
    table = text[text.index("## Commands") : text.index("## Supported G-code")]
    rows = {}
    for m in re.finditer(r"^\| `cnc-interp (\w+)([^`]*)` \|", table, re.M):
        rows[m.group(1)] = m.group(2)
    return rows


def test_every_command_has_a_row():
    assert set(readme_rows()) == set(main.commands)


@pytest.mark.parametrize("name", sorted(main.commands))
def test_row_options_match_help(name):
    cmd = main.commands[name]
    listed = set(re.findall(r"(?<![\w-])(--?[a-zA-Z][\w-]*)", readme_rows()[name]))
    options = [p for p in cmd.params if isinstance(p, click.Option) and "--help" not in p.opts]
    names = {o for p in options for o in p.opts}
    assert listed <= names, f"README lists {sorted(listed - names)}, which {name} --help lacks"
    missing = [p.opts for p in options if not listed & set(p.opts)]
    assert not missing, f"README's {name} row misses {missing}"
    for p in cmd.params:  # and every option explains itself
        if isinstance(p, click.Option):
            assert p.help, f"{name} {p.opts} has no help text"


# -- every `cnc-interp ...` quoted in the docs -------------------------------------------------
def _quoted_commands() -> list[tuple[str, str]]:
    """(FILE:LINE, text) of every inline `cnc-interp CMD ...` of README.md and docs/*.md."""
    found = []
    for path in DOCS:
        text = open(path, encoding="utf-8").read()
        for m in re.finditer(r"(?<!`)`(?:\.venv/bin/)?(cnc-interp [^`]+)`", text):
            where = f"{os.path.relpath(path, REPO)}:{text.count(chr(10), 0, m.start()) + 1}"
            found.append((where, " ".join(m.group(1).split())))
    return found


@pytest.mark.parametrize("where,quoted", _quoted_commands(), ids=[w for w, _ in _quoted_commands()])
def test_quoted_command_names_a_command_and_its_options(where, quoted):
    name = quoted.split()[1]
    assert name in main.commands, f"{where}: `{quoted}`: no command {name!r}"
    cmd = main.commands[name]
    options = {o for p in cmd.params if isinstance(p, click.Option) for o in p.opts}
    listed = set(re.findall(r"(?<![\w-])(--?[a-zA-Z][\w-]*)", quoted))
    assert listed <= options, f"{where}: `{quoted}`: {name} has no {sorted(listed - options)}"


# -- every code block runs -----------------------------------------------------------------------
#: commands of the docs that the tests do not run, each with its reason (regex on the command)
SKIPPED = {
    r"^python3 -m venv ": "creates the virtualenv the tests run in",
    r"^\.venv/bin/pip install ": "installs the package and its dependencies (network); the tests run in the result",
    r"^(\.venv/bin/)?python3? -m pytest\b": "runs the test suite this test is part of",
    r"^(\.venv/bin/)?cnc-interp stream (?!.*--dry-run)": "streams to the FPGA over USB: needs the device",
}
_COMMAND = re.compile(r"^(\$ )?(\.venv/bin/)?(cnc-interp|python3?|pip)\s")
_SHELL = {"sh", "bash", "shell", "console"}


def _blocks() -> list[tuple[str, str, str]]:
    """(FILE:LINE, language, text) of every fenced code block of README.md and docs/*.md."""
    found = []
    for path in DOCS:
        lines = open(path, encoding="utf-8").read().splitlines()
        start = None
        for i, line in enumerate(lines):
            if line.startswith("```"):
                if start is None:
                    start, lang = i, line[3:].strip().lower()
                else:
                    where = f"{os.path.relpath(path, REPO)}:{start + 1}"
                    found.append((where, lang, "\n".join(lines[start + 1 : i]) + "\n"))
                    start = None
    return found


def _kind(lang: str, text: str) -> str:
    """How a block is tested: ``shell``, ``python``, ``toml``/``ini`` (a machine file), or
    ``text`` (a diagram, equations or a command's output: nothing to run)."""
    if lang in _SHELL or (not lang and any(_COMMAND.match(line) for line in text.splitlines())):
        return "shell"
    return lang if lang in ("python", "toml", "ini") else "text"


def _commands(text: str) -> list[str]:
    """The commands of a shell block: lines joined at a trailing backslash, split at ``&&``."""
    out = []
    for line in text.replace("\\\n", " ").splitlines():
        line = line.strip().removeprefix("$ ")
        if line and not line.startswith("#"):
            out.extend(part.strip() for part in line.split("&&"))
    return out


def _block_params():
    params = []
    for where, lang, text in _blocks():
        kind = _kind(lang, text)
        if kind == "text":
            continue
        needs_corpus = "corpus/" in text or "CNC_CORPUS" in text
        marks = [pytest.mark.corpus] if needs_corpus else []
        params.append(pytest.param(kind, text, id=where, marks=marks))
    return params


@pytest.fixture
def docs_dir(tmp_path, monkeypatch):
    """A working directory where the docs' relative paths resolve: ``samples/`` and
    ``examples/`` of the repository, ``../shared/corpus/linuxcnc`` the corpus; outputs
    stay in ``tmp_path``."""
    work = tmp_path / "main"
    work.mkdir()
    for name in ("samples", "examples"):
        os.symlink(os.path.join(REPO, name), work / name)
    if os.path.isdir(CORPUS):
        (tmp_path / "shared" / "corpus").mkdir(parents=True)
        os.symlink(CORPUS, tmp_path / "shared" / "corpus" / "linuxcnc")
    monkeypatch.chdir(work)
    return work


def test_the_docs_have_runnable_blocks():
    found = {(p.id.split(":")[0], p.values[0]) for p in _block_params()}
    assert {("README.md", "shell"), ("README.md", "python"), ("docs/machines.md", "shell")} <= found


@pytest.mark.parametrize("kind,text", _block_params())
def test_code_block_runs(docs_dir, kind, text):
    if kind == "python":
        exec(compile(text, "<docs>", "exec"), {"__name__": "__docs__"})
        return
    if kind in ("toml", "ini"):
        from cnc_interp.machine.load import load_machine

        path = docs_dir / f"machine.{kind}"
        path.write_text(text, encoding="utf-8")
        load_machine(str(path))
        return
    skipped, ran = [], 0
    for command in _commands(text):
        reason = next((why for pat, why in SKIPPED.items() if re.search(pat, command)), None)
        if reason is not None:
            skipped.append(f"`{command}`: {reason}")
            continue
        argv = shlex.split(command)
        assert re.fullmatch(r"(\.venv/bin/)?cnc-interp", argv[0]), (
            f"`{command}`: the docs test runs only cnc-interp commands; run it here or list it in SKIPPED"
        )
        r = run_inproc(*argv[1:])
        assert r.code == 0, f"`{command}`: {r.explain()}"
        ran += 1
    if not ran:
        pytest.skip("; ".join(skipped))
