"""Bulk tokeniser for plain CAM lines (``N123 G1 X1.234 Y-5.6 F1200``), in numpy.

A *plain* line holds only word letters (not E, O), digits, ``. + -`` and blanks,
and every letter is followed directly by a number (optionally signed, at most one
dot, a digit next to the dot), with ``N`` only as the line's first character and
unsigned. Such a line needs no parameters, expressions, comments or O-words, so
its words are computed for a whole chunk of lines at once:

* :func:`scan` finds, for the whole file, where lines start and which lines are
  *special* (contain any other character: comments, ``#``, ``[``, O-words, ``%``,
  ``/``, lower-case ``e``/``o``, control or non-ASCII bytes) or are too long;
* :func:`tokenize_chunk` tokenises a range of lines, sends every line that breaks
  the plain grammar to the slow path (:mod:`.lexer`, which then reports the error
  or handles the unusual spelling), and returns per-line slices of ready
  ``(LETTER, value, col)`` tuples.

Values are exact: numbers are converted by ``np.fromstring`` (Python's correctly
rounded string-to-double), the same float as ``float(text)`` on the slow path; a
number that overflows to infinity sends its line to the slow path, which reports it.
"""

from __future__ import annotations

from ..constants import MAX_LINE_CHARS

#: bytes a plain line may contain (besides the newline)
PLAIN_BYTES = b"ABCDFGHIJKLMNPQRSTUVWXYZabcdfghijklmnpqrstuvwxyz0123456789.+- \t\r"


def scan(b: bytes):
    """Line starts and special-line mask of the whole text ``b`` (ends with b'\\n').

    Returns ``(line_starts, special)``: ``line_starts`` (n_lines + 1,) int64 byte
    offsets (the last is ``len(b)``) and ``special`` (n_lines,) bool.
    """
    import numpy as np

    a = np.frombuffer(b, np.uint8)
    nl = np.flatnonzero(a == 10)
    line_starts = np.empty(len(nl) + 1, np.int64)
    line_starts[0] = 0
    line_starts[1:] = nl + 1
    special = np.zeros(len(nl), bool)
    left = np.frombuffer(b.translate(None, PLAIN_BYTES), np.uint8)
    if len(left) > len(nl):
        lnl = left == 10
        lid = np.cumsum(lnl) - lnl
        special[lid[~lnl]] = True
    special |= np.diff(line_starts) > MAX_LINE_CHARS
    return line_starts, special


def tokenize_chunk(b: bytes, text: str | None, line_starts, special, l0: int, l1: int):
    """Tokenise lines ``l0 .. l1-1`` (0-based) of ``b`` / ``text`` (``None``: the text is
    ``b`` decoded as latin-1, and only this chunk of it is decoded).

    Returns ``(slow, offs, tuples, lines)``: ``slow`` (n,) bool array (True: use
    the slow path), ``offs`` (n+1,) int array, the words of plain line j being
    ``tuples[offs[j]:offs[j+1]]`` (N words dropped), and ``lines`` the raw line
    strings. Callers building many objects should pause the cyclic GC around it.
    """
    import numpy as np

    s0 = int(line_starts[l0])
    s1 = int(line_starts[l1])
    nlines = l1 - l0
    lines = (b[s0:s1].decode("latin-1") if text is None else text[s0:s1]).split("\n")
    starts = line_starts[l0:l1] - s0  # local start of each line
    nl_pos = line_starts[l0 + 1 : l1 + 1] - 1 - s0  # local position of each newline
    lens = np.diff(line_starts[l0 : l1 + 1])
    a = np.frombuffer(b, np.uint8, count=s1 - s0, offset=s0).copy()

    def blank(mask) -> None:
        a[np.repeat(mask, lens)] = 32
        a[nl_pos] = 10

    sp = special[l0:l1]
    if sp.any():
        blank(sp)

    def prev(x, first):
        return np.concatenate(([first], x[:-1]))

    def nxt(x):
        return np.concatenate((x[1:], [False]))

    letter = a >= 65  # after blanking only word letters are >= 65
    digit = (a >= 48) & (a <= 57)
    dot = a == 46
    numch = digit | dot
    sign = (a == 43) | (a == 45)
    is_n = (a == 78) | (a == 110)
    p_letter = prev(letter, False)
    n_numch = nxt(numch)
    viol = sign & ~(p_letter & n_numch)  # a sign sits between a letter and a number
    viol |= numch & ~(p_letter | prev(sign, False) | prev(numch, False))  # number after letter
    viol |= letter & ~(nxt(sign) | n_numch)  # letter before a number
    viol |= is_n & ~(prev(a == 10, True) & nxt(digit))  # N first on the line, unsigned
    viol |= dot & ~(prev(digit, False) | nxt(digit))  # a number has a digit next to its dot
    slow = sp.copy()
    vpos = np.flatnonzero(viol)
    if len(vpos):
        slow[np.searchsorted(nl_pos, vpos)] = True
        blank(slow & ~sp)  # now every letter has exactly one number and no number is stray...
    P = np.flatnonzero(a >= 65)
    vals = _numbers(a)
    if vals is None or len(vals) != len(P):
        # ...except a number with two dots ("1.2.3"): find those lines, blank them too
        dots = np.flatnonzero(a == 46)
        breaks = np.flatnonzero(~numch)  # the chunk ends with a newline: every run ends
        run_end = breaks[np.searchsorted(breaks, dots[:-1])]
        twice = dots[:-1][dots[1:] < run_end]
        slow[np.searchsorted(nl_pos, twice)] = True
        blank(slow & ~sp)
        P = np.flatnonzero(a >= 65)
        vals = _numbers(a)
        if vals is None or len(vals) != len(P):  # cannot happen; stay correct anyway
            return np.ones(nlines, bool), np.zeros(nlines + 1, np.int64), [], lines
    tok_line = np.searchsorted(nl_pos, P)
    bad = ~np.isfinite(vals)  # overflowing numbers: the slow path reports them
    if bad.any():
        slow[tok_line[bad]] = True
    is_nt = is_n[P]
    keep = ~is_nt & ~slow[tok_line]
    P = P[keep]
    tok_line = tok_line[keep]
    cols = P - starts[tok_line] + 1
    letters = (a[P] & 0xDF).tobytes().decode("ascii")
    tuples = list(zip(letters, vals[keep].tolist(), cols.tolist()))
    counts = np.bincount(tok_line, minlength=nlines)
    offs = np.concatenate(([0], np.cumsum(counts)))
    return slow, offs, tuples, lines


def _numbers(a):
    """All numbers of the (blanked) chunk ``a``, or None if one does not parse."""
    import warnings

    import numpy as np

    with warnings.catch_warnings():
        # numpy warns (future versions raise) when text is left over, e.g. "1.2.3"
        warnings.simplefilter("error", DeprecationWarning)
        try:
            return np.fromstring(a.tobytes().translate(_TO_SPACE), sep=" ")
        except (DeprecationWarning, ValueError):
            return None


_LETTERS = b"ABCDFGHIJKLMNPQRSTUVWXYZabcdfghijklmnpqrstuvwxyz"
#: letters and line breaks become blanks, leaving only the numbers for np.fromstring
_TO_SPACE = bytes.maketrans(_LETTERS + b"\n\t\r", b" " * (len(_LETTERS) + 3))
