"""O-word control flow (LinuxCNC): block structure check and execution.

:class:`Structure` pairs every ``sub/endsub``, ``if/elseif/else/endif``,
``while/endwhile``, ``do/while``, ``repeat/endrepeat`` of the program (by O-word
key and nesting, so control-flow numbers may be reused, e.g. in different subs)
and finds the program's ``%`` extent, before anything runs. :class:`Executor`
runs the O-word lines for :func:`.blocks.iter_blocks`: call frames (``#1..#30``
and local names via the ParamStore), return values, branch choice, loop counters
bounded by ``LOOP_ITERATION_LIMIT`` and call depth bounded by ``MAX_CALL_DEPTH``.
Line indices are 0-based; ``src`` is the block layer's source (``line(i)``,
``special``, ``n_lines``) and ``code_at(i)`` its compiled :class:`.lexer.LineCode`.
"""

from __future__ import annotations

from ..constants import LOOP_ITERATION_LIMIT, MAX_CALL_DEPTH
from ..errors import GCodeError, SourceLocation
from .expr import evaluate, to_int
from .lexer import EMPTY, OWORD, PERCENT, LineCode, snippet
from .params import ParamStore


#: upper bound on loop iterations of a whole program, all loops and nestings together (as
#: many as a ten-million-line program has blocks)
LOOP_TOTAL_ITERATION_LIMIT = 10_000_000


class Structure:
    """O-word block structure and program extent, checked before running."""

    def __init__(self, src, code_at, source: str, block_delete: bool):
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
    def _blank(src, code_at, i: int) -> bool:
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
            closer = {"sub": "endsub", "if": "endif", "while": "endwhile", "do": "while", "repeat": "endrepeat"}[kind]
            raise err(i, f"{key} {kind} without {key} {closer}")

    def _loop(self, head: int, end: int, kind: str) -> None:
        self.loop_end[head] = end
        self.loop_head[end] = head
        self.loop_kind[head] = kind


class Executor:
    """O-word control flow: call frames, loop counters, branch selection."""

    def __init__(self, st: Structure, params: ParamStore, source: str, src, code_at):
        self.st = st
        self.params = params
        self.source = source
        self.src = src
        self.code_at = code_at
        self.frames: list[tuple[int, dict]] = []  # (return line index, caller's loops)
        self.loops: dict[int, int] = {}  # loop head -> iterations so far / repeats left
        self.iterations = 0  # loop iterations of the whole program, every loop and nesting

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

    def _total(self, i: int, lc: LineCode) -> None:
        """Count one more loop iteration of the whole program: nested loops are each
        within ``LOOP_ITERATION_LIMIT`` but their product must be bounded too."""
        self.iterations += 1
        if self.iterations > LOOP_TOTAL_ITERATION_LIMIT:
            raise GCodeError(
                f"the program's loops ran more than {LOOP_TOTAL_ITERATION_LIMIT} iterations in "
                "all (LOOP_TOTAL_ITERATION_LIMIT; nested loops multiply)",
                self.where_at(i)(lc.ocol),
            )

    def _count(self, head: int, i: int, lc: LineCode) -> None:
        self._total(i, lc)
        n = self.loops.get(head, 0) + 1
        if n > LOOP_ITERATION_LIMIT:
            where = self.where_at(i)
            raise GCodeError(
                f"{lc.okey} loop ran more than {LOOP_ITERATION_LIMIT} iterations (LOOP_ITERATION_LIMIT; endless loop?)",
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
            self.params.set("_value_returned", 0.0)  # cleared by every call (LinuxCNC)
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
            else:  # no expression: the value is 0 (LinuxCNC)
                p.pop_frame()
                p.set("_value", 0.0)
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
                self._total(i, lc)
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
