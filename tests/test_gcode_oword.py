"""O-word control flow: subs with arguments and return values, if, loops, limits, errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from cnc_interp.constants import LOOP_ITERATION_LIMIT, MAX_CALL_DEPTH
from cnc_interp.errors import GCodeError, UnsupportedError
from cnc_interp.gcode import oword
from cnc_interp.gcode.blocks import iter_blocks
from cnc_interp.gcode.params import ParamStore

from .conftest import CORPUS as CORPUS_DIR

CORPUS = Path(CORPUS_DIR)


def run(src: str, params: ParamStore | None = None):
    return list(iter_blocks(src, "o.ngc", params if params is not None else ParamStore()))


def xs(src: str, letter: str = "X") -> list[float]:
    """Values of ``letter`` words, in execution order."""
    return [v for b in run(src) for w, v, _ in b.words if w == letter]


def err(src: str, cls=GCodeError) -> GCodeError:
    with pytest.raises(cls) as ei:
        run(src)
    return ei.value


def test_sub_with_arguments_and_return_value():
    src = """
o<hyp> sub
  #<h> = [SQRT[#1*#1 + #2*#2]]
  o<hyp> return [#<h>]
  G1 X999 (never reached)
o<hyp> endsub
#1 = 111
o<hyp> call [3] [4]
G1 X#<_value> Y#<_value_returned> Z#1
o<hyp> call [6] [8]
G1 X#<_value>
"""
    bs = run(src)
    assert [b.words for b in bs] == [
        [("G", 1.0, 1), ("X", 5.0, 4), ("Y", 1.0, 15), ("Z", 111.0, 35)],
        [("G", 1.0, 1), ("X", 10.0, 4)],
    ]
    assert [b.line for b in bs] == [9, 11]


def test_endsub_value_and_no_value():
    src = """
o100 sub
o100 endsub [#1 * 2]
o200 sub
  G0 X#1
o200 endsub
o100 call [21]
G1 X#<_value> Y#<_value_returned>
o200 call [7]
G1 X#<_value> Y#<_value_returned>
"""
    assert xs(src) == [42.0, 7.0, 0.0]  # endsub without a value returns 0
    assert xs(src, "Y") == [1.0, 0.0]
    assert xs("G1 X#<_value> Y#<_value_returned>\n") == [0.0]  # defined from the start


def test_call_frames_are_local():
    src = """
o<inner> sub
  #<loc> = 5
  #1 = 99
  #<_g> = [#<_g> + 1]
o<inner> endsub
#<loc> = 1
#1 = 10
#<_g> = 0
o<inner> call [3]
G1 X#<loc> Y#1 Z#<_g> A[EXISTS[#<loc>]]
"""
    (b,) = run(src)
    assert [v for _, v, _ in b.words[1:]] == [1.0, 10.0, 1.0, 1.0]


def test_missing_arguments_are_zero_and_sub_may_follow_call():
    src = "#2 = 7\no<s> call [1]\nG1 X#<_value>\no<s> sub\no<s> return [#1 + #2]\no<s> endsub\n"
    assert xs(src) == [1.0]


def test_recursion_factorial():
    src = """
o<fact> sub
  o1 if [#1 LE 1]
    o<fact> return [1]
  o1 endif
  o<fact> call [#1 - 1]
  o<fact> return [#1 * #<_value>]
o<fact> endsub
o<fact> call [6]
G1 X#<_value>
"""
    assert xs(src) == [720.0]


def test_nested_if_elseif_else():
    src = """
#1 = 0
o1 while [#1 LT 6]
  o2 if [#1 EQ 0]
    G1 X0
  o2 elseif [#1 LT 3]
    o3 if [#1 EQ 2]
      G1 X22
    o3 else
      G1 X11
    o3 endif
  o2 elseif [#1 EQ 3]
    G1 X33
  o2 else
    G1 X[100 + #1]
  o2 endif
  #1 = [#1 + 1]
o1 endwhile
"""
    assert xs(src) == [0.0, 11.0, 22.0, 33.0, 104.0, 105.0]


def test_if_without_else_false_skips():
    assert xs("o1 if [0]\nG1 X1\no1 endif\nG1 X2\n") == [2.0]
    assert xs("o1 if [0]\nG1 X1\no1 elseif [0]\nG1 X3\no1 endif\nG1 X2\n") == [2.0]


def test_do_while_runs_once_at_least():
    src = "#1 = 10\no1 do\n  G1 X#1\n  #1 = [#1 + 1]\no1 while [#1 LT 3]\nG1 X-1\n"
    assert xs(src) == [10.0, -1.0]
    src = "#1 = 0\no1 do\n  G1 X#1\n  #1 = [#1 + 1]\no1 while [#1 LT 3]\n"
    assert xs(src) == [0.0, 1.0, 2.0]


def test_repeat_and_nested_loops():
    src = """
#1 = 0
o1 repeat [3]
  o2 repeat [2]
    #1 = [#1 + 1]
    G1 X#1
  o2 endrepeat
o1 endrepeat
o3 repeat [0]
  G1 X999
o3 endrepeat
"""
    assert xs(src) == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]


def test_break_and_continue():
    src = """
#1 = 0
o1 while [1]
  #1 = [#1 + 1]
  o2 if [#1 EQ 2]
    o1 continue
  o2 endif
  o3 if [#1 GT 4]
    o1 break
  o3 endif
  G1 X#1
o1 endwhile
G1 X100
#2 = 0
o4 repeat [5]
  #2 = [#2 + 1]
  o5 if [#2 EQ 3]
    o4 continue
  o5 endif
  G1 Y#2
o4 endrepeat
#3 = 0
o6 do
  #3 = [#3 + 1]
  o7 if [#3 EQ 2]
    o6 continue
  o7 endif
  G1 Z#3
o6 while [#3 LT 4]
"""
    assert xs(src) == [1.0, 3.0, 4.0, 100.0]
    assert xs(src, "Y") == [1.0, 2.0, 4.0, 5.0]
    assert xs(src, "Z") == [1.0, 3.0, 4.0]


def test_loop_in_subroutine_called_repeatedly():
    src = """
o<row> sub
  #<i> = 0
  o10 while [#<i> LT #1]
    G1 X[#<i> + #2]
    #<i> = [#<i> + 1]
  o10 endwhile
o<row> endsub
o<row> call [2] [10]
o<row> call [3] [20]
"""
    assert xs(src) == [10.0, 11.0, 20.0, 21.0, 22.0]


def test_line_numbers_and_comments_on_o_lines():
    src = "N10 o1 if [1] (yes)\nN20 G1 X1\nN30 O1 ENDIF ; done\n"
    bs = run(src)
    assert [(b.line, b.words) for b in bs] == [(2, [("G", 1.0, 5), ("X", 1.0, 8)])]


def test_numbered_o_words_compare_as_numbers():
    assert xs("o0100 if [1]\nG1 X1\no100 endif\n") == [1.0]


def test_o_word_reads_interpreter_parameters_lazily():
    p = ParamStore()
    it = iter_blocks("G0 X0\no1 while [#5420 LT 3]\nG1 X[#5420 + 1]\no1 endwhile\n", "o.ngc", p)
    seen = []
    for b in it:
        x = b.words[1][1]
        seen.append(x)
        p.set(5420, x)  # the interpreter records the position after each move
    assert seen == [0.0, 1.0, 2.0, 3.0]


@pytest.fixture
def small_limit(monkeypatch):
    # the mechanism, not the constant, is under test: keep the test fast
    monkeypatch.setattr(oword, "LOOP_ITERATION_LIMIT", 1000)
    return 1000


def test_loop_iteration_limit(small_limit):
    e = err("o1 while [1]\nG1 X1\no1 endwhile\n")
    assert "1000 iterations" in e.message and e.location.line == 1
    assert len(xs("#1=0\no1 while [#1 LT 1000]\n#1=[#1+1]\nG1 X1\no1 endwhile\n")) == 1000
    e = err("o1 repeat [1001]\no1 endrepeat\n")
    assert "LOOP_ITERATION_LIMIT" in e.message and e.location.line == 1


def test_loop_limit_on_do_while(small_limit):
    e = err("o7 do\no7 while [1]\n")
    assert "o7" in e.message and e.location.line == 2


def test_loop_limit_constant_is_large():
    assert LOOP_ITERATION_LIMIT >= 100_000


def test_call_depth_limit():
    e = err("o<r> sub\no<r> call\no<r> endsub\no<r> call\n")
    assert str(MAX_CALL_DEPTH) in e.message and e.location.line == 2


@pytest.mark.parametrize(
    "src, line, needle",
    [
        ("o<nope> call [1]\n", 1, "subroutine o<nope> not defined in this file"),
        ("o1 if [1]\nG1 X1\n", 1, "o1 if without o1 endif"),
        ("o1 endif\n", 1, "without an opening"),
        ("o1 if [1]\no2 endif\n", 2, "does not close o1 if"),
        ("o1 while [1]\no1 endif\n", 2, "does not close o1 while"),
        ("o1 else\n", 1, "without a matching o1 if"),
        ("o1 if [1]\no1 else\no1 elseif [1]\no1 endif\n", 3, "after o1 else"),
        ("o1 break\n", 1, "outside a o1 loop"),
        ("o1 while [1]\no2 break\no1 endwhile\n", 2, "outside a o2 loop"),
        ("o1 return\n", 1, "return outside subroutine"),
        ("o1 sub\no2 sub\no2 endsub\no1 endsub\n", 2, "defined inside"),
        ("o1 sub\no1 endsub\no1 sub\no1 endsub\n", 3, "defined twice"),
        ("o1 sub\n", 1, "without o1 endsub"),
        ("o1 if\no1 endif\n", 1, "takes 1"),
        ("o1 if [1] [2]\no1 endif\n", 1, "takes 1"),
        ("o1 if 1\no1 endif\n", 1, "[bracketed]"),
        ("o1 frobnicate\n", 1, "unknown O-word keyword"),
        ("o<> sub\n", 1, "empty O-word name"),
        ("o<abc sub\n", 1, "'>'"),
        ("o1 if [1/0]\no1 endif\n", 1, "division by zero"),
        ("o1 repeat [1.5]\no1 endrepeat\n", 1, "integer"),
        ("o<s> call [#<undefined>]\no<s> sub\no<s> endsub\n", 1, "#<undefined>"),
    ],
)
def test_structure_errors(src, line, needle):
    e = err(src)
    assert e.location.line == line, e.format()
    assert needle in e.message, e.format()
    assert e.location.col >= 1


def test_computed_o_numbers_unsupported():
    e = err("o#1 call\n", UnsupportedError)
    assert "computed" in e.message


def test_percent_ends_before_o_structure_check():
    # everything after the closing % is not part of the program
    assert xs("%\nG1 X1\n%\no1 if [1]\n") == [1.0]


def _corpus_files() -> list[Path]:
    if not CORPUS.is_dir():
        return []
    out = []
    for p in sorted(CORPUS.rglob("*")):
        if p.is_file() and p.suffix.lower() in (".ngc", ".nc", ".gcode", ".tap", ".txt"):
            out.append(p)
    return out


@pytest.mark.corpus
def test_corpus_reads_without_traceback():
    """Every corpus program reads through the block layer or ends in a clean GCodeError."""
    files = _corpus_files()
    assert files
    ok = clean = 0
    for p in files:
        params = ParamStore()
        try:
            for _ in iter_blocks(p.read_bytes(), str(p), params):
                pass
            ok += 1
        except GCodeError as e:
            assert e.location.file == str(p)
            assert e.format().startswith(str(p))
            clean += 1
    assert ok > clean  # most of the corpus is plain LinuxCNC G-code
