"""Parameters and [expressions]: LinuxCNC operators, precedence, functions, errors."""

from __future__ import annotations

import math

import pytest
from numpy.testing import assert_allclose

from cnc_interp.errors import GCodeError
from cnc_interp.gcode.blocks import iter_blocks
from cnc_interp.gcode.params import ParamStore


def run(src: str, params: ParamStore | None = None):
    return list(iter_blocks(src, "e.ngc", params if params is not None else ParamStore()))


def ev(expr: str, params: ParamStore | None = None) -> float:
    (b,) = run(f"G1 X{expr}\n", params)
    assert b.words[1][0] == "X"
    return b.words[1][1]


def err(src: str, params: ParamStore | None = None) -> GCodeError:
    with pytest.raises(GCodeError) as ei:
        run(src, params)
    return ei.value


@pytest.mark.parametrize(
    "expr, value",
    [
        ("[1+2*3]", 7.0),
        ("[[1+2]*3]", 9.0),
        ("[2**3**2]", 64.0),  # left-associative, as LinuxCNC
        ("[2*3**2]", 18.0),  # ** binds tighter than *
        ("[-2**2]", 4.0),  # the sign belongs to the number
        ("[10-4-3]", 3.0),
        ("[12/3/2]", 2.0),
        ("[7 MOD 3]", 1.0),
        ("[-7 MOD 3]", 2.0),  # LinuxCNC: fmod result shifted by |b| when negative
        ("[7.5 mod 2]", 1.5),
        ("[1+2 EQ 3]", 1.0),  # + before comparison
        ("[1 EQ 1.00005]", 1.0),  # EQ within 0.0001
        ("[1 NE 1.00005]", 0.0),
        ("[1 NE 1.001]", 1.0),
        ("[2 GT 1]", 1.0),
        ("[2 GE 2]", 1.0),
        ("[2 LT 1]", 0.0),
        ("[2 LE 2]", 1.0),
        ("[1 LT 2 AND 3 LT 2]", 0.0),  # comparisons before AND
        ("[0 OR 2]", 1.0),
        ("[1 XOR 1]", 0.0),
        ("[1 XOR 0]", 1.0),
        ("[1 AND 2 OR 0]", 1.0),
        ("[3 + 0 AND 0]", 0.0),  # AND lowest: (3+0) AND 0
        ("-[1+1]", -2.0),
        ("+[1+1]", 2.0),
        ("[--1]", 1.0),
        ("[1--1]", 2.0),
        ("[SIN[30]]", 0.5),
        ("COS[60]", 0.5),
        ("[TAN[45]]", 1.0),
        ("[ASIN[0.5]]", 30.0),
        ("[ACOS[0.5]]", 60.0),
        ("[ATAN[1]/[1]]", 45.0),
        ("ATAN[1]/[-1]", 135.0),
        ("[ATAN[-1]/[-1]]", -135.0),
        ("[SQRT[16]]", 4.0),
        ("[ABS[-3.5]]", 3.5),
        ("[EXP[1]]", math.e),
        ("[LN[EXP[2]]]", 2.0),
        ("[ROUND[2.5]]", 3.0),
        ("[ROUND[-2.5]]", -3.0),  # half away from zero
        ("[ROUND[2.4999]]", 2.0),
        ("[FIX[-2.5]]", -3.0),
        ("[FUP[-2.5]]", -2.0),
        ("[FIX[2.5]]", 2.0),
        ("[FUP[2.1]]", 3.0),
        ("[sin[30]+cos[60]*2]", 1.5),
        ("[ 1 + 2 ]", 3.0),
        ("[2 ** 0.5]", math.sqrt(2.0)),
        ("[-2 ** 3]", -8.0),
    ],
)
def test_operators_and_functions(expr, value):
    assert_allclose(ev(expr), value, rtol=0, atol=1e-12)


def test_deep_nesting_does_not_recurse():
    depth = 50_000
    assert ev("[" * depth + "1+1" + "]" * depth) == 2.0
    assert ev("-[" * 1000 + "2" + "]" * 1000) == 2.0
    assert ev("ABS[" * 3000 + "-3" + "]" * 3000) == 3.0
    e = err("G1 X" + "[" * 20_000 + "1\n")
    assert "unclosed" in e.message and e.location.col == 5 + 20_000 - 1


def test_numbered_and_named_parameters():
    p = ParamStore()
    bs = run(
        "#1 = 2.5\n"
        "#<len> = [#1 * 2]\n"
        "#<_glob> = 7 #2 = 3\n"
        "#[#2 + 1] = 40\n"  # indirect: #4
        "##2 = 30\n"  # indirect: #3
        "G1 X#1 Y#<len> Z#<_GLOB> A#4 B#3 C##2 U#[1+1]\n"
        "G1 X#99\n",  # never set: 0.0
        p,
    )
    line = "G1 X#1 Y#<len> Z#<_GLOB> A#4 B#3 C##2 U#[1+1]"
    vals = [2.5, 5.0, 7.0, 40.0, 30.0, 30.0, 3.0]
    assert bs[0].words[1:] == [(w, v, line.index(" " + w) + 2) for w, v in zip("XYZABCU", vals)]
    assert bs[1].words[1] == ("X", 0.0, 4)
    assert p.get(1) == 2.5 and p.get("len") == 5.0 and p.get("_glob") == 7.0
    assert p.exists("len") and not p.exists("nope")


