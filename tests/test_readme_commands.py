"""The README's command table lists exactly the options each command's ``--help`` has."""

from __future__ import annotations

import os
import re

import click
import pytest

from cnc_interp.cli import main

README = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "README.md")


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
