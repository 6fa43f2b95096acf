"""Tokenizer: words, comments, N, case, spacing, CRLF, %, block delete, errors, fast path."""

from __future__ import annotations

import random
import time

import numpy as np
import pytest

from cnc_interp.errors import GCodeError, UnsupportedError
from cnc_interp.gcode.blocks import Block, iter_blocks
from cnc_interp.gcode.fastpath import scan, tokenize_chunk
from cnc_interp.gcode.lexer import lex_line
from cnc_interp.gcode.params import ParamStore


def blocks(src, **kw) -> list[Block]:
    return list(iter_blocks(src, "t.ngc", ParamStore(), **kw))


def words(src, **kw) -> list[list[tuple[str, float, int]]]:
    return [b.words for b in blocks(src, **kw)]


def err(src, cls=GCodeError, **kw) -> GCodeError:
    with pytest.raises(cls) as ei:
        blocks(src, **kw)
    return ei.value


def test_plain_cam_line():
    (b,) = blocks("N123 G1 X1.234 Y-5.6 F1200\n")
    assert b.line == 1
    assert b.text == "N123 G1 X1.234 Y-5.6 F1200"
    assert b.comment is None
    assert b.words == [("G", 1.0, 6), ("X", 1.234, 9), ("Y", -5.6, 16), ("F", 1200.0, 22)]


def test_g_and_m_values_are_floats():
    assert words("G5.2 M61.1 G90.1\n") == [[("G", 5.2, 1), ("M", 61.1, 6), ("G", 90.1, 12)]]


def test_lower_case_missing_spaces_signs():
    assert words("g1x+1.5y-.5z2.\n") == [[("G", 1.0, 1), ("X", 1.5, 3), ("Y", -0.5, 8), ("Z", 2.0, 12)]]


def test_spaces_inside_words_are_ignored():
    # RS274NGC ignores blanks outside comments: "X 1 . 5" is X1.5
    assert words("G 1 X 1 . 5 Y- 2\n") == [[("G", 1.0, 1), ("X", 1.5, 5), ("Y", -2.0, 13)]]


def test_tabs_and_leading_blanks():
    assert words("\t  G0\tX1\n") == [[("G", 0.0, 4), ("X", 1.0, 7)]]


def test_n_numbers_dropped_and_must_come_first():
    assert words("N10G1X2\n n20 g0\n") == [[("G", 1.0, 4), ("X", 2.0, 6)], [("G", 0.0, 6)]]
    e = err("G1 N10 X1\n")
    assert (e.location.line, e.location.col) == (1, 4)
    assert "N" in e.message


def test_comments_paren_and_semicolon():
    bs = blocks("G1 (move; not a semicolon comment) X1 ; tail (x)\n(MSG, hello)\n")
    assert bs[0].words == [("G", 1.0, 1), ("X", 1.0, 36)]
    assert bs[0].comment == " tail (x)"
    assert bs[1].words == [] and bs[1].comment == "MSG, hello"


def test_empty_and_blank_lines_yield_nothing():
    bs = blocks("\n   \nG0 X1\n\n#1=2\n")
    assert [b.line for b in bs] == [3]


def test_crlf_and_latin1_comment():
    data = b"G1 X1 (caf\xe9 \xb5m)\r\nG1 X2\r\n"
    bs = blocks(data)
    assert [b.line for b in bs] == [1, 2]
    assert bs[0].comment == "café µm"
    assert bs[0].text == "G1 X1 (café µm)"
    assert bs[1].words == [("G", 1.0, 1), ("X", 2.0, 4)]
    assert bs[1].text == "G1 X2"


def test_no_trailing_newline():
    assert words("G0 X1\nG1 X2") == [[("G", 0.0, 1), ("X", 1.0, 4)], [("G", 1.0, 1), ("X", 2.0, 4)]]


