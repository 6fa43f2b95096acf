"""The block iterator: source text -> :class:`Block` objects, O-word control flow applied.

:func:`iter_blocks` is a generator driven lazily by the modal interpreter, so a
parameter the interpreter writes between two blocks (``G10 L2`` offsets, ``#5420``
positions) is seen by later expressions and O-word conditions. Plain CAM lines are
tokenised in bulk by :mod:`.fastpath`, every other line by :mod:`.lexer` (cached
when the program can run it again); O-word control flow lives in :mod:`.oword`.

Conventions (decided here, relied on by the interpreter):

* Lines that are empty, only whitespace, only parameter settings, O-word lines,
  ``%`` lines and deleted lines yield nothing. A line without words but with a
  comment yields a Block with ``words == []`` and the comment (for MSG/DEBUG).
* ``N`` line numbers are dropped. Words keep source order; values are floats
  (``G5.2`` gives ``("G", 5.2, col)``). Word expressions are evaluated with the
  parameter values from *before* the line's ``#n = ...`` settings, which are all
  evaluated first and then applied in order (RS274NGC semantics), before the
  block is yielded.
* Block delete: ``/`` as the first character of a line deletes the line when the
  switch is on. The switch defaults to **on** (``block_delete=True``), LinuxCNC's
  interpreter default; pass ``block_delete=False`` to run those lines.
* ``%``: if the first non-blank, non-comment line is ``%`` it opens the program and
  the next ``%`` line ends it; otherwise a ``%`` line ends the program. Lines after
  the end are not read.
* O-words (LinuxCNC): ``sub/endsub/call/return`` with up to 30 ``[args]`` in
  ``#1..#30`` of a fresh local frame, ``endsub [v]`` / ``return [v]`` setting
  ``#<_value>`` (0 without ``[v]``) and ``#<_value_returned>`` (1 / 0, cleared
  by every call); ``if/elseif/else/endif``;
  ``while/endwhile``; ``do/while``; ``repeat [n]/endrepeat``; ``break``,
  ``continue``. Named (``o<name>``) and numbered (``o100``) forms. Subroutines must
  be defined in this file (LinuxCNC's SUBROUTINE_PATH files are not searched) and
  may be defined after their call. The block structure is checked for the whole
  program before the first block is yielded. Each loop runs at most
  ``LOOP_ITERATION_LIMIT`` times, calls nest at most ``MAX_CALL_DEPTH`` deep.
* M2/M30 end the program: that is the interpreter's job (it stops iterating).
"""

from __future__ import annotations

from collections.abc import Iterator
from itertools import repeat
from typing import NamedTuple

from ..errors import SourceLocation
from .expr import evaluate
from .lexer import EMPTY, PERCENT, WORDS, LineCode, lex_line, snippet
from .oword import Executor, Structure
from .params import ParamStore


#: fast path: source lines tokenised per numpy chunk (bounds memory on huge files): two
#: chunks are kept, ~0.5 kB a line (32768 held 32 MB; 8192 parses as fast within 5 %)
FAST_CHUNK_LINES = 8192


class Block(NamedTuple):
    """One executable source line."""

    line: int  #: 1-based source line number
    words: list  #: [(LETTER, value, col)], source order, N dropped, values evaluated
    text: str  #: the raw source line (latin-1 decoded, no newline)
    comment: str | None  #: text of the line's last comment, if any


_new = tuple.__new__


def iter_blocks(data: bytes | str, source: str, params: ParamStore, *, block_delete: bool = True) -> Iterator[Block]:
    """Blocks of the program ``data`` (bytes are decoded as latin-1).

    ``source`` names the file in error locations. Raises GCodeError (with file,
    line, column and text) or UnsupportedError while iterating.
    """
    return _run(data, source, params, block_delete)


# --------------------------------------------------------------------------- source
class _Source:
    """The program text, its line index and the bulk-tokenised chunks."""

    def __init__(self, data: bytes | str):
        from .fastpath import scan

        # The text is ``b`` decoded as latin-1 (one byte, one character: byte offsets are
        # character offsets), decoded a line or a chunk at a time where it is needed: a
        # decoded copy of the whole file would be held for the whole run (32 MB for a
        # 32 MB program). Only a str holding characters outside latin-1 keeps its text.
        text: str | None = None
        if isinstance(data, str):
            b = data.encode("latin-1", "replace")  # 1 char -> 1 byte keeps offsets
            if b.count(b"?") != data.count("?"):  # characters were replaced
                text = data
        else:
            b = bytes(data)
        if b.startswith(b"\xef\xbb\xbf"):  # a UTF-8 byte order mark (Windows editors)
            b = b[3:]
            if text is not None:
                text = text[3:] if text.startswith("\xef\xbb\xbf") else text.lstrip("\ufeff")
        if b"\r" in b:
            # CRLF (DOS) and CR alone (classic Mac) both end a line
            b = b.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
            if text is not None:
                text = text.replace("\r\n", "\n").replace("\r", "\n")
        if not b.endswith(b"\n"):
            b += b"\n"
            if text is not None:
                text += "\n"
        self.text = text
        self.b = b
        self.line_starts, self.special = scan(b)
        self.n_lines = len(self.special)
        self._chunks: dict[int, tuple] = {}

    def line(self, i: int) -> str:
        """Raw text of 0-based line ``i`` (no newline)."""
        ls = self.line_starts
        if self.text is None:
            return self.b[int(ls[i]) : int(ls[i + 1]) - 1].decode("latin-1")
        return self.text[int(ls[i]) : int(ls[i + 1]) - 1]

    def chunk(self, k: int) -> _Chunk:
        """Chunk ``k`` (FAST_CHUNK_LINES lines), tokenised in bulk."""
        got = self._chunks.get(k)
        if got is None:
            import gc

            l0 = k * FAST_CHUNK_LINES
            l1 = min(l0 + FAST_CHUNK_LINES, self.n_lines)
            # ~10**5 objects are built at once: cyclic GC passes would only slow that down
            enabled = gc.isenabled()
            gc.disable()
            try:
                got = _Chunk(self, l0, l1)
            finally:
                if enabled:
                    gc.enable()
            if len(self._chunks) >= 2:  # a loop may jump back one chunk; keep memory bounded
                self._chunks.pop(next(iter(self._chunks)))
            self._chunks[k] = got
        return got


