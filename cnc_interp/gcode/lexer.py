"""One RS274NGC source line -> :class:`LineCode` (the general, "slow" path).

The line is split into comments (``( ... )`` and ``;`` to the end of the line) and
code; the code has its whitespace removed and is lower-cased (RS274NGC ignores
spaces and case outside comments, so ``G 1 x 1 . 5`` is ``G1 X1.5``). What remains
is, in order:

* an optional ``/`` (block delete),
* an optional ``%`` (program delimiter; the rest of the line is ignored),
* an optional ``N`` line number (dropped),
* either an O-word (``o100 if [...]``, ``o<name> call [a] [b]``) and nothing else,
* or words (a letter and a real value, see :mod:`.expr`) and parameter settings
  ``#n = value`` / ``#<name> = value`` in any order.

Columns in errors and words are 1-based positions in the raw source line.
Plain CAM lines do not come here: :mod:`.fastpath` tokenises them in bulk.
"""

from __future__ import annotations

import re
from bisect import bisect_right
from dataclasses import dataclass, field

from ..constants import EXPR_INTEGER_TOL, MAX_LINE_CHARS, PARAM_LOCAL_COUNT, PARAM_NUMBERED_MAX
from ..errors import GCodeError, SourceLocation, UnsupportedError
from .expr import ExprSyntax, parse_value

# line kinds
EMPTY, WORDS, OWORD, PERCENT = 0, 1, 2, 3

#: letters that start a word (N is the line number, O the O-word, E is not RS274NGC; @ and ^
#: are the polar distance and angle)
WORD_LETTERS = frozenset("abcdfghijklmpqrstuvwxyz@^")

#: O-word keyword -> (least, most) number of [bracketed] arguments
O_KEYWORDS = {
    "sub": (0, 0),
    "endsub": (0, 1),
    "call": (0, PARAM_LOCAL_COUNT),
    "return": (0, 1),
    "if": (1, 1),
    "elseif": (1, 1),
    "else": (0, 0),
    "endif": (0, 0),
    "while": (1, 1),
    "endwhile": (0, 0),
    "do": (0, 0),
    "repeat": (1, 1),
    "endrepeat": (0, 0),
    "break": (0, 0),
    "continue": (0, 0),
}

_COMMENT_CHARS = re.compile(r"[();]")
_CHUNK = re.compile(r"[^ \t\r\f\v]+")
_LINE_NUMBER = re.compile(r"n[0-9]+(?:\.[0-9]*)?")  # LinuxCNC ignores a fraction
_KEYWORD = re.compile(r"[a-z]+")
_OWORD_NUMBER = re.compile(r"[0-9]+")
_SIMPLE_WORD = re.compile(r"[abcdfghijklmpqrstuvwxyz@^]([-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+))")
_INF = float("inf")


@dataclass(slots=True)
class LineCode:
    """A compiled source line. Values are floats or expression code (see expr)."""

    kind: int
    words: list = field(default_factory=list)  # (LETTER, value, col)
    const: bool = True  # every word value is a float
    assigns: list = field(default_factory=list)  # (target int | str | code, value, col)
    comment: str | None = None
    okey: str = ""  # "o100" or "o<name>"
    okw: str = ""  # O-word keyword
    oargs: list = field(default_factory=list)  # argument codes
    ocol: int = 0


def snippet(raw: str, col: int) -> str:
    """A short, printable piece of ``raw`` around column ``col`` for error messages."""
    if len(raw) > 60:
        start = max(col - 11, 0)
        raw = raw[start : start + 50]
    if not raw.isprintable():
        raw = "".join(ch if ch.isprintable() else "?" for ch in raw)
    return raw.strip()