def test_percent_delimiters():
    src = "(header)\n%\nG0 X1\n%\nG0 X99 this is not read\n"
    assert [b.line for b in blocks(src)] == [1, 3]
    # without an opening %, a % line ends the program
    assert [b.line for b in blocks("G0 X1\n%\nG0 X2\n")] == [1]


def test_block_delete_switch():
    src = "G0 X1\n/G0 X2\n  / G0 X3 (MSG, skipped)\n"
    assert [b.line for b in blocks(src)] == [1]  # default: switch on, lines deleted
    assert [b.words[1][1] for b in blocks(src, block_delete=False)] == [1.0, 2.0, 3.0]


def test_block_delete_applies_to_o_words():
    src = "#1=0\n/o1 if [1]\n/o1 endif\nG0 X1\n"
    assert [b.line for b in blocks(src)] == [4]
    assert [b.line for b in blocks(src, block_delete=False)] == [4]


@pytest.mark.parametrize(
    "src, line, col, needle",
    [
        ("G1 X1 (open comment\n", 1, 7, "unterminated comment"),
        ("G1 X1 ) Y1\n", 1, 7, "')'"),
        ("G1 (a (nested) b)\n", 1, 7, "nested"),
        ("G0\nG1 X\n", 2, 4, "X has no value"),
        ("G1 X Y2\n", 1, 4, "X has no value"),
        ("G1 X1 K-\n", 1, 7, "K has no value"),
        ("1.5 G1\n", 1, 1, "number without a word letter"),
        ("G1 [1]\n", 1, 4, "expression without a word letter"),
        ("G1 X1 E5\n", 1, 7, "'E'"),
        ("G1 X1e5\n", 1, 6, "exponent"),
        ("G1 X1.2.3\n", 1, 8, "word letter"),
        ("G1 X[1+2\n", 1, 5, "unclosed '['"),
        ("G1 X[[1+2]\n", 1, 5, "unclosed '['"),
        ("G1 X1]\n", 1, 6, "']'"),
        ("G1 X1 = 2\n", 1, 7, "'='"),
        ("G1 X1 #1\n", 1, 7, "'='"),
        ("G1 X1 \x00\x01\n", 1, 7, "invalid character"),
        ("G1 X\xe91\n", 1, 4, "X has no value"),
        ("G1 X1 %\n", 1, 7, "'%'"),
        ("G1 X1 O100\n", 1, 7, "O-word"),
        ("G1 X" + "9" * 400 + "\n", 1, 5, "too large"),
    ],
)
def test_errors_with_location(src, line, col, needle):
    e = err(src)
    assert (e.location.line, e.location.col) == (line, col), e.format()
    assert needle in e.message, e.format()
    assert e.location.file == "t.ngc"
    assert e.format().startswith(f"t.ngc:{line}:{col}: error: ")


def test_unsupported_constructs_named():
    assert "spindle selection" in err("G1 X1 $1\n", UnsupportedError).message
    assert "Fanuc" in err("O1000\nG0 X1\n", UnsupportedError).message


def test_binary_garbage_is_a_clean_error():
    rng = np.random.default_rng(5)
    data = bytes(rng.integers(0, 256, 5000, dtype=np.uint8))
    e = err(data)
    assert e.location.line >= 1
    assert e.format().count("\n") == 0


def test_two_megabyte_line_is_fast_and_rejected():
    data = b"G1 " + b"X1 " * 700_000 + b"\n"
    t = time.perf_counter()
    e = err(data)
    assert "characters long" in e.message and e.location.line == 1
    assert time.perf_counter() - t < 5.0  # linear: a quadratic scan would take minutes
    # a long line under the limit is read linearly too, on either path
    long_plain = b"G1 " + b"X1 " * 300_000 + b"\n"
    (b,) = blocks(long_plain)
    assert len(b.words) == 300_001
    long_slow = b"G1 " + b"X[1] " * 150_000 + b"\n"
    (b,) = blocks(long_slow)
    assert len(b.words) == 150_001 and b.words[-1][1] == 1.0


