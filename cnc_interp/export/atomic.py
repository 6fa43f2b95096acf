"""Atomic output files: write to a temporary file beside the target, then rename.

A reader never sees a half-written file, and an interrupted run (an exception,
Ctrl-C) leaves the previous file, or none, and no temporary file behind.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from typing import BinaryIO, Iterator

from ..errors import SourceLocation, UsageError


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def check_writable(path: str) -> None:
    """Fail now, with the error ``atomic_write`` would give later, when ``path`` cannot be
    written: its folder is missing or not writable, or it is a folder. (Planning a long
    program first and failing at the end would waste the run.)"""
    if path == "-":
        return
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise UsageError("cannot write output: No such file or directory", SourceLocation(file=path))
    if os.path.isdir(path):
        raise UsageError("cannot write output: Is a directory", SourceLocation(file=path))
    if not os.access(directory, os.W_OK | os.X_OK):
        raise UsageError("cannot write output: Permission denied", SourceLocation(file=path))


@contextlib.contextmanager
def atomic_write(path: str) -> Iterator[BinaryIO]:
    """Yield a binary file object whose content replaces ``path`` only on success.

    ``path == "-"`` writes to standard output (no atomicity there). A
    ``BrokenPipeError`` from stdout is left to propagate: the CLI turns it into a
    quiet exit.
    """
    if path == "-":
        out = sys.stdout.buffer
        yield out
        out.flush()
        return
    directory = os.path.dirname(os.path.abspath(path))
    base = os.path.basename(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{base}.", suffix=".tmp", dir=directory)
    except OSError as exc:
        raise UsageError(f"cannot write output: {exc.strerror}", SourceLocation(file=path)) from None
    try:
        with os.fdopen(fd, "wb") as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        # mkstemp creates 0600; give the file the mode a plain open() would
        os.chmod(tmp, 0o666 & ~_umask())
        try:
            os.replace(tmp, path)
        except OSError as exc:
            raise UsageError(f"cannot write output: {exc.strerror}",
                             SourceLocation(file=path)) from None
    except BaseException:  # includes KeyboardInterrupt: never leave the temporary file
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
