"""Reading a command's input files with a bound: an endless device or stream (``/dev/zero``,
``yes | cnc-interp plan -``) ends in one clear error, never in memory running out.

Machine files and tool tables have their own, smaller caps where they are read.
"""

from __future__ import annotations

import os
import stat
from typing import BinaryIO

from .constants import MAX_LINE_CHARS
from .errors import SourceLocation, UsageError

#: largest part program read, bytes: about 30 million blocks, far past the largest CAM
#: programs (a million-line program is ~30 MB); the cap stops an endless stream
PART_MAX_BYTES = 1 << 30

#: bytes read at a time while the cap and the line length are checked
READ_CHUNK_BYTES = 1 << 22


def read_bounded(fh: BinaryIO, name: str, limit: int = PART_MAX_BYTES) -> bytes:
    """All of ``fh`` (a part program), at most ``limit`` bytes, in chunks; raises
    ``UsageError`` as soon as the text is longer, or holds a line longer than
    ``MAX_LINE_CHARS`` (``/dev/zero`` is refused after its first megabyte)."""
    chunks: list[bytes] = []
    total = 0
    lines = 0
    since_newline = 0  # bytes after the last newline seen
    while True:
        chunk = fh.read(READ_CHUNK_BYTES)
        if not chunk:
            break
        total += len(chunk)
        if total > limit:
            raise UsageError(f"part program is larger than {limit} bytes", SourceLocation(file=name))
        last = chunk.rfind(b"\n")
        if last < 0:
            since_newline += len(chunk)
        else:
            lines += chunk.count(b"\n")
            since_newline = len(chunk) - last - 1
        if since_newline > MAX_LINE_CHARS:
            raise UsageError(
                f"line is longer than {MAX_LINE_CHARS} characters", SourceLocation(file=name, line=lines + 1, col=1)
            )
        chunks.append(chunk)
    return b"".join(chunks)


def require_regular_file(path: str, what: str) -> None:
    """Raise ``UsageError`` unless ``path`` is a regular file: a plan or frame file is read
    whole, so a device or a pipe (``/dev/zero``) would never end."""
    try:
        st = os.stat(path)
    except OSError as exc:
        raise UsageError(f"cannot read {what}: {exc.strerror}", SourceLocation(file=path)) from None
    if not stat.S_ISREG(st.st_mode):
        raise UsageError(f"{what} must be a regular file (not a device, pipe or folder)", SourceLocation(file=path))