# ---------------------------------------------------------------- fast path == slow path
_LETTERS = "GXYZIJKFSTMPQRABCUVWDHL" + "gxyzfe" + "o"


def _random_number(rng: random.Random) -> str:
    kind = rng.random()
    if kind < 0.5:
        s = f"{rng.uniform(-1000, 1000):.{rng.randint(0, 6)}f}"
    elif kind < 0.7:
        s = str(rng.randint(0, 99999))
    elif kind < 0.8:
        s = rng.choice([".5", "5.", "-.25", "+3", "007", "-0", "1.2.3", "", "-", "12345678901234567890.5"])
    elif kind < 0.9:
        s = "".join(rng.choice("0123456789") for _ in range(rng.randint(1, 20))) + "." + str(rng.randint(0, 9))
    else:
        s = repr(rng.uniform(-1e6, 1e6)).replace("e", "")
    return s


def _random_line(rng: random.Random) -> str:
    parts = []
    if rng.random() < 0.5:
        parts.append(f"N{rng.randint(0, 10**6)}" + ("" if rng.random() < 0.95 else ".5"))
    for _ in range(rng.randint(0, 6)):
        parts.append(rng.choice(_LETTERS) + rng.choice(["", "", "", " "]) + _random_number(rng))
    if rng.random() < 0.03:
        parts.insert(rng.randint(0, len(parts)), rng.choice(["N5", "(c)", "#1=2", "[", "\t", "1"]))
    seps = [rng.choice([" ", " ", " ", "", "  ", "\t"]) for _ in parts]
    lead = rng.choice(["", "", "", " "])
    return lead + "".join(p + s for p, s in zip(parts, seps))


def test_fast_path_equals_slow_path_random():
    rng = random.Random(1234)
    lines = [_random_line(rng) for _ in range(6000)]
    text = "\n".join(lines) + "\n"
    b = text.encode("latin-1")
    line_starts, special = scan(b)
    slow, offs, tuples, raw = tokenize_chunk(b, text, line_starts, special, 0, len(lines))
    n_fast = 0
    for j, line in enumerate(lines):
        assert raw[j] == line
        try:
            lc = lex_line(line, j + 1, "t.ngc")
            expect = [(w, v, c) for w, v, c in lc.words]
        except GCodeError:
            expect = None
        if slow[j]:
            continue
        n_fast += 1
        assert expect is not None, f"fast path accepted a bad line: {line!r}"
        got = tuples[offs[j] : offs[j + 1]]
        assert got == expect, line
        assert all(np.signbit(g[1]) == np.signbit(x[1]) for g, x in zip(got, expect)), line
    assert n_fast > 1500  # the sweep really exercises the fast path


def test_fast_path_takes_plain_cam_lines():
    lines = ["N1 G1 X1.234 Y-5.6 F1200", "G2 X1 Y2 I.5 J-0.5", "x1 y2", "G0Z5"]
    text = "\n".join(lines) + "\n"
    b = text.encode()
    ls, sp = scan(b)
    slow, offs, tuples, _ = tokenize_chunk(b, text, ls, sp, 0, len(lines))
    assert slow.tolist() == [False] * 4
    assert tuples[offs[2] : offs[3]] == [("X", 1.0, 1), ("Y", 2.0, 4)]


def test_fast_path_sends_only_bad_lines_to_slow_path():
    lines = ["G1 X1", "G1 X1.2.3", "G1 X2", "G1 X.", "N10.5 G1 X3", "N.5 X1", "G1 X4 (c)", "G1 X5"]
    text = "\n".join(lines) + "\n"
    b = text.encode()
    ls, sp = scan(b)
    slow, offs, tuples, _ = tokenize_chunk(b, text, ls, sp, 0, len(lines))
    assert slow.tolist() == [False, True, False, True, False, True, True, False]
    assert tuples[offs[4] : offs[5]] == [("G", 1.0, 7), ("X", 3.0, 10)]
    assert tuples[offs[7] : offs[8]] == [("G", 1.0, 1), ("X", 5.0, 4)]
    e = err("G1 X.\n")
    assert e.location.col == 5


