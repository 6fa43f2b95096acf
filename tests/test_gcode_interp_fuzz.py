"""Seeded random word soup: the interpreter ends every program cleanly or with a CncInterpError."""

from __future__ import annotations

import random

import numpy as np
import pytest

from cnc_interp.errors import CncInterpError
from cnc_interp.gcode import Run, read_program

G_CODES = [
    "0",
    "1",
    "2",
    "3",
    "4",
    "5",
    "5.1",
    "5.2",
    "5.3",
    "10",
    "17",
    "18",
    "19",
    "20",
    "21",
    "28",
    "28.1",
    "30",
    "40",
    "43",
    "49",
    "53",
    "54",
    "55",
    "59.3",
    "61",
    "61.1",
    "64",
    "73",
    "80",
    "81",
    "82",
    "83",
    "85",
    "89",
    "90",
    "91",
    "90.1",
    "91.1",
    "92",
    "92.1",
    "92.2",
    "92.3",
    "93",
    "94",
    "98",
    "99",
    "7",
    "8",
    "33",
    "38.2",
    "41",
    "95",
    "12",
]
M_CODES = ["0", "1", "2", "3", "5", "6", "8", "9", "30", "60", "48", "66", "98", "100", "200"]
LETTERS = "XYZABCIJKRPQLFSTHD"


def _soup(rng: random.Random) -> str:
    lines = []
    for _ in range(rng.randint(1, 25)):
        words = []
        for _ in range(rng.randint(0, 6)):
            r = rng.random()
            if r < 0.25:
                words.append("G" + rng.choice(G_CODES))
            elif r < 0.32:
                words.append("M" + rng.choice(M_CODES))
            else:
                v = rng.choice([0, 1, -1, 2, 0.5, rng.uniform(-50, 50), rng.randint(0, 10)])
                words.append(f"{rng.choice(LETTERS)}{v:.4f}")
        lines.append(" ".join(words))
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("seed", range(40))
def test_word_soup_never_crashes(seed):
    rng = random.Random(seed)
    for _ in range(25):
        text = _soup(rng)
        try:
            p = read_program(text, "fuzz.ngc")
        except CncInterpError as exc:
            assert exc.location.line >= 1, exc.format()
            continue
        for it in p.items:
            if isinstance(it, Run):
                assert np.all(np.isfinite(it.nodes))
                assert it.nodes.shape == (it.n_nodes, len(p.axes))


def _num(rng: random.Random, lo: float = -20, hi: float = 20) -> str:
    return f"{rng.uniform(lo, hi):.3f}"


def _structured(rng: random.Random) -> str:
    """Mostly valid programs that walk through many modal states."""
    lines = ["G21 G90 G17 G94 F600", "G0 X0 Y0 Z10"]
    for _ in range(rng.randint(5, 40)):
        r = rng.random()
        if r < 0.3:
            lines.append(f"G{rng.choice(['0', '1'])} X{_num(rng)} Y{_num(rng)} Z{_num(rng, -5, 10)}")
        elif r < 0.4:
            lines.append(f"G{rng.choice(['2', '3'])} X{_num(rng)} Y{_num(rng)} R{_num(rng, -30, 30)}")
        elif r < 0.45:
            lines.append(f"G{rng.choice(['2', '3'])} I{_num(rng, -5, 5)} J{_num(rng, -5, 5)} P{rng.randint(1, 3)}")
        elif r < 0.5:
            code = rng.choice(["81", "82 P0.1", "83 Q1.5", "73 Q0.7", "85", "89 P0.2"])
            lines.append(
                f"G{rng.choice(['98', '99'])} G{code} X{_num(rng)} Y{_num(rng)} "
                f"Z{_num(rng, -6, 0)} R{_num(rng, 0, 3)} L{rng.randint(1, 3)}"
            )
            lines.append("G80")
        elif r < 0.55:
            lines.append(
                rng.choice(
                    [
                        "G91",
                        "G90",
                        "G20",
                        "G21",
                        "G61",
                        "G61.1",
                        "G64 P0.01",
                        "G64",
                        "G18",
                        "G19",
                        "G17",
                        "G90.1",
                        "G91.1",
                        "G93",
                        "G94",
                    ]
                )
            )
        elif r < 0.6:
            lines.append(
                rng.choice(
                    [
                        f"G92 X{_num(rng)}",
                        "G92.1",
                        "G92.2",
                        "G92.3",
                        f"G10 L2 P{rng.randint(0, 3)} X{_num(rng)} Y{_num(rng)}",
                        f"G10 L20 P1 Z{_num(rng)}",
                        f"G5{rng.randint(4, 6)}",
                        "G28.1",
                        "G28",
                        f"G53 G0 Z{_num(rng, 0, 20)}",
                    ]
                )
            )
        elif r < 0.65:
            lines.append(rng.choice(["G4 P0.5", "M0", "M1", "T1 M6", "M3 S1000", "M9"]))
        elif r < 0.7:
            lines.append("G5.2 P1 L3")
            for _ in range(rng.randint(0, 5)):
                lines.append(f"X{_num(rng)} Y{_num(rng)} P{rng.choice(['1', '2', '0.5'])}")
            lines.append("G5.3")
        elif r < 0.75:
            lines.append(
                f"G5 I{_num(rng, -3, 3)} J{_num(rng, -3, 3)} P{_num(rng, -3, 3)} "
                f"Q{_num(rng, -3, 3)} X{_num(rng)} Y{_num(rng)}"
            )
        elif r < 0.8:
            lines.append(f"G1 A{_num(rng, -90, 90)} C{_num(rng, 0, 360)} F{rng.randint(1, 900)}")
        else:
            lines.append(f"X{_num(rng)} Y{_num(rng)} F{rng.randint(50, 2000)}")
    return "\n".join(lines) + "\nM2\n"


@pytest.mark.parametrize("seed", range(40))
def test_structured_programs_never_crash(seed):
    rng = random.Random(1000 + seed)
    for _ in range(10):
        text = _structured(rng)
        try:
            p = read_program(text, "fuzz.ngc")
        except CncInterpError as exc:
            assert exc.location.line >= 1, exc.format()
            continue
        for it in p.items:
            if isinstance(it, Run):
                assert np.all(np.isfinite(it.nodes))
                assert np.all(it.feed_mm_s > 0)
                for cp in it.curves:
                    assert 0 <= cp.first < cp.last < it.n_nodes