class _Chunk:
    """The bulk-tokenised plain lines of source lines ``l0 .. l1-1``.

    ``next_slow[j]``: first local line >= j that needs the slow path (or the chunk
    size). ``bidx[j]``: number of plain lines with words before local line j; the
    Blocks of those lines are made on demand by :meth:`blocks` (short-lived objects
    keep the cyclic GC cheap).
    """

    __slots__ = ("next_slow", "bidx", "lines", "_tuples", "_starts", "_ends", "_numbers", "_texts")

    def __init__(self, src: _Source, l0: int, l1: int):
        import numpy as np

        from .fastpath import tokenize_chunk

        slow, offs, self._tuples, lines = tokenize_chunk(src.b, src.text, src.line_starts, src.special, l0, l1)
        n = l1 - l0
        has = (offs[1:] > offs[:-1]) & ~slow
        idx = np.flatnonzero(has)
        self._starts = offs[idx].tolist()
        self._ends = offs[idx + 1].tolist()
        self._numbers = (idx + (l0 + 1)).tolist()
        self._texts = list(map(lines.__getitem__, idx.tolist()))
        self.bidx = np.concatenate(([0], np.cumsum(has))).tolist()
        slow_at = np.flatnonzero(slow)
        self.next_slow = np.append(slow_at, n)[np.searchsorted(slow_at, np.arange(n))].tolist()
        self.lines = lines

    def blocks(self, j0: int, j1: int) -> Iterator[Block]:
        """Blocks of the plain lines among local lines ``j0 .. j1-1`` (C-level iterators)."""
        a = self.bidx[j0]
        b = self.bidx[j1]
        words = map(self._tuples.__getitem__, map(slice, self._starts[a:b], self._ends[a:b]))
        return map(_new, repeat(Block), zip(self._numbers[a:b], words, self._texts[a:b], repeat(None)))


# ------------------------------------------------------------------------- running
def _run(data, source: str, params: ParamStore, block_delete: bool) -> Iterator[Block]:
    src = _Source(data)
    codes: dict[int, LineCode] = {}

    def code_at(i: int) -> LineCode:
        lc = codes.get(i)
        if lc is None:
            lc = lex_line(src.line(i), i + 1, source, block_delete)
            if cache_all or lc.kind != WORDS:
                codes[i] = lc
        return lc

    # Programs with loops or subroutines run lines again: keep every compiled line.
    # Straight-line programs only keep O-word / % lines (bounded memory on huge files).
    cache_all = False
    st = Structure(src, code_at, source, block_delete)
    cache_all = bool(st.loop_end or st.subs)
    ex = Executor(st, params, source, src, code_at)
    end = st.end
    pc = 0
    cur = -1
    base = top = 0
    ch = next_slow = lines = None
    CH = FAST_CHUNK_LINES
    while pc < end:
        k = pc // CH
        if k != cur:
            ch = src.chunk(k)
            next_slow = ch.next_slow
            lines = ch.lines
            cur = k
            base = k * CH
            top = min(base + CH, end) - base
        j = pc - base
        js = next_slow[j]
        if js > j:  # plain lines up to the next slow one: Blocks from the bulk tokeniser
            if js > top:
                js = top
            yield from ch.blocks(j, js)
            pc = base + js
            if js >= top:
                continue
            j = js
        lc = code_at(pc)
        kind = lc.kind
        if kind == WORDS:
            raw = lines[j]
            line = pc + 1

            def where(col: int, raw=raw, line=line) -> SourceLocation:
                return SourceLocation(source, line, col, snippet(raw, col))

            if lc.const:
                words = list(lc.words)
            else:
                words = [(w, v if v.__class__ is float else evaluate(v, params, where), c) for w, v, c in lc.words]
            if lc.assigns:
                todo = [(ex.target(t, c, where), evaluate(v, params, where), c) for t, v, c in lc.assigns]
                for key, value, c in todo:
                    params.set(key, value, where(c))
            if words or lc.comment is not None:
                yield _new(Block, (line, words, raw, lc.comment))
            pc += 1
        elif kind == EMPTY:
            if lc.comment is not None:
                yield _new(Block, (pc + 1, [], lines[j], lc.comment))
            pc += 1
        elif kind == PERCENT:
            if pc != st.opener:
                return
            pc += 1
        else:
            pc = ex.oword(pc, lc)
