"""The block iterator: source text -> :class:`Block` objects, O-word control flow applied.

:func:`iter_blocks` is a generator driven lazily by the modal interpreter, so a
parameter the interpreter writes between two blocks (``G10 L2`` offsets, ``#5420``
positions) is seen by later expressions and O-word conditions.

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
  ``#<_value>`` and ``#<_value_returned>``; ``if/elseif/else/endif``;
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

from ..constants import FAST_CHUNK_LINES, LOOP_ITERATION_LIMIT, MAX_CALL_DEPTH
from ..errors import GCodeError, SourceLocation
from .expr import evaluate, to_int
from .lexer import EMPTY, OWORD, PERCENT, WORDS, LineCode, lex_line, snippet
from .params import ParamStore


class Block(NamedTuple):
    """One executable source line."""

    line: int  #: 1-based source line number
    words: list  #: [(LETTER, value, col)], source order, N dropped, values evaluated
    text: str  #: the raw source line (latin-1 decoded, no newline)
    comment: str | None  #: text of the line's last comment, if any


_new = tuple.__new__


def iter_blocks(
    data: bytes | str, source: str, params: ParamStore, *, block_delete: bool = True
) -> Iterator[Block]:
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

        if isinstance(data, str):
            text = data
            b = data.encode("latin-1", "replace")  # 1 char -> 1 byte keeps offsets
        else:
            b = bytes(data)
            text = b.decode("latin-1")
        if "\r" in text:
            text = text.replace("\r\n", "\n")
            b = b.replace(b"\r\n", b"\n")
            if text.endswith("\r"):  # a last line ended by CR alone
                text = text[:-1]
                b = b[:-1]
        if not text.endswith("\n"):
            text += "\n"
            b += b"\n"
        self.text = text
        self.b = b
        self.line_starts, self.special = scan(b)
        self.n_lines = len(self.special)
        self._chunks: dict[int, tuple] = {}

    def line(self, i: int) -> str:
        """Raw text of 0-based line ``i`` (no newline)."""
        ls = self.line_starts
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

        slow, offs, self._tuples, lines = tokenize_chunk(
            src.b, src.text, src.line_starts, src.special, l0, l1
        )
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


# ------------------------------------------------------------------------ structure
class _Structure:
    """O-word block structure and program extent, checked before running."""

    def __init__(self, src: _Source, code_at, source: str, block_delete: bool):
        self.subs: dict[str, int] = {}  # sub key -> line index of "sub"
        self.sub_end: dict[int, int] = {}  # "sub" line -> "endsub" line
        self.next_branch: dict[int, int] = {}  # if/elseif line -> next elseif/else/endif
        self.endif_of: dict[int, int] = {}  # if/elseif/else line -> endif line
        self.loop_end: dict[int, int] = {}  # while/do/repeat head -> endwhile/while/endrepeat
        self.loop_head: dict[int, int] = {}  # inverse of loop_end
        self.loop_kind: dict[int, str] = {}  # head -> "while" | "do" | "repeat"
        self.target: dict[int, int] = {}  # break/continue line -> loop head
        self.opener = -1  # line index of an opening "%"
        self.end = src.n_lines  # first line index not read

        import numpy as np

        candidates = []
        for i in np.flatnonzero(src.special).tolist():
            head = src.line(i).lstrip(" \t\r\f\v")[:1]
            if head == "/" and not block_delete:
                head = src.line(i).lstrip(" \t\r\f\v")[1:].lstrip(" \t\r\f\v")[:1]
            if head in ("o", "O", "n", "N", "%"):
                candidates.append(i)
        percent = [i for i in candidates if code_at(i).kind == PERCENT]
        if percent:
            p0 = percent[0]
            if all(self._blank(src, code_at, i) for i in range(p0)):
                self.opener = p0
                self.end = percent[1] if len(percent) > 1 else src.n_lines
            else:
                self.end = p0
        olines = [i for i in candidates if i < self.end and code_at(i).kind == OWORD]
        self._build(olines, code_at, source, src)

    @staticmethod
    def _blank(src: _Source, code_at, i: int) -> bool:
        if not src.special[i]:
            return not src.line(i).strip()
        return code_at(i).kind == EMPTY

    def _build(self, olines, code_at, source, src) -> None:
        stack: list[list] = []  # [kind, key, line index, branches / has_else]

        def err(i: int, msg: str) -> GCodeError:
            lc = code_at(i)
            raw = src.line(i)
            return GCodeError(msg, SourceLocation(source, i + 1, lc.ocol, snippet(raw, lc.ocol)))

        def close(i: int, key: str, kinds: tuple[str, ...], kw: str) -> list:
            if not stack or stack[-1][0] not in kinds or stack[-1][1] != key:
                if stack:
                    k, okey, oi = stack[-1][0], stack[-1][1], stack[-1][2]
                    raise err(i, f"{key} {kw} does not close {okey} {k} (line {oi + 1})")
                raise err(i, f"{key} {kw} without an opening {'/'.join(kinds)}")
            return stack.pop()

        for i in olines:
            lc = code_at(i)
            kw, key = lc.okw, lc.okey
            if kw == "sub":
                if stack:
                    raise err(i, f"subroutine {key} defined inside {stack[-1][1]} {stack[-1][0]}")
                if key in self.subs:
                    raise err(i, f"subroutine {key} defined twice (first on line {self.subs[key] + 1})")
                self.subs[key] = i
                stack.append(["sub", key, i, None])
            elif kw == "endsub":
                top = close(i, key, ("sub",), kw)
                self.sub_end[top[2]] = i
            elif kw == "return":
                if not any(e[0] == "sub" and e[1] == key for e in stack):
                    raise err(i, f"{key} return outside subroutine {key}")
            elif kw == "call":
                pass  # resolved when executed (the sub may come later in the file)
            elif kw == "if":
                stack.append(["if", key, i, [i], False])
            elif kw in ("elseif", "else"):
                if not stack or stack[-1][0] != "if" or stack[-1][1] != key:
                    raise err(i, f"{key} {kw} without a matching {key} if")
                if stack[-1][4]:
                    raise err(i, f"{key} {kw} after {key} else")
                stack[-1][3].append(i)
                stack[-1][4] = kw == "else"
            elif kw == "endif":
                top = close(i, key, ("if",), kw)
                chain = top[3] + [i]
                for a, b in zip(chain, chain[1:]):
                    self.next_branch[a] = b
                for a in top[3]:
                    self.endif_of[a] = i
            elif kw == "do":
                stack.append(["do", key, i, None])
            elif kw == "while":
                if stack and stack[-1][0] == "do" and stack[-1][1] == key:
                    head = stack.pop()[2]
                    self._loop(head, i, "do")
                else:
                    stack.append(["while", key, i, None])
            elif kw == "endwhile":
                self._loop(close(i, key, ("while",), kw)[2], i, "while")
            elif kw == "repeat":
                stack.append(["repeat", key, i, None])
            elif kw == "endrepeat":
                self._loop(close(i, key, ("repeat",), kw)[2], i, "repeat")
            else:  # break, continue
                for e in reversed(stack):
                    if e[1] == key and e[0] in ("while", "do", "repeat"):
                        self.target[i] = e[2]
                        break
                else:
                    raise err(i, f"{key} {kw} outside a {key} loop")
        if stack:
            kind, key, i = stack[-1][0], stack[-1][1], stack[-1][2]
            closer = {"sub": "endsub", "if": "endif", "while": "endwhile", "do": "while",
                      "repeat": "endrepeat"}[kind]
            raise err(i, f"{key} {kind} without {key} {closer}")

    def _loop(self, head: int, end: int, kind: str) -> None:
        self.loop_end[head] = end
        self.loop_head[end] = head
        self.loop_kind[head] = kind


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
    st = _Structure(src, code_at, source, block_delete)
    cache_all = bool(st.loop_end or st.subs)
    ex = _Executor(st, params, source, src, code_at)
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
                words = [
                    (w, v if v.__class__ is float else evaluate(v, params, where), c)
                    for w, v, c in lc.words
                ]
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


class _Executor:
    """O-word control flow: call frames, loop counters, branch selection."""

    def __init__(self, st: _Structure, params: ParamStore, source: str, src: _Source, code_at):
        self.st = st
        self.params = params
        self.source = source
        self.src = src
        self.code_at = code_at
        self.frames: list[tuple[int, dict]] = []  # (return line index, caller's loops)
        self.loops: dict[int, int] = {}  # loop head -> iterations so far / repeats left

    def where_at(self, i: int):
        """Error-location builder for line index ``i`` (reads the line only on error)."""

        def where(col: int) -> SourceLocation:
            return SourceLocation(self.source, i + 1, col, snippet(self.src.line(i), col))

        return where

    def target(self, t, col: int, where) -> int | str:
        """Key of an assignment target (int, name, or an indirect ``#[expr]``)."""
        if t.__class__ is int or t.__class__ is str:
            return t
        return to_int(evaluate(t, self.params, where), "parameter number", col, where)

    def _cond(self, i: int, lc: LineCode) -> bool:
        return evaluate(lc.oargs[0], self.params, self.where_at(i)) != 0.0

    def _count(self, head: int, i: int, lc: LineCode) -> None:
        n = self.loops.get(head, 0) + 1
        if n > LOOP_ITERATION_LIMIT:
            where = self.where_at(i)
            raise GCodeError(
                f"{lc.okey} loop ran more than {LOOP_ITERATION_LIMIT} iterations "
                "(LOOP_ITERATION_LIMIT; endless loop?)",
                where(lc.ocol),
            )
        self.loops[head] = n

    def oword(self, i: int, lc: LineCode) -> int:
        """Execute the O-word line ``i``; return the next line index."""
        st = self.st
        kw = lc.okw
        if kw == "sub":
            return st.sub_end[i] + 1
        if kw == "call":
            where = self.where_at(i)
            head = st.subs.get(lc.okey)
            if head is None:
                raise GCodeError(
                    f"subroutine {lc.okey} not defined in this file "
                    "(subroutine files on a search path are not supported)",
                    where(lc.ocol),
                )
            args = [evaluate(a, self.params, where) for a in lc.oargs]
            if len(self.frames) >= MAX_CALL_DEPTH:
                raise GCodeError(
                    f"O-word calls nested deeper than {MAX_CALL_DEPTH} (MAX_CALL_DEPTH; endless recursion?)",
                    where(lc.ocol),
                )
            self.params.push_frame(args)
            self.frames.append((i + 1, self.loops))
            self.loops = {}
            return head + 1
        if kw == "endsub" or kw == "return":
            if not self.frames:
                raise GCodeError(f"{lc.okey} {kw} reached outside a call", self.where_at(i)(lc.ocol))
            p = self.params
            if lc.oargs:
                value = evaluate(lc.oargs[0], p, self.where_at(i))
                p.pop_frame()
                p.set("_value", value)
                p.set("_value_returned", 1.0)
            else:
                p.pop_frame()
                p.set("_value_returned", 0.0)
            ret, self.loops = self.frames.pop()
            return ret
        if kw == "if":
            if self._cond(i, lc):
                return i + 1
            b = st.next_branch[i]
            while True:
                blc = self.code_at(b)
                if blc.okw != "elseif" or self._cond(b, blc):
                    return b + 1
                b = st.next_branch[b]
        if kw == "elseif" or kw == "else":
            return st.endif_of[i] + 1  # end of the branch that ran
        if kw == "endif":
            return i + 1
        if kw == "while":
            head = st.loop_head.get(i)
            if head is not None:  # the "while" that ends a do loop
                if self._cond(i, lc):
                    self._count(head, i, lc)
                    return head + 1
                self.loops.pop(head, None)
                return i + 1
            if self._cond(i, lc):
                self._count(i, i, lc)
                return i + 1
            self.loops.pop(i, None)
            return st.loop_end[i] + 1
        if kw == "endwhile":
            return st.loop_head[i]
        if kw == "do":
            return i + 1
        if kw == "repeat":
            where = self.where_at(i)
            n = to_int(evaluate(lc.oargs[0], self.params, where), "repeat count", lc.ocol, where)
            if n > LOOP_ITERATION_LIMIT:
                raise GCodeError(
                    f"{lc.okey} repeat count {n} exceeds LOOP_ITERATION_LIMIT ({LOOP_ITERATION_LIMIT})",
                    where(lc.ocol),
                )
            if n <= 0:
                return st.loop_end[i] + 1
            self.loops[i] = n - 1
            return i + 1
        if kw == "endrepeat":
            head = st.loop_head[i]
            left = self.loops.get(head, 0)
            if left > 0:
                self.loops[head] = left - 1
                return head + 1
            self.loops.pop(head, None)
            return i + 1
        head = st.target[i]
        if kw == "break":
            self.loops.pop(head, None)
            return st.loop_end[head] + 1
        # continue: to the loop's test
        return head if st.loop_kind[head] == "while" else st.loop_end[head]
