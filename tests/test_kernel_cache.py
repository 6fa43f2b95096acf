"""numba's cache files are dropped when a module, or a package module it imports, changes."""

from __future__ import annotations

import os

from cnc_interp._kernel_cache import STAMP_NAME, refresh


def _tree(root):
    files = {
        "__init__.py": "",
        "a.py": "from .b import f\n\n\ndef k():\n    return f()\n",
        "b.py": "def f():\n    return 1\n",
        "c.py": "X = 1\n",
        "sub/__init__.py": "from . import d\n",
        "sub/d.py": "from ..b import (\n    f,\n)\n",
    }
    for rel, text in files.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)


def _caches(root):
    made = {
        "__pycache__": [
            "a.k-4.py311.nbi",
            "a.k-4.py311.1.nbc",
            "b.f-1.py311.nbi",
            "c.g-1.py311.nbi",
            "a.cpython-311.pyc",
        ],
        "sub/__pycache__": ["d.h-1.py311.nbi", "__init__.x-1.py311.nbi"],
    }
    for folder, names in made.items():
        (root / folder).mkdir(parents=True, exist_ok=True)
        for n in names:
            (root / folder / n).write_bytes(b"x")


def _left(root):
    return sorted(
        os.path.relpath(os.path.join(d, f), root)
        for d, _, fs in os.walk(root)
        for f in fs
        if f.endswith((".nbi", ".nbc"))
    )


def test_first_run_drops_everything_then_only_what_changed(tmp_path):
    root = tmp_path / "pkg"
    _tree(root)
    _caches(root)
    # no record yet: every cache may predate it
    assert refresh(str(root)) == ["a", "b", "c", "sub", "sub.d"]  # "" has no cache files
    assert _left(root) == []
    assert (root / "__pycache__" / STAMP_NAME).is_file()
    assert (root / "__pycache__" / "a.cpython-311.pyc").exists()  # Python's own cache is kept
    # nothing changed: nothing dropped
    _caches(root)
    assert refresh(str(root)) == []
    assert len(_left(root)) == 6
    # b changes: b, a (imports b), sub.d (imports ..b) and sub (imports .d) lose theirs
    (root / "b.py").write_text("def f():\n    return 2\n")
    dropped = refresh(str(root))
    assert dropped == ["a", "b", "sub", "sub.d"]
    assert _left(root) == [os.path.join("__pycache__", "c.g-1.py311.nbi")]
    # a change of c alone touches c only
    _caches(root)
    (root / "c.py").write_text("X = 2\n")
    assert refresh(str(root)) == ["c"]


def test_unwritable_cache_folder_is_left_alone(tmp_path, monkeypatch):
    root = tmp_path / "pkg"
    _tree(root)
    _caches(root)
    monkeypatch.setattr(os, "access", lambda *a, **k: False)
    assert refresh(str(root)) == []
    assert len(_left(root)) == 6


def test_numba_cache_dir_is_where_the_kernels_are_looked_for(tmp_path, monkeypatch):
    # numba's own rule (``_UserProvidedCacheLocator``): <NUMBA_CACHE_DIR>/<folder>_<sha1 of
    # the folder's path>; a cache there counts, one in the package's __pycache__ does not
    import hashlib

    from cnc_interp._kernel_cache import missing_kernels

    PLAN_KERNEL_MODULES = ("fit._arclen", "plan.vpop.step")
    root = tmp_path / "pkg"
    cache = tmp_path / "cache"
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(cache))
    for mod in PLAN_KERNEL_MODULES:
        *pkg, name = mod.split(".")
        src = str(root.joinpath(*pkg))
        d = cache / f"{pkg[-1]}_{hashlib.sha1(src.encode()).hexdigest()}"
        d.mkdir(parents=True, exist_ok=True)
        (d / f"{name}.kernel-1.py311.nbi").write_bytes(b"")
        pyc = root.joinpath(*pkg, "__pycache__")
        pyc.mkdir(parents=True, exist_ok=True)
    assert missing_kernels(str(root), PLAN_KERNEL_MODULES) == []
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    assert missing_kernels(str(root), PLAN_KERNEL_MODULES) == list(PLAN_KERNEL_MODULES)