def test_whole_program_mixed_paths_keep_order():
    rng = random.Random(7)
    good = []
    for _ in range(3000):
        line = _random_line(rng)
        try:
            lex_line(line, 1, "t")
        except GCodeError:
            continue
        good.append(line)
    text = "\n".join(good) + "\n"
    bs = blocks(text)
    expect = []
    for i, line in enumerate(good):
        lc = lex_line(line, i + 1, "t")
        if lc.words or lc.comment is not None:
            expect.append((i + 1, lc.words))
    assert [(b.line, b.words) for b in bs] == expect


def test_random_text_never_crashes():
    """Seeded fuzz: arbitrary G-code-like text reads or ends in a clean GCodeError."""
    rng = random.Random(99)
    alphabet = list("GXYZIJKFNOE#[]<>()=+-*/.;%0123456789 \t") + [
        "o1 ",
        "if",
        "while",
        "endwhile",
        "endif",
        "sub",
        "endsub",
        "call",
        "repeat",
        "endrepeat",
        "do",
        "break",
        "continue",
        "return",
        "else",
        "elseif",
        "#<a>",
        "#<_b>",
        "sin",
        "atan",
        "mod",
        "eq",
        "and",
        "exists",
        "\x00",
        "\xe9",
        "\n",
        "\n",
        "\n",
    ]
    outcomes = {"ok": 0, "error": 0}
    for _ in range(1500):
        text = "".join(rng.choice(alphabet) for _ in range(rng.randint(1, 60)))
        try:
            blocks(text)
            outcomes["ok"] += 1
        except GCodeError as e:
            assert e.location.line >= 1 and e.location.col >= 1, e.format()
            assert "\n" not in e.format()
            outcomes["error"] += 1
    assert outcomes["ok"] > 10 and outcomes["error"] > 500


_VALID = """%
#<n> = 3 #1 = 0
o<f> sub
  o1 if [#1 GT 2]
    o<f> return [#1 * 2]
  o1 elseif [#1 EQ 1]
    G1 X[SIN[30] + #1] Y#<_g>
  o1 else
    G2 X1 Y1 I0.5 J0 F100
  o1 endif
o<f> endsub
#<_g> = 1.5
o2 repeat [#<n>]
  o<f> call [#1]
  #1 = [#1 + 1]
  o3 while [#1 LT 2]
    #1 = [#1 + 1]
    o3 continue
  o3 endwhile
o2 endrepeat
o4 do
  G0 Z[ATAN[1]/[2] MOD 7]
o4 while [0]
N100 G1 X1.5 Y-2 F1200 (done)
%
"""


def test_mutated_programs_never_crash(monkeypatch):
    """Seeded fuzz: small mutations of a valid program read or end in a clean error."""
    from cnc_interp.gcode import oword

    monkeypatch.setattr(oword, "LOOP_ITERATION_LIMIT", 200)  # mutants may loop forever
    assert blocks(_VALID)
    rng = random.Random(2024)
    pieces = list("#[]<>()=+-*/.;%0123456789 \nGXo") + ["if", "endif", "while", "sub", "call", "\x00"]
    errors = 0
    for _ in range(1200):
        text = list(_VALID)
        for _ in range(rng.randint(1, 3)):
            i = rng.randrange(len(text))
            op = rng.random()
            if op < 0.4:
                del text[i]
            elif op < 0.8:
                text.insert(i, rng.choice(pieces))
            else:
                text[i] = rng.choice(pieces)
        try:
            blocks("".join(text))
        except GCodeError as e:
            assert e.location.line >= 1 and e.location.col >= 1, e.format()
            errors += 1
    assert errors > 200
