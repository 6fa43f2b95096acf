"""The compiled kernels take few arguments: at most ``MAX_KERNEL_ARGS``.

Arguments that belong together travel as a module-level namedtuple (a joint table,
per-axis limits, scratch buffers, settings), so a call reads like the concept and a
new argument cannot be passed in the wrong position among thirty.
"""

from __future__ import annotations

import ast
import os

import cnc_interp

PKG_DIR = os.path.dirname(cnc_interp.__file__)
MAX_KERNEL_ARGS = 12


def _is_njit(dec: ast.expr) -> bool:
    target = dec.func if isinstance(dec, ast.Call) else dec
    name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
    return name in ("njit", "jit")


def _kernels():
    for d, _, files in os.walk(PKG_DIR):
        for f in sorted(files):
            if not f.endswith(".py"):
                continue
            path = os.path.join(d, f)
            rel = os.path.relpath(path, PKG_DIR).replace(os.sep, "/")
            with open(path, encoding="utf-8") as fh:
                tree = ast.parse(fh.read())
            for node in ast.walk(tree):
                if isinstance(node, ast.FunctionDef) and any(_is_njit(d) for d in node.decorator_list):
                    a = node.args
                    yield rel, node.name, len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs)


def test_the_scan_finds_the_kernels():
    found = {(rel, name) for rel, name, _ in _kernels()}
    names = {name for _, name in found}
    assert {"plan_core", "drive", "track", "lp_rows", "polyline_path_deviation", "refine", "planar_fit_kernel"} <= names
    assert len(found) > 50


def test_no_kernel_takes_more_than_twelve_arguments():
    over = [f"{rel}:{name} takes {n}" for rel, name, n in _kernels() if n > MAX_KERNEL_ARGS]
    assert not over, "bundle these kernels' arguments (namedtuples): " + ", ".join(over)
