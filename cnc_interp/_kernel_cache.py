"""Keep numba's on-disk kernel cache consistent across source updates.

Numba's cache (``@njit(cache=True)``) is keyed on the source file of each cached function.
A kernel that calls a kernel of another module keeps its old machine code when only that
other module changes — after a ``git pull`` or an edit — and then computes with the old
callee or crashes in the next call (measured: a ``SystemError`` out of an unrelated
kernel). ``refresh`` fixes that at import time, before any kernel loads: it hashes every
module of the package together with the package modules it imports (transitively) and
deletes the cache files of each module whose hash changed since the last run. The first
run without a record deletes them all (older caches may predate the record).

Reading and hashing the package's sources takes about 20 ms. Nothing here
imports numba.
"""

from __future__ import annotations

import hashlib
import json
import os
import re

#: where the hashes of the last run are kept (in the package's own ``__pycache__``)
STAMP_NAME = "cnc-interp-kernel-deps.json"

_LOCAL_IMPORT = re.compile(rb"^[ \t]*from[ \t]+(\.+)([\w.]*)[ \t]+import[ \t]+(\(?[^\n]*)", re.M)


def refresh(root: str) -> list[str]:
    """Delete stale numba cache files under the package directory ``root``; returns the
    modules (relative dotted names) whose cache files were deleted. Does nothing where
    ``root/__pycache__`` cannot be written (numba then caches elsewhere, per user)."""
    pycache = os.path.join(root, "__pycache__")
    try:
        os.makedirs(pycache, exist_ok=True)
    except OSError:
        return []
    if not os.access(pycache, os.W_OK):
        return []
    sources, packages = _read_sources(root)
    hashes = _closure_hashes(sources, packages)
    stamp = os.path.join(pycache, STAMP_NAME)
    try:
        with open(stamp, encoding="utf-8") as fh:
            old = json.load(fh)
    except (OSError, ValueError):
        old = {}
    if old == hashes:
        return []
    dropped = [m for m in sorted(hashes) if old.get(m) != hashes[m] and _drop_cache(root, m, m in packages)]
    tmp = f"{stamp}.{os.getpid()}.tmp"
    try:
        with open(tmp, "w", encoding="utf-8") as fh:
            json.dump(hashes, fh, sort_keys=True)
        os.replace(tmp, stamp)
    except OSError:
        pass
    return dropped


def _read_sources(root: str) -> tuple[dict[str, bytes], set[str]]:
    """Dotted module name (relative to the package; "" for the package itself) -> source
    bytes, and the names that are packages (``__init__.py``)."""
    out = {}
    packages = set()
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if d != "__pycache__")
        for name in sorted(filenames):
            if name.endswith(".py"):
                rel = os.path.relpath(os.path.join(dirpath, name), root)[:-3]
                mod = rel.replace(os.sep, ".")
                if name == "__init__.py":
                    mod = mod[: -len("__init__")].rstrip(".")
                    packages.add(mod)
                with open(os.path.join(dirpath, name), "rb") as fh:
                    out[mod] = fh.read()
    return out, packages


def _imports(mod: str, src: bytes, known: dict, is_pkg: bool) -> set[str]:
    """Package modules that ``mod`` imports with relative imports (``from .x import y``,
    ``from .. import x``); ``is_pkg``: ``mod`` is a package (its ``.`` is itself)."""
    parts = mod.split(".") if mod else []
    found = set()
    for dots, name, names in _LOCAL_IMPORT.findall(src):
        up = len(dots) - (1 if is_pkg else 0)
        if up > len(parts):
            continue
        base = parts[: len(parts) - up]
        target = ".".join(base + ([name.decode()] if name else []))
        if target in known:
            found.add(target)
        if not name:  # from . import a, b
            for n in re.findall(rb"\w+", names):
                cand = ".".join(base + [n.decode()])
                if cand in known:
                    found.add(cand)
        else:
            for n in re.findall(rb"\w+", names):  # from .pkg import module
                cand = target + "." + n.decode()
                if cand in known:
                    found.add(cand)
    return found


def _closure_hashes(sources: dict[str, bytes], packages: set[str]) -> dict[str, str]:
    """Per module, a hash of its source and of every package module it imports, directly
    or not."""
    deps = {m: _imports(m, src, sources, m in packages) for m, src in sources.items()}
    out = {}
    for m in sources:
        seen, todo = {m}, [m]
        while todo:
            for d in deps[todo.pop()]:
                if d not in seen:
                    seen.add(d)
                    todo.append(d)
        h = hashlib.sha256()
        for d in sorted(seen):
            h.update(d.encode() + b"\0" + hashlib.sha256(sources[d]).digest())
        out[m] = h.hexdigest()
    return out


def _drop_cache(root: str, mod: str, is_pkg: bool) -> bool:
    """Delete numba's cache files (``NAME.FUNC-LINE.pyXY[.N].nbi|nbc``) of module ``mod``
    (of its ``__init__.py`` for a package)."""
    parts = mod.split(".") if mod else []
    if is_pkg:
        name, folder = "__init__", os.path.join(root, *parts, "__pycache__")
    else:
        name, folder = parts[-1], os.path.join(root, *parts[:-1], "__pycache__")
    try:
        entries = os.listdir(folder)
    except OSError:
        return False
    dropped = False
    for entry in entries:
        if entry.startswith(name + ".") and entry.endswith((".nbi", ".nbc")):
            try:
                os.remove(os.path.join(folder, entry))
                dropped = True
            except OSError:
                pass
    return dropped


def missing_kernels(root: str, modules) -> list[str]:
    """The ``modules`` (dotted, relative to the package folder ``root``) with no cached
    compiled kernel yet: their first call compiles them."""
    import glob

    out = []
    for mod in modules:
        *pkg, name = mod.split(".")
        folder = _cache_folder(os.path.join(root, *pkg))
        if not glob.glob(os.path.join(glob.escape(folder), f"{name}.*.nbi")):
            out.append(mod)
    return out


def kernel_cached(root: str, module: str, function: str) -> bool:
    """Whether numba's cache holds the kernel ``function`` of ``module`` (dotted, relative
    to the package folder ``root``): numba names its index ``module.function-LINE.pyXY.nbi``."""
    import glob

    *pkg, name = module.split(".")
    folder = _cache_folder(os.path.join(root, *pkg))
    return bool(glob.glob(os.path.join(glob.escape(folder), f"{name}.{function}-*.nbi")))


def _cache_folder(source_dir: str) -> str:
    """Where numba caches the kernels of the modules in ``source_dir``: its
    ``__pycache__``, or under ``NUMBA_CACHE_DIR`` when set, or numba's per-user folder when
    the sources cannot be written (numba's cache locators, in their order)."""
    import hashlib

    source_dir = os.path.abspath(source_dir)
    # numba's ``get_suitable_cache_subpath``: the folder's name and the SHA-1 of its path
    sub = f"{os.path.basename(source_dir)}_{hashlib.sha1(source_dir.encode()).hexdigest()}"
    user_dir = os.environ.get("NUMBA_CACHE_DIR")
    if user_dir:
        return os.path.join(user_dir, sub)
    pycache = os.path.join(source_dir, "__pycache__")
    if os.path.isdir(pycache):
        writable = os.access(pycache, os.W_OK)
    else:  # numba creates it where it can
        writable = not os.path.isdir(source_dir) or os.access(source_dir, os.W_OK)
    if writable:
        return pycache
    xdg = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(xdg, "numba", sub)
