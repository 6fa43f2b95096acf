"""The package's floors: a module imports only from its own floor or below.

    base    cnc_interp (root), errors, constants, outfile, _kernel_cache, _stage_call
    machine Machine, its readers (TOML, INI, presets) and kinematics: every stage's input
    gcode   G-code -> Program
    fit     Program -> Paths
    plan    Paths + Machine -> Trajectory
    export | fpga   (siblings: neither imports the other)
    top     api, pipeline, precompile, batch, batch_workers, cli, fpga.commands

Every import counts, also those inside functions (the package imports lazily, so an
upward import would only show when its function runs). The test fails naming the edge.
"""

from __future__ import annotations

import ast
import os

import cnc_interp

PKG_DIR = os.path.dirname(cnc_interp.__file__)

FLOORS = {"base": 0, "machine": 1, "gcode": 2, "fit": 3, "plan": 4, "export": 5, "fpga": 5, "top": 6}
#: the floor of siblings that must not import each other
SIBLINGS = 5
TOP = {"api", "pipeline", "precompile", "batch", "batch_workers", "cli", "fpga.commands"}
BASE = {"", "errors", "constants", "outfile", "inputfile", "_kernel_cache", "_stage_call"}
#: deliberate upward edges, each with its reason
ALLOWED = {
    # calling ``cnc_interp.fit(...)`` / ``cnc_interp.plan(...)`` runs the API function
    ("_stage_call", "api"),
}


def _floor(mod: str) -> str:
    """Floor name of ``mod`` (a dotted name below ``cnc_interp``, '' for the root)."""
    if mod in TOP or any(mod.startswith(t + ".") for t in TOP):
        return "top"
    if mod in BASE:
        return "base"
    head = mod.split(".")[0]
    if head in FLOORS:
        return head
    raise AssertionError(f"module cnc_interp.{mod} is on no floor: add it to this test")


def _modules():
    for d, _, files in os.walk(PKG_DIR):
        for f in files:
            if f.endswith(".py"):
                path = os.path.join(d, f)
                rel = os.path.relpath(path, PKG_DIR)[:-3].replace(os.sep, ".")
                is_pkg = rel.endswith("__init__")
                name = rel[: -len("__init__")].rstrip(".") if is_pkg else rel
                yield name, is_pkg, path


def _imports(name: str, is_pkg: bool, path: str):
    """Dotted names (below ``cnc_interp``) that the module at ``path`` imports."""
    package = name if is_pkg else name.rpartition(".")[0]
    with open(path, encoding="utf-8") as fh:
        tree = ast.parse(fh.read())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".") if package else []
                parts = parts[: len(parts) - node.level + 1]
                base = ".".join(parts + ([node.module] if node.module else []))
            elif node.module and (node.module + ".").startswith("cnc_interp."):
                base = node.module[len("cnc_interp.") :] if node.module != "cnc_interp" else ""
            else:
                continue
            for alias in node.names:
                full = f"{base}.{alias.name}" if base else alias.name
                # ``from . import api`` names a module; ``from .errors import X`` a value
                yield full if os.path.exists(_file_of(full)) else base, node.lineno
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("cnc_interp."):
                    yield alias.name[len("cnc_interp.") :], node.lineno


def _file_of(mod: str) -> str:
    p = os.path.join(PKG_DIR, *mod.split("."))
    return p + ".py" if os.path.exists(p + ".py") else os.path.join(p, "__init__.py")


def test_no_module_imports_from_a_higher_floor():
    bad = []
    for name, is_pkg, path in _modules():
        src = _floor(name)
        for target, line in _imports(name, is_pkg, path):
            dst = _floor(target)
            if (name, target) in ALLOWED or target == name:
                continue
            upward = FLOORS[dst] > FLOORS[src]
            sideways = FLOORS[dst] == FLOORS[src] == SIBLINGS and dst != src
            if upward or sideways:
                bad.append(
                    f"cnc_interp/{os.path.relpath(path, PKG_DIR)}:{line}: {src} imports {dst} (cnc_interp.{target})"
                )
    assert not bad, "\n".join(bad)


def test_the_check_sees_an_upward_import(tmp_path):
    # the checker itself: a gcode module importing the planner is reported
    fake = tmp_path / "bad.py"
    fake.write_text("def f():\n    from ..plan.timeline import plan_program\n")
    found = list(_imports("gcode.bad", False, str(fake)))
    assert ("plan.timeline", 2) in found and FLOORS[_floor("plan.timeline")] > FLOORS["gcode"]


def test_the_machine_floor_is_below_every_stage(tmp_path):
    # Machine's package may import only base; a stage importing it is no upward edge
    fake = tmp_path / "bad.py"
    fake.write_text("from ..gcode.program import Program\nfrom ..errors import MachineError\n")
    found = dict(_imports("machine.bad", False, str(fake)))
    assert FLOORS[_floor("gcode.program")] > FLOORS[_floor("machine.bad")]
    assert FLOORS[_floor("errors")] < FLOORS[_floor("machine.bad")]
    assert set(found) == {"gcode.program", "errors"}
    for stage in ("gcode", "fit", "plan", "export", "fpga", "top"):
        assert FLOORS[stage] > FLOORS["machine"]


#: the sampled planners: none imports another's package for what they share (the step
#: limits, ``plan.step_limits``; the joint table, ``plan.joint_table``), only to call it
PLANNERS = ("plan.vpop", "plan.optimal", "plan.safe")


def _component(mod: str) -> str:
    """The planning stage's unit ``mod`` belongs to: ``plan.X`` (a module or a package)."""
    parts = mod.split(".")
    return ".".join(parts[:2]) if parts[0] == "plan" and len(parts) > 1 else mod


def _plan_graph() -> dict:
    """{unit: units it imports} over the planning stage's modules and packages."""
    graph: dict = {}
    for name, is_pkg, path in _modules():
        src = _component(name)
        if not src.startswith("plan."):
            continue
        for target, _ in _imports(name, is_pkg, path):
            dst = _component(target)
            if dst.startswith("plan.") and dst != src:
                graph.setdefault(src, set()).add(dst)
    return graph


def _reaches(graph: dict, a: str, b: str) -> bool:
    seen, todo = set(), [a]
    while todo:
        for nxt in graph.get(todo.pop(), ()):
            if nxt == b:
                return True
            if nxt not in seen:
                seen.add(nxt)
                todo.append(nxt)
    return False


def test_no_planner_imports_another_that_imports_it_back():
    # VPOp falls back on the safe planner and the optimal planner on both: the edges go
    # one way only (optimal -> vpop, optimal -> safe, vpop -> safe), so no planner needs
    # another's package imported first
    graph = _plan_graph()
    assert _reaches(graph, "plan.optimal", "plan.vpop") and _reaches(graph, "plan.vpop", "plan.safe")
    cycles = [(a, b) for a in PLANNERS for b in PLANNERS if a < b and _reaches(graph, a, b) and _reaches(graph, b, a)]
    assert not cycles, cycles
    for shared in ("plan.step_limits", "plan.joint_table"):
        assert not any(_reaches(graph, shared, p) for p in PLANNERS), shared
