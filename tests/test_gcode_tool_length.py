"""Tool length offsets as LinuxCNC applies them: G43 [H], G43.1, G43.2, G49, tool tables."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from cnc_interp.errors import CncInterpWarning, GCodeError, MachineError
from cnc_interp.gcode import read_program
from cnc_interp.gcode.tooltable import parse_tool_table

TABLE = parse_tool_table("T1 P1 Z+12.5 D6 ;6 mm end mill\nT2 P2 X0.5 Z-3.25\n\n; spare\nT7 Z100\n", "tool.tbl")


def nodes(text: str, table=TABLE) -> np.ndarray:
    prog = read_program(text.encode(), "t.ngc", axes="XYZ", tool_table=table)
    return np.concatenate([it.nodes[1:] for it in prog.items if hasattr(it, "nodes")])


def test_tool_table_format():
    assert TABLE[1] == (0.0, 0.0, 12.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert TABLE[2][0] == 0.5 and TABLE[2][2] == -3.25 and set(TABLE) == {1, 2, 7}
    for bad in ("P1 Z3\n", "T1 Z\n", "T1 Q3 K4\n", "T1.5 Z1\n", "T1 Z1e400\n"):
        with pytest.raises(MachineError) as exc:
            parse_tool_table(bad, "bad.tbl")
        assert exc.value.location.line == 1


def test_offset_applies_from_the_next_move_and_g49_cancels():
    q = nodes("G21 G90 F600\nG0 Z10\nG43 H1\nG0 Z5\nG1 X10\nG49\nG0 Z5\nM2\n")
    # G43 alone moves nothing; the next Z5 is the tool tip at 5, the spindle at 17.5
    np.testing.assert_allclose(q[:, 2], [10.0, 17.5, 17.5, 5.0])


def test_g43_axis_words_are_a_move_with_the_new_offset_not_an_offset():
    # LinuxCNC: "G43 H1 Z3" applies tool 1's offset and moves the tip to Z3; the axis word
    # is the block's motion (G0 modal), added to no offset (only G43.2 takes axis offsets)
    q = nodes("G21 G90\nG0 X1\nG43 H1 Z3\nG1 Z-1 F100\nM2\n")
    np.testing.assert_allclose(q[:, 2], [0.0, 15.5, 11.5])


def test_g43_without_h_uses_the_tool_in_the_spindle():
    q = nodes("G21 G90 F600\nT2 M6\nG43\nG0 X1 Z0\nM2\n")
    np.testing.assert_allclose(q[-1], [1.5, 0.0, -3.25])
    q = nodes("G21 G90 F600\nT2\nG43\nG0 Z1\nM2\n")  # selected, not loaded: tool 0
    np.testing.assert_allclose(q[-1], [0.0, 0.0, 1.0])


def test_h0_and_a_new_g43_replace_not_add():
    q = nodes("G21 G90\nG43 H1\nG0 Z0\nG43 H2\nG0 Z0\nG43 H0\nG0 Z1\nM2\n")
    np.testing.assert_allclose(q[:, 2], [12.5, -3.25, 1.0])


def test_g43_1_dynamic_and_g43_2_additional_offsets_in_program_units():
    q = nodes("G21 G90\nG43.1 Z2\nG0 Z0\nG43.2 H1\nG0 Z0\nG43.2 Z0.5\nG0 Z0\nG20\nG43.1 Z1\nG0 Z0\nM2\n")
    np.testing.assert_allclose(q[:, 2], [2.0, 14.5, 15.0, 25.4])


def test_tlo_parameters_and_g10_l1():
    prog = read_program(
        b"G21 G90\nG10 L1 P3 Z4\nG43 H3\n#1=#5403\nG0 Z[#1]\nM2\n", "t.ngc", axes="XYZ", tool_table=TABLE
    )
    np.testing.assert_allclose(prog.items[0].nodes[-1], [0.0, 0.0, 8.0])
    assert 3 not in TABLE  # the caller's table is not edited


def test_errors_name_the_block():
    for text, msg in (
        ("G43 H9\n", "not in the tool table"),
        ("G43.1\n", "G43.1 without axis"),
        ("G43.2\n", "G43.2 without H"),
        ("G43 H1.5\n", "H must be"),
        ("G10 L10 P1 Z0\nG43 H1\n", "G10 L10/L11"),
    ):
        with pytest.raises(GCodeError, match=msg) as exc:
            read_program(f"G21 G90\n{text}M2\n".encode(), "e.ngc", axes="XYZ", tool_table=TABLE)
        assert exc.value.location.line >= 2


def test_g43_1_with_a_motion_code_is_one_error_line():
    # G43.1/G43.2 take their offsets from the axis words, so a motion in the same block has
    # none: an error naming both codes at G43.x's column (it was a TypeError traceback)
    for text, owner, col in (("G43.1 Z1 G1 X1\n", "G43.1", 1), ("G1 X2 G43.2 Z1\n", "G43.2", 7)):
        with pytest.raises(GCodeError, match=f"{owner} and G1 both use the axis words") as exc:
            read_program(f"G21 G90\n{text}M2\n".encode(), "e.ngc", axes="XYZ", tool_table=TABLE)
        assert (exc.value.location.line, exc.value.location.col) == (2, col)
    # a group-0 code that takes the axis words is named first, as before
    with pytest.raises(GCodeError, match="G92 and G1 both use the axis words"):
        read_program(b"G21 G90\nG92 G43.1 G1 Z1\nM2\n", "e.ngc", axes="XYZ", tool_table=TABLE)


def test_no_table_applies_zero_with_one_warning():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        q = nodes("G21 G90\nG43 H1\nG0 Z5\nG43 H2\nG0 Z4\nM2\n", table=None)
    np.testing.assert_allclose(q[:, 2], [5.0, 4.0])
    ours = [w for w in caught if issubclass(w.category, CncInterpWarning)]
    assert len(ours) == 1 and str(ours[0].message).startswith("t.ngc:2:5: warning: G43 H1")


def test_cli_tool_table_and_ini_emcio(tmp_path):
    from tests._contract_helpers import run_inproc

    part = tmp_path / "p.ngc"
    part.write_text("G21 G90 F600\nG43 H1\nG0 Z5\nG1 X10\nM2\n")
    tbl = tmp_path / "tool.tbl"
    tbl.write_text("T1 P1 Z+12.5 D6 ;comment\n")
    res = run_inproc("plan", part, "--tool-table", tbl, "-q")
    assert res.code == 0 and res.err == "", res.explain()
    assert res.out.decode().strip().splitlines()[-1].endswith(",17.5")
    ini = tmp_path / "m.ini"
    ini.write_text(
        "[EMC]\nMACHINE = m\n[TRAJ]\nCOORDINATES = XYZ\n[EMCIO]\nTOOL_TABLE = tool.tbl\n"
        + "".join(f"[AXIS_{a}]\nMAX_VELOCITY = 100\nMAX_ACCELERATION = 1000\n" for a in "XYZ")
    )
    res = run_inproc("plan", part, "-m", ini, "-q")
    assert res.code == 0 and res.out.decode().strip().splitlines()[-1].endswith(",17.5"), res.explain()
    res = run_inproc("plan", part, "-q")
    assert res.code == 0 and res.err.count("warning: G43 H1") == 1
