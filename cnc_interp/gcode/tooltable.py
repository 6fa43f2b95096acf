"""LinuxCNC tool tables: the tool length offsets ``G43 Hn`` applies.

One tool per line, words in any order, a comment after ``;``::

    T1 P1 Z+12.5 D6 ;6 mm end mill
    T2 P2 X0.5 Z-3.25 ;lathe tool

``T`` (tool number, required) and ``P`` (pocket) are integers; ``X Y Z A B C U V W`` are the
offsets of each axis, ``D`` the diameter, ``I J Q`` lathe tool data (read, not used). The
offsets are in mm (deg for A, B, C), LinuxCNC's machine units for a metric machine. Blank
and comment-only lines are skipped; anything else is an error with the file's line.
"""

from __future__ import annotations

import math
import os
import re
import stat

from ..constants import ALL_AXES
from ..errors import MachineError, SourceLocation

#: largest tool table read, bytes (a table of thousands of tools is ~100 kB)
TOOL_TABLE_MAX_BYTES = 1 << 22
#: largest tool offset accepted, mm or deg
TOOL_OFFSET_MAX = 1e6

_WORD = re.compile(r"([A-Za-z])\s*([+-]?(?:\d+\.?\d*|\.\d+))")
_OTHER_WORDS = "PDIJQ"


class ToolTable(dict):
    """Tool number -> offsets per axis, a 9-tuple in XYZABCUVW order (mm / deg)."""

    source: str = ""


def read_tool_table(path: str) -> ToolTable:
    """Read a LinuxCNC tool table file; ``MachineError`` (exit 2) with the line on bad input."""
    loc = SourceLocation(file=path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as exc:
        raise MachineError(f"cannot read tool table: {exc.strerror}", loc) from None
    with os.fdopen(fd, "rb") as fh:
        st = os.fstat(fh.fileno())
        if not stat.S_ISREG(st.st_mode) or st.st_size > TOOL_TABLE_MAX_BYTES:
            raise MachineError(f"tool table must be a regular file of at most {TOOL_TABLE_MAX_BYTES} bytes", loc)
        raw = fh.read(TOOL_TABLE_MAX_BYTES + 1)
    text = raw.decode("latin-1")
    return parse_tool_table(text, path)


def parse_tool_table(text: str, source: str = "<tool table>") -> ToolTable:
    """The tools of a tool table's text (see the module docstring)."""
    table = ToolTable()
    table.source = source
    for n, line in enumerate(text.splitlines(), start=1):
        body = line.split(";", 1)[0].strip()
        if not body:
            continue
        pos = 0
        words: dict[str, float] = {}
        for m in _WORD.finditer(body):
            gap = body[pos : m.start()].strip()
            if gap:
                raise MachineError(
                    "tool table: not a word (letter and number)", SourceLocation(source, n, pos + 1, line.strip())
                )
            letter = m.group(1).upper()
            if letter != "T" and letter not in ALL_AXES and letter not in _OTHER_WORDS:
                raise MachineError(
                    f"tool table: unknown word {letter}", SourceLocation(source, n, m.start() + 1, line.strip())
                )
            v = float(m.group(2))
            if not math.isfinite(v) or abs(v) > TOOL_OFFSET_MAX:
                raise MachineError(
                    f"tool table: {letter} out of range", SourceLocation(source, n, m.start() + 1, line.strip())
                )
            words[letter] = v
            pos = m.end()
        if body[pos:].strip():
            raise MachineError(
                "tool table: not a word (letter and number)", SourceLocation(source, n, pos + 1, line.strip())
            )
        tool = words.get("T")
        if tool is None or tool != int(tool) or tool < 0:
            raise MachineError(
                "tool table: each line needs T and a tool number", SourceLocation(source, n, 1, line.strip())
            )
        table[int(tool)] = tuple(words.get(a, 0.0) for a in ALL_AXES)
    return table