def test_names_ignore_case_and_spaces():
    (b,) = run("#<My Var> = 4\nG1 X#<myvar>\n")
    assert b.words[1][1] == 4.0


def test_line_reads_before_its_assignments():
    # all reads of a line use the values from before the line; settings apply in order
    bs = run("#1 = 1\n#1 = 2 #2 = #1 G1 X#1\nG1 X#2 Y#1\n")
    assert bs[0].words[1][1] == 1.0
    assert bs[1].words[1:] == [("X", 1.0, 4), ("Y", 2.0, 8)]
    bs = run("#1 = 5 #1 = 6\nG1 X#1\n")
    assert bs[0].words[1][1] == 6.0  # settings in source order


def test_exists():
    assert ev("[EXISTS[#<nope>]]") == 0.0
    (b,) = run("#<yes> = 1\nG1 X[EXISTS[#<yes>]] Y[EXISTS[#<_nope>]]\n")
    assert b.words[1][1] == 1.0 and b.words[2][1] == 0.0


def test_interpreter_writes_between_blocks_are_seen():
    p = ParamStore()
    it = iter_blocks("G1 X1\nG1 X#5420\no1 if [#5420 GT 5]\nG1 Y1\no1 endif\n", "e.ngc", p)
    next(it)
    p.set(5420, 10.0)  # the interpreter records the current position
    b2 = next(it)
    assert b2.words[1][1] == 10.0
    b3 = next(it)
    assert b3.words == [("G", 1.0, 1), ("Y", 1.0, 4)]


@pytest.mark.parametrize(
    "src, line, col, needle",
    [
        ("G1 X[1/0]\n", 1, 7, "division by zero"),
        ("G1 X[1/[2-2]]\n", 1, 7, "division by zero"),
        ("#1=0\nG1 X[1/#1]\n", 2, 7, "division by zero"),
        ("G1 X[1 MOD 0]\n", 1, 8, "MOD by zero"),
        ("G1 X[SQRT[-1]]\n", 1, 6, "SQRT"),
        ("G1 X[LN[0]]\n", 1, 6, "LN"),
        ("G1 X[ASIN[2]]\n", 1, 6, "ASIN"),
        ("G1 X[ACOS[-1.5]]\n", 1, 6, "ACOS"),
        ("G1 X[EXP[1000]]\n", 1, 6, "EXP"),
        ("G1 X[10**400]\n", 1, 8, "overflow"),
        ("G1 X[-2**0.5]\n", 1, 8, "non-integer power"),
        ("G1 X[0**-1]\n", 1, 7, "division by zero"),
        (
            "G1 X[99999999999*99999999999*99999999999*99999999999*99999999999*99999999999"
            "*99999999999*99999999999*99999999999*99999999999*99999999999*99999999999"
            "*99999999999*99999999999*99999999999*99999999999*99999999999*99999999999"
            "*99999999999*99999999999*99999999999*99999999999*99999999999*99999999999"
            "*99999999999*99999999999*99999999999*99999999999*99999999999*99999999999]\n",
            1,
            None,
            "overflow",
        ),
        ("G0\nG1 X#<undefined>\n", 2, 5, "undefined parameter #<undefined>"),
        ("G1 X#<_undefglobal>\n", 1, 5, "#<_undefglobal>"),
        ("G1 X#0\n", 1, 5, "out of range"),
        ("G1 X#6000\n", 1, 5, "out of range"),
        ("#6000 = 1\n", 1, 1, "out of range"),
        ("G1 X#1.5\n", 1, 5, "integer"),
        ("G1 X[FOO[1]]\n", 1, 6, "unknown function or operator 'FOO'"),
        ("G1 X[1 + ]\n", 1, 10, "expected a value"),
        ("G1 X[1 [2]]\n", 1, 8, "expected an operator"),
        ("G1 X[1 ** ** 2]\n", 1, 11, "expected a value"),
        ("G1 X[ATAN[1]]\n", 1, 13, "ATAN"),
        ("G1 X[SIN 30]\n", 1, 10, "SIN"),
        ("G1 X[EXISTS[#1]]\n", 1, 6, "EXISTS"),
        ("G1 X#<abc\n", 1, 5, "'>'"),
        ("G1 X#<>\n", 1, 5, "empty"),
        ("G1 X[1e3]\n", 1, 7, "exponent"),
    ],
)
def test_expression_errors(src, line, col, needle):
    e = err(src)
    assert e.location.line == line, e.format()
    if col is not None:
        assert e.location.col == col, e.format()
    assert needle in e.message, e.format()
    assert e.location.text


def test_param_store_frames():
    p = ParamStore()
    p.set(1, 1.0)
    p.set(31, 31.0)
    p.set("loc", 2.0)
    p.set("_g", 3.0)
    p.push_frame([10.0, 20.0])
    assert p.get(1) == 10.0 and p.get(2) == 20.0 and p.get(3) == 0.0 and p.get(31) == 31.0
    assert not p.exists("loc") and p.get("_g") == 3.0
    p.set("loc", 9.0)
    p.set(31, 32.0)  # #31 and up are global
    p.pop_frame()
    assert p.get(1) == 1.0 and p.get("loc") == 2.0 and p.get(31) == 32.0
    with pytest.raises(GCodeError, match="#<zz>"):
        p.get("zz")


def test_ini_and_hal_parameters_unsupported():
    from cnc_interp.errors import UnsupportedError

    with pytest.raises(UnsupportedError, match="INI/HAL"):
        run("G1 X#<_ini[axis_x]max_velocity>\n")
