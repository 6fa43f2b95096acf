"""Test vectors for an HDL test bench of the datapath, ``$readmemh`` style.

``export_test_vectors(prog, out_dir)`` writes, for the program's planar segments:

- ``segments.hex``: per segment, 14 words: cos, sin, origin_h, origin_v, x_exp,
  x_mant, p_exp, p_mant[0..5], n_pieces;
- ``pieces.hex``: per profile piece (segments in order), 9 words:
  n_samples, dtau, exp, mant[0..5];
- ``expected.hex``: per sample, 5 words: ξ, x*, z*, q_h, q_v (the golden model's
  outputs after the profile generator, the polynomial block and the integrators);
- ``layout.json``: word widths, formats and counts.

Every word is one line of two's complement hex, ``VECTOR_WORD_BITS`` wide
(zero-padded), so ``$readmemh("segments.hex", mem)`` with a 128-bit memory reads
them; narrower hardware registers take the low bits.
"""

from __future__ import annotations

import json
import os

from .model import FixedSegment, FpgaProgram, run_segment

VECTOR_WORD_BITS = 128
SEGMENT_WORDS = (
    "cos",
    "sin",
    "origin_h",
    "origin_v",
    "x_exp",
    "x_mant",
    "p_exp",
    "p_mant0",
    "p_mant1",
    "p_mant2",
    "p_mant3",
    "p_mant4",
    "p_mant5",
    "n_pieces",
)
PIECE_WORDS = ("n_samples", "dtau", "exp", "mant0", "mant1", "mant2", "mant3", "mant4", "mant5")
SAMPLE_WORDS = ("xi", "x_star", "z_star", "q_h", "q_v")


def hex_word(v: int, bits: int = VECTOR_WORD_BITS) -> str:
    """Two's complement hex of ``v`` in ``bits`` bits (raises if it does not fit)."""
    v = int(v)
    if not -(1 << (bits - 1)) <= v < (1 << (bits - 1)):
        raise ValueError(f"{v} does not fit {bits} bits")
    return format(v & ((1 << bits) - 1), f"0{bits // 4}x")


def parse_hex_word(text: str, bits: int = VECTOR_WORD_BITS) -> int:
    v = int(text, 16)
    return v - (1 << bits) if v >> (bits - 1) else v


def export_test_vectors(prog: FpgaProgram, out_dir: str, max_segments: int | None = None) -> dict:
    """Write the vector files into ``out_dir`` (created); returns the layout written."""
    from ..outfile import atomic_write

    os.makedirs(out_dir, exist_ok=True)
    segs = [it for it in prog.items if isinstance(it, FixedSegment)]
    if max_segments is not None:
        segs = segs[:max_segments]
    seg_lines, piece_lines, sample_lines = [], [], []
    for seg in segs:
        seg_lines += [
            hex_word(v)
            for v in (
                seg.cos,
                seg.sin,
                seg.origin[0],
                seg.origin[1],
                seg.x_exp,
                seg.x_mant,
                seg.p_exp,
                *seg.p_mant,
                len(seg.pieces),
            )
        ]
        for p in seg.pieces:
            piece_lines += [hex_word(v) for v in (p.n_samples, p.dtau, p.exp, *p.mant)]
        run = run_segment(seg, prog.formats, prog.source)
        for j in range(run.xi.shape[0]):
            sample_lines += [hex_word(v) for v in (run.xi[j], run.x[j], run.z[j], run.q[j, 0], run.q[j, 1])]
    f = prog.formats
    layout = {
        "word_bits": VECTOR_WORD_BITS,
        "segment_words": list(SEGMENT_WORDS),
        "piece_words": list(PIECE_WORDS),
        "sample_words": list(SAMPLE_WORDS),
        "segments": len(segs),
        "pieces": sum(len(s.pieces) for s in segs),
        "samples": sum(s.n_samples for s in segs),
        "formats": {
            "pos": [f.pos.word, f.pos.frac],
            "trig": [f.trig.word, f.trig.frac],
            "param": [f.param.word, f.param.frac],
            "coef_word": f.coef_word,
            "horner_word": f.horner_word,
            "int_word": f.int_word,
            "mult_word": f.mult_word,
        },
        "rounding": "round half up: add 2^(shift-1), arithmetic shift right",
        "integrators": "reset to the segment origin at each segment start (resynchronisation)",
    }
    for name, lines in (("segments.hex", seg_lines), ("pieces.hex", piece_lines), ("expected.hex", sample_lines)):
        with atomic_write(os.path.join(out_dir, name)) as fh:
            fh.write(("\n".join(lines) + "\n").encode("ascii") if lines else b"")
    with atomic_write(os.path.join(out_dir, "layout.json")) as fh:
        fh.write((json.dumps(layout, indent=2, sort_keys=True) + "\n").encode("ascii"))
    return layout


def replay_vectors(out_dir: str, formats) -> list[tuple[int, int, int, int, int]]:
    """Re-run the datapath from ``segments.hex``/``pieces.hex`` alone (a software test bench).

    Returns the per-sample (ξ, x*, z*, q_h, q_v) the files imply; tests compare
    them with ``expected.hex``.
    """
    from .model import ProfilePiece

    def words(name):
        with open(os.path.join(out_dir, name)) as fh:
            return [parse_hex_word(x) for x in fh.read().split()]

    sw, pw = words("segments.hex"), words("pieces.hex")
    out = []
    pi = 0
    for k in range(0, len(sw), len(SEGMENT_WORDS)):
        c, s, oh, ov, x_exp, x_mant, p_exp, *rest = sw[k : k + len(SEGMENT_WORDS)]
        p_mant, n_pieces = tuple(rest[:6]), rest[6]
        pieces = []
        for _ in range(n_pieces):
            n, dtau, exp, *mant = pw[pi : pi + len(PIECE_WORDS)]
            pieces.append(ProfilePiece(n, dtau, exp, tuple(mant)))
            pi += len(PIECE_WORDS)
        seg = FixedSegment(
            index=k // len(SEGMENT_WORDS),
            line=0,
            plane=(0, 1),
            cos=c,
            sin=s,
            origin=(oh, ov),
            x_exp=x_exp,
            x_mant=x_mant,
            p_exp=p_exp,
            p_mant=p_mant,
            start_sample=0,
            pieces=tuple(pieces),
        )
        run = run_segment(seg, formats)
        out += [
            (int(run.xi[j]), int(run.x[j]), int(run.z[j]), int(run.q[j, 0]), int(run.q[j, 1]))
            for j in range(run.xi.shape[0])
        ]
    return out