def lex_line(raw: str, lineno: int, source: str, block_delete: bool = True) -> LineCode:
    """Compile one raw source line (no newline). Raises GCodeError / UnsupportedError."""

    def loc(col: int) -> SourceLocation:
        return SourceLocation(source, lineno, col, snippet(raw, col))

    if len(raw) > MAX_LINE_CHARS:
        raise GCodeError(f"line is {len(raw)} characters long (limit {MAX_LINE_CHARS})", loc(1))

    # ---- comments out, code chunks (without whitespace) in, with their columns
    chunks: list[str] = []
    soffs: list[int] = []  # offset of each chunk in the compressed text
    rcols: list[int] = []  # its 1-based column in the raw line
    total = 0
    comment = None
    pos = 0
    n_raw = len(raw)
    while pos <= n_raw:
        m = _COMMENT_CHARS.search(raw, pos)
        end = m.start() if m else n_raw
        for c in _CHUNK.finditer(raw, pos, end):
            chunks.append(c.group())
            soffs.append(total)
            rcols.append(c.start() + 1)
            total += c.end() - c.start()
        if m is None:
            break
        ch = m.group()
        i = m.start()
        if ch == ")":
            raise GCodeError("')' without an opening '('", loc(i + 1))
        if ch == ";":
            comment = raw[i + 1 :]
            break
        j = raw.find(")", i + 1)
        if j < 0:
            raise GCodeError("unterminated comment (missing ')')", loc(i + 1))
        k = raw.find("(", i + 1, j)
        if k >= 0:
            raise GCodeError("nested comment ('(' inside a comment)", loc(k + 1))
        comment = raw[i + 1 : j]
        pos = j + 1
    if not chunks:
        return LineCode(EMPTY, comment=comment)
    s = "".join(chunks).lower()

    def col_of(p: int) -> int:
        i = bisect_right(soffs, p) - 1
        return rcols[i] + (p - soffs[i])

    def syntax(e: ExprSyntax) -> GCodeError:
        cls = UnsupportedError if e.unsupported else GCodeError
        return cls(e.message, loc(col_of(e.pos)))

    n = len(s)
    pos = 0
    if s[0] == "/":
        if block_delete:
            return LineCode(EMPTY)  # deleted, comment included
        pos = 1
    if pos < n and s[pos] == "%":
        return LineCode(PERCENT, comment=comment)
    if pos < n and s[pos] == "n":
        m = _LINE_NUMBER.match(s, pos)
        if m is None:
            raise GCodeError("line number N needs digits", loc(col_of(pos)))
        pos = m.end()
    if pos < n and s[pos] == "o":
        try:
            return _oword(s, pos, comment, col_of, loc)
        except ExprSyntax as e:
            raise syntax(e) from None

    words: list = []
    assigns: list = []
    const = True
    while pos < n:
        c = s[pos]
        m = _SIMPLE_WORD.match(s, pos)
        if m is not None:  # letter + plain number: no need for the expression parser
            value = float(m.group(1))
            if value != _INF and value != -_INF:
                words.append((c.upper(), value, col_of(pos)))
                pos = m.end()
                continue
        if c in WORD_LETTERS:
            start = pos + 1
            try:
                value, pos = parse_value(s, start, col_of)
            except ExprSyntax as e:
                if _no_value(s, start, e):
                    raise GCodeError(f"word {c.upper()} has no value", loc(col_of(start - 1))) from None
                raise syntax(e) from None
            if value.__class__ is not float:
                const = False
            words.append((c.upper(), value, col_of(start - 1)))
        elif c == "#":
            tpos = pos
            try:
                if s.startswith("#<", pos):
                    j = s.find(">", pos + 2)
                    if j < 0:
                        raise GCodeError("parameter name without closing '>'", loc(col_of(pos)))
                    target = s[pos + 2 : j]
                    if not target:
                        raise GCodeError("empty parameter name #<>", loc(col_of(pos)))
                    pos = j + 1
                else:
                    target, pos = parse_value(s, pos + 1, col_of)
                    if target.__class__ is float:
                        target = _param_number(target, loc(col_of(tpos)))
                if pos >= n or s[pos] != "=":
                    raise GCodeError(
                        "expected '=' after a parameter (a parameter value needs a word letter)",
                        loc(col_of(tpos)),
                    )
                value, pos = parse_value(s, pos + 1, col_of)
            except ExprSyntax as e:
                raise syntax(e) from None
            assigns.append((target, value, col_of(tpos)))
        else:
            raise _bad_char(s, pos, c, loc(col_of(pos)))
    return LineCode(WORDS if (words or assigns) else EMPTY, words, const, assigns, comment)


