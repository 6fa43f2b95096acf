"""RS274NGC real values and ``[expressions]``, LinuxCNC dialect.

A *real value* is a number, ``#n`` / ``#<name>`` / ``##n`` / ``#[expr]``, a
bracketed expression ``[ ... ]``, a unary function ``NAME[expr]`` (``ATAN[y]/[x]``,
``EXISTS[#<name>]``), each optionally preceded by ``-``/``+``. Binary operators
exist only inside brackets. Precedence (LinuxCNC ``Interp::precedence``), highest
first, each level left-associative:

    **            (power)
    *  /  MOD
    +  -
    EQ NE GT GE LT LE
    AND OR XOR

A leading ``-`` binds to the single value after it (LinuxCNC reads it as part of
the number), so ``[-2 ** 2]`` is 4. Angles of SIN/COS/TAN/ASIN/ACOS/ATAN are in
degrees. EQ/NE compare within ``EXPR_EQUAL_TOL``; comparisons and logic give 1.0 or
0.0; MOD's result has the sign of a positive divisor (LinuxCNC adds |b| to a negative
fmod); ROUND rounds half away from zero, FIX = floor, FUP = ceil. There is no
exponent notation (``1e5`` is an error).

Parsing is an iterative shunting-yard into reverse Polish code and evaluation is a
loop over that code, so nesting depth is bounded only by the line length and can
never raise ``RecursionError``. Expressions without parameter reads are folded to
a float when parsed.

The parser works on the lexer's *compressed* text: lower case, whitespace and
comments removed. Positions in :class:`ExprSyntax` are indices into that text;
``col_of`` maps them to 1-based source columns for the code's error locations.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable

from ..constants import EXPR_INTEGER_TOL
from ..errors import GCodeError, SourceLocation


#: EQ / NE compare within this tolerance (LinuxCNC TOLERANCE_EQUAL)
EXPR_EQUAL_TOL = 0.0001

# opcodes of the reverse Polish code: tuples (opcode, argument, source column)
CONST, NUMREAD, NAMEREAD, EXISTS, NEG, FUNC, BIN, ATAN, NUMREAD_K = range(9)
# operator-stack-only markers
_LBR, _ATAN1, _ATAN2 = 100, 101, 102
_PREFIX = frozenset((NEG, NUMREAD, FUNC, _ATAN2))

Code = tuple  # tuple of (opcode, arg, col); a folded constant is a plain float
Where = Callable[[int], SourceLocation]

PRECEDENCE = {
    "**": 6,
    "*": 5,
    "/": 5,
    "mod": 5,
    "+": 4,
    "-": 4,
    "eq": 3,
    "ne": 3,
    "gt": 3,
    "ge": 3,
    "lt": 3,
    "le": 3,
    "and": 2,
    "or": 2,
    "xor": 2,
}
FUNCTIONS = frozenset(("abs", "acos", "asin", "atan", "cos", "exp", "fix", "fup", "ln", "round", "sin", "sqrt", "tan"))

_NUM = re.compile(r"[0-9]+\.?[0-9]*|\.[0-9]+")
_IDENT = re.compile(r"[a-z_]+")
_BINOP = re.compile(r"\*\*|[-+*/]|mod|eq|ne|gt|ge|lt|le|and|xor|or")
_EXISTS = re.compile(r"exists\[#<([^>\[\]]*)>\]")
_DIGITS_DOT = frozenset("0123456789.")


class ExprSyntax(Exception):
    """Syntax error at ``pos`` of the compressed text (converted by the lexer)."""

    def __init__(self, pos: int, message: str, unsupported: bool = False):
        super().__init__(message)
        self.pos = pos
        self.message = message
        self.unsupported = unsupported


def parse_value(s: str, pos: int, col_of: Callable[[int], int]) -> tuple[float | Code, int]:
    """Parse one real value of ``s`` starting at ``pos``.

    Returns ``(code, end)``: ``code`` is a float when the value is constant, else a
    tuple of reverse Polish instructions for :func:`evaluate`; ``end`` is the index
    just after the value. Raises :class:`ExprSyntax`.
    """
    out: list[tuple] = []
    ops: list[tuple] = []
    depth = 0
    n = len(s)
    reads = False
    while True:
        # ---- an operand is expected
        if pos >= n:
            if depth:
                raise ExprSyntax(_open_bracket(ops), "unclosed '[' (missing ']')")
            raise ExprSyntax(pos, "expected a value")
        c = s[pos]
        if c == "[":
            ops.append((_LBR, None, pos))
            depth += 1
            pos += 1
            continue
        if c == "-":
            ops.append((NEG, None, col_of(pos)))
            pos += 1
            continue
        if c == "+":
            pos += 1
            continue
        if c == "#":
            reads = True
            if pos + 1 < n and s[pos + 1] == "<":
                j = s.find(">", pos + 2)
                if j < 0:
                    raise ExprSyntax(pos, "parameter name without closing '>'")
                name = s[pos + 2 : j]
                if not name:
                    raise ExprSyntax(pos, "empty parameter name #<>")
                if name.startswith(("_ini[", "_hal[")):
                    raise ExprSyntax(pos, f"#<{name}> (INI/HAL parameters) is not supported", True)
                out.append((NAMEREAD, name, col_of(pos)))
                pos = j + 1
            else:
                ops.append((NUMREAD, None, col_of(pos)))
                pos += 1
                continue
        elif c in _DIGITS_DOT:
            m = _NUM.match(s, pos)
            if m is None:
                raise ExprSyntax(pos, "bad number")
            v = float(m.group())
            if v == math.inf:
                raise ExprSyntax(pos, "number too large for a float")
            out.append((CONST, v, col_of(pos)))
            pos = m.end()
        elif "a" <= c <= "z":
            m = _IDENT.match(s, pos)
            name = m.group()  # type: ignore[union-attr]
            if name.startswith("exists"):
                e = _EXISTS.match(s, pos)
                if e is None:
                    raise ExprSyntax(pos, "EXISTS takes one named parameter: EXISTS[#<name>]")
                out.append((EXISTS, e.group(1), col_of(pos)))
                reads = True
                pos = e.end()
            elif name in FUNCTIONS:
                end = m.end()  # type: ignore[union-attr]
                if end >= n or s[end] != "[":
                    raise ExprSyntax(end, f"function {name.upper()} needs a [bracketed] argument")
                ops.append((_ATAN1 if name == "atan" else FUNC, name, col_of(pos)))
                ops.append((_LBR, None, end))
                depth += 1
                pos = end + 1
                continue
            else:
                raise ExprSyntax(pos, f"unknown function or operator '{name.upper()}'")
        else:
            if c == "]":
                raise ExprSyntax(pos, "expected a value before ']'")
            raise ExprSyntax(pos, "expected a value")
        # ---- an operand is complete
        while True:
            while ops and ops[-1][0] in _PREFIX:
                out.append(_emit(ops.pop(), out))
            if depth == 0:
                return _finish(out, reads), pos
            if pos < n and s[pos] == "]":
                while ops[-1][0] != _LBR:
                    out.append(ops.pop())
                ops.pop()
                depth -= 1
                pos += 1
                if ops and ops[-1][0] == _ATAN1:
                    if not s.startswith("/[", pos):
                        raise ExprSyntax(pos, "ATAN needs two arguments: ATAN[y]/[x]")
                    ops[-1] = (_ATAN2, None, ops[-1][2])
                    ops.append((_LBR, None, pos + 1))
                    depth += 1
                    pos += 2
                    break
                continue
            m = _BINOP.match(s, pos)
            if m is None:
                if pos >= n:
                    raise ExprSyntax(_open_bracket(ops), "unclosed '[' (missing ']')")
                if s[pos] == "e" and pos > 0 and s[pos - 1] in _DIGITS_DOT:
                    raise ExprSyntax(pos, "RS274NGC numbers have no exponent notation")
                raise ExprSyntax(pos, "expected an operator or ']'")
            op = m.group()
            prec = PRECEDENCE[op]
            while ops[-1][0] == BIN and PRECEDENCE[ops[-1][1]] >= prec:
                out.append(ops.pop())
            ops.append((BIN, op, col_of(pos)))
            pos = m.end()
            break


def _open_bracket(ops: list[tuple]) -> int:
    for kind, _arg, p in reversed(ops):
        if kind == _LBR:
            return p
    return 0


def _emit(op: tuple, out: list) -> tuple:
    kind = op[0]
    if kind == _ATAN2:
        return (ATAN, None, op[2])
    if kind == NUMREAD and out and out[-1][0] == CONST:
        # "#5": the parameter number is a constant; check it once, read directly
        v = out[-1][1]
        r = round(v)
        if abs(v - r) <= EXPR_INTEGER_TOL:
            out.pop()
            return (NUMREAD_K, int(r), op[2])
    return op


def _no_where(col: int) -> SourceLocation:
    return SourceLocation(col=col)


def _finish(out: list[tuple], reads: bool) -> float | Code:
    if len(out) == 1 and out[0][0] == CONST:
        return out[0][1]
    code = tuple(out)
    if not reads:
        try:
            return evaluate(code, None, _no_where)  # type: ignore[arg-type]
        except GCodeError:
            pass  # keep the code: the error is reported, with its line, when evaluated
    return code


def evaluate(code: float | Code, params, where: Where) -> float:
    """Value of ``code`` with the parameters of ``params`` (a ParamStore).

    ``where(col)`` builds the SourceLocation of an error at source column ``col``.
    """
    if code.__class__ is float:
        return code  # type: ignore[return-value]
    st: list[float] = []
    push = st.append
    pop = st.pop
    for op, arg, col in code:  # type: ignore[union-attr]
        if op == CONST:
            push(arg)
        elif op == BIN:
            b = pop()
            push(_binary(arg, pop(), b, col, where))
        elif op == NEG:
            push(-pop())
        elif op == NUMREAD_K:
            try:
                push(params.get(arg))
            except GCodeError as e:
                raise GCodeError(e.message, where(col)) from None
        elif op == NAMEREAD:
            try:
                push(params.get(arg))
            except GCodeError as e:
                raise GCodeError(e.message, where(col)) from None
        elif op == NUMREAD:
            key = to_int(pop(), "parameter number", col, where)
            try:
                push(params.get(key))
            except GCodeError as e:
                raise GCodeError(e.message, where(col)) from None
        elif op == FUNC:
            push(_function(arg, pop(), col, where))
        elif op == ATAN:
            x = pop()
            y = pop()
            push(math.degrees(math.atan2(y, x)))
        else:  # EXISTS
            push(1.0 if params.exists(arg) else 0.0)
    return st[-1]


def to_int(value: float, what: str, col: int, where: Where) -> int:
    """``value`` as an int; an error if it is not within EXPR_INTEGER_TOL of one."""
    r = round(value)
    if abs(value - r) > EXPR_INTEGER_TOL:
        raise GCodeError(f"{what} must be an integer, got {value:g}", where(col))
    return int(r)


def _binary(op: str, a: float, b: float, col: int, where: Where) -> float:
    try:
        if op == "+":
            r = a + b
        elif op == "-":
            r = a - b
        elif op == "*":
            r = a * b
        elif op == "/":
            if b == 0.0:
                raise GCodeError("division by zero", where(col))
            r = a / b
        elif op == "**":
            if a < 0.0 and b != math.floor(b):
                raise GCodeError(f"negative number {a:g} raised to non-integer power {b:g}", where(col))
            if a == 0.0 and b < 0.0:
                raise GCodeError("division by zero (zero raised to a negative power)", where(col))
            r = math.pow(a, b)
        elif op == "mod":
            if b == 0.0:
                raise GCodeError("MOD by zero", where(col))
            r = math.fmod(a, b)
            if r < 0.0:
                r += abs(b)
        elif op == "eq":
            return 1.0 if abs(a - b) < EXPR_EQUAL_TOL else 0.0
        elif op == "ne":
            return 1.0 if abs(a - b) >= EXPR_EQUAL_TOL else 0.0
        elif op == "gt":
            return 1.0 if a > b else 0.0
        elif op == "ge":
            return 1.0 if a >= b else 0.0
        elif op == "lt":
            return 1.0 if a < b else 0.0
        elif op == "le":
            return 1.0 if a <= b else 0.0
        elif op == "and":
            return 0.0 if (a == 0.0 or b == 0.0) else 1.0
        elif op == "or":
            return 1.0 if (a != 0.0 or b != 0.0) else 0.0
        else:  # xor
            return 1.0 if ((a != 0.0) != (b != 0.0)) else 0.0
    except OverflowError:
        raise GCodeError(f"numeric overflow in {op.upper()}", where(col)) from None
    if not math.isfinite(r):
        raise GCodeError(f"numeric overflow in {op.upper()}", where(col))
    return r


def _function(name: str, x: float, col: int, where: Where) -> float:
    if name == "abs":
        return abs(x)
    if name == "sin":
        return math.sin(math.radians(x))
    if name == "cos":
        return math.cos(math.radians(x))
    if name == "tan":
        r = math.tan(math.radians(x))
    elif name == "asin" or name == "acos":
        if not -1.0 <= x <= 1.0:
            raise GCodeError(f"{name.upper()} argument {x:g} outside [-1, 1]", where(col))
        r = math.degrees(math.asin(x) if name == "asin" else math.acos(x))
    elif name == "sqrt":
        if x < 0.0:
            raise GCodeError(f"SQRT of negative number {x:g}", where(col))
        r = math.sqrt(x)
    elif name == "ln":
        if x <= 0.0:
            raise GCodeError(f"LN of non-positive number {x:g}", where(col))
        r = math.log(x)
    elif name == "exp":
        try:
            r = math.exp(x)
        except OverflowError:
            raise GCodeError(f"EXP[{x:g}] overflows", where(col)) from None
    elif name == "fix":
        r = float(math.floor(x))
    elif name == "fup":
        r = float(math.ceil(x))
    else:  # round: half away from zero, as LinuxCNC
        r = float(math.floor(x + 0.5)) if x >= 0.0 else -float(math.floor(-x + 0.5))
    if not math.isfinite(r):
        raise GCodeError(f"{name.upper()}[{x:g}] is not a finite number", where(col))
    return r