def _no_value(s: str, start: int, e: ExprSyntax) -> bool:
    """True if the syntax error means the word letter has no value at all."""
    if e.pos < start or s[start : e.pos].strip("+-"):
        return False
    return e.message == "expected a value" or e.message.startswith("unknown function")


def _param_number(value: float, loc: SourceLocation) -> int:
    r = round(value)
    if abs(value - r) > EXPR_INTEGER_TOL:
        raise GCodeError(f"parameter number must be an integer, got {value:g}", loc)
    if not 0 < r <= PARAM_NUMBERED_MAX:
        raise GCodeError(f"parameter number #{r} out of range 1..{PARAM_NUMBERED_MAX}", loc)
    return int(r)


def _bad_char(s: str, pos: int, c: str, loc: SourceLocation) -> GCodeError:
    if c == "n":
        return GCodeError("line number N must start the line", loc)
    if c == "o":
        return GCodeError("O-word must start the line", loc)
    if c == "e":
        if pos > 0 and s[pos - 1] in "0123456789.":
            return GCodeError("RS274NGC numbers have no exponent notation ('E' is not a word)", loc)
        return GCodeError("'E' is not an RS274NGC word letter", loc)
    if c in "0123456789.+-":
        return GCodeError("number without a word letter", loc)
    if c == "[":
        return GCodeError("expression without a word letter", loc)
    if c == "]":
        return GCodeError("']' without an opening '['", loc)
    if c == "$":
        return UnsupportedError("'$' words (spindle selection) are not supported", loc)
    if c == "%":
        return GCodeError("'%' must stand alone on its line", loc)
    if c == "=":
        return GCodeError("'=' without a parameter to set", loc)
    if "a" <= c <= "z":
        return GCodeError(f"unknown word letter '{c.upper()}'", loc)
    return GCodeError(f"invalid character {c!r} (binary data?)", loc)


def _oword(s, pos, comment, col_of, loc) -> LineCode:
    ocol = col_of(pos)
    n = len(s)
    p = pos + 1
    if p < n and s[p] == "<":
        j = s.find(">", p + 1)
        if j < 0:
            raise GCodeError("O-word name without closing '>'", loc(ocol))
        name = s[p + 1 : j]
        if not name:
            raise GCodeError("empty O-word name o<>", loc(ocol))
        key = f"o<{name}>"
        p = j + 1
    else:
        m = _OWORD_NUMBER.match(s, p)
        if m is None:
            if p < n and s[p] in "#[":
                raise UnsupportedError("computed O-word numbers (o#n, o[...]) are not supported", loc(ocol))
            raise GCodeError("O-word needs a number or a <name>", loc(ocol))
        key = f"o{int(m.group())}"
        p = m.end()
    m = _KEYWORD.match(s, p)
    if m is None:
        raise UnsupportedError(
            f"O-word {key} without a keyword (a Fanuc-style program number is not RS274NGC)",
            loc(ocol),
        )
    kw = m.group()
    if kw not in O_KEYWORDS:
        raise GCodeError(f"unknown O-word keyword '{kw}'", loc(col_of(p)))
    p = m.end()
    args = []
    while p < n:
        if s[p] != "[":
            raise GCodeError(f"O-word {kw} arguments must be [bracketed]", loc(col_of(p)))
        value, p = parse_value(s, p, col_of)
        args.append(value)
    lo, hi = O_KEYWORDS[kw]
    if not lo <= len(args) <= hi:
        want = f"{lo}" if lo == hi else f"{lo} to {hi}"
        raise GCodeError(f"O-word {kw} takes {want} [argument]s, got {len(args)}", loc(ocol))
    return LineCode(OWORD, comment=comment, okey=key, okw=kw, oargs=args, ocol=ocol)
