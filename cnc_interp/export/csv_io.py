"""Plan CSV: ``t,s,feed,<axis letters>`` and one row per sample.

Numbers are Python's shortest round-trip form (``repr(float)``), so reading the
file back gives the same float64 values bit for bit and anyone can re-check the
limits from the file. Units: s, mm, mm/s, then mm or deg per axis. No comment
lines; ``\\n`` line ends. The same trajectory always gives the same bytes.
"""

from __future__ import annotations

import io
import warnings
from typing import BinaryIO

import numpy as np

from ..constants import ALL_AXES
from ..errors import CncInterpError, SourceLocation
from ..outfile import atomic_write


#: rows per chunk when writing CSV (bounds memory of the string conversion)
CSV_CHUNK_ROWS = 65_536

#: t[k] may differ from t[0] + k*dt by this share of dt when a plan is read back (the
#: writer prints k*dt exactly; the tolerance is relative to the period, never to the clock)
CSV_TIME_REL_DT_TOL = 1e-6

_FIXED = ("t", "s", "feed")
#: blocks of at least this many rows are formatted in two halves on two threads
CSV_SPLIT_ROWS = 8192


class PlanFileError(CncInterpError):
    """A plan file (CSV) that cannot be read back: bad header, number or row length."""


class CsvPlanWriter:
    """Writes a plan as CSV while it is planned: the header, then ``write`` blocks of
    samples in order. The bytes do not depend on how the samples are split into blocks."""

    def __init__(self, fh: BinaryIO, axes: str):
        self.fh = fh
        self.rows = 0
        self._pool = None
        fh.write((",".join(_FIXED + tuple(axes)) + "\n").encode("ascii"))

    def write(self, t, s, feed, q) -> None:
        """Append rows (t, s, feed (K,), q (K, n))."""
        q = np.asarray(q, dtype=float)
        k = q.shape[0]
        cols = np.empty((3 + q.shape[1], k))
        cols[0] = t
        cols[1] = s
        cols[2] = feed
        cols[3:] = q.T
        for lo in range(0, k, CSV_CHUNK_ROWS):
            hi = min(k, lo + CSV_CHUNK_ROWS)
            if hi - lo >= CSV_SPLIT_ROWS:
                # two halves formatted at once (the formatter releases the GIL); the text of
                # a row does not depend on where the rows are cut
                mid = (lo + hi) // 2
                if self._pool is None:
                    from concurrent.futures import ThreadPoolExecutor

                    self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="cnc-interp-csv")
                second = self._pool.submit(format_rows, cols[:, mid:hi])
                self.fh.write(format_rows(cols[:, lo:mid]))
                self.fh.write(second.result())
            else:
                self.fh.write(format_rows(cols[:, lo:hi]))
        self.rows += k


def format_rows(cols: np.ndarray) -> bytes:
    """The columns ``cols`` (ncol, K) as K CSV rows: ``repr`` of each float (compiled:
    ``export._repr``), ``,`` between columns, ``\\n`` after each row."""
    from ._repr import format_table

    return format_table(cols)


def write_csv_to(traj, fh: BinaryIO) -> int:
    """Write ``traj`` as CSV to an open binary file; returns the number of rows."""
    w = CsvPlanWriter(fh, traj.axes)
    w.write(traj.t, traj.s, traj.feed, traj.q)
    return w.rows


def write_csv(traj, out: str) -> int:
    """Write ``traj`` to the file ``out`` atomically (``-`` = stdout); returns the row count."""
    with atomic_write(out) as fh:
        return write_csv_to(traj, fh)


def read_csv(path: str, dt_s: float | None = None):
    """Read a plan CSV back into a ``Trajectory`` (planner ``"csv"``, axes from the header).

    ``dt_s`` is needed only for a one-row file; otherwise it is taken from the
    ``t`` column, which must be t[0] + k*dt.
    """
    from ..plan.trajectory import Trajectory

    try:
        with open(path, "rb") as fh:
            first = fh.readline().rstrip(b"\n")
    except OSError as exc:
        raise PlanFileError(f"cannot read plan: {exc.strerror}", SourceLocation(file=path)) from None
    header = first.decode("ascii", "replace").strip().split(",")
    names = [h.strip() for h in header]
    hloc = SourceLocation(path, 1, 1, first.decode("ascii", "replace").strip())
    if tuple(names[:3]) != _FIXED:
        raise PlanFileError("not a plan CSV: the header must start with t,s,feed", hloc)
    axes = "".join(names[3:])
    if len(axes) != len(names) - 3 or any(a not in ALL_AXES for a in axes) or len(set(axes)) != len(axes):
        raise PlanFileError("plan CSV header: the columns after t,s,feed must be distinct axis letters", hloc)
    ncol = len(names)
    data = _parse_arrow(path, names)
    if data is None:
        try:
            with open(path, "rb") as fh:
                body = fh.read().partition(b"\n")[2]
        except OSError as exc:
            raise PlanFileError(f"cannot read plan: {exc.strerror}", SourceLocation(file=path)) from None
        data = _parse_numbers(body, ncol, path)
    k = data.shape[0]
    if k == 0:
        raise PlanFileError("plan CSV has no samples", hloc)
    t = data[:, 0]
    if k >= 2:
        dt_s = float(t[1] - t[0])  # the writer stores t = k*dt, so t[1] - t[0] is dt exactly
        expect = t[0] + np.arange(k) * dt_s
        bad = np.abs(t - expect) > CSV_TIME_REL_DT_TOL * abs(dt_s)
        if not dt_s > 0 or bad.any():
            row = int(np.argmax(bad)) if bad.any() else 1
            raise PlanFileError("plan CSV: t is not sampled at a fixed period", SourceLocation(path, row + 2, 1))
    elif dt_s is None:
        raise PlanFileError("plan CSV with one sample: the sample period is unknown", hloc)
    return Trajectory(
        axes=axes,
        dt_s=float(dt_s),
        t=np.ascontiguousarray(t),
        s=np.ascontiguousarray(data[:, 1]),
        feed=np.ascontiguousarray(data[:, 2]),
        q=np.ascontiguousarray(data[:, 3:]),
        line=np.zeros(k, dtype=np.int64),
        planner="csv",
        settings={"source": path},
    )


def _parse_arrow(path: str, names: list[str]) -> np.ndarray | None:
    """The rows as a (K, ncol) array read by Arrow's multithreaded CSV reader (correctly
    rounded, about 5x numpy's text parsers on 2 cores); ``None`` when pyarrow is missing or
    the file has anything it would not read as exactly ``ncol`` numbers per row (the numpy
    path then reads it or names the bad row)."""
    try:
        import pyarrow as pa
        import pyarrow.csv as pacsv
    except ImportError:
        return None
    try:
        table = pacsv.read_csv(
            path,
            read_options=pacsv.ReadOptions(column_names=names, skip_rows=1),
            parse_options=pacsv.ParseOptions(newlines_in_values=False),
            convert_options=pacsv.ConvertOptions(
                column_types={n: pa.float64() for n in names},
                strings_can_be_null=False,
                null_values=[],
                quoted_strings_can_be_null=False,
            ),
        )
    except (pa.ArrowInvalid, pa.ArrowTypeError, OSError, ValueError):
        return None
    if table.num_columns != len(names) or any(c.null_count for c in table.columns):
        return None
    out = np.empty((table.num_rows, len(names)))
    for j, col in enumerate(table.columns):
        out[:, j] = col.to_numpy()
    return out


def _parse_fast(body: bytes, ncol: int) -> np.ndarray | None:
    """The rows as a (K, ncol) array, parsed in C (numpy's text ``fromstring``) after a
    vectorised check that every line has ``ncol`` fields; ``None`` when anything is off
    (the slow path then names the bad row). Several times faster than ``np.loadtxt``."""
    raw = np.frombuffer(body, dtype=np.uint8)
    if raw.size and raw[-1] != 0x0A:
        raw = np.concatenate([raw, np.array([0x0A], dtype=np.uint8)])
    ends = np.flatnonzero(raw == 0x0A)
    starts = np.concatenate(([0], ends[:-1] + 1))
    rows = ends > starts
    if not rows.all():  # blank lines: numpy's reader skips them
        return None
    # every line has ncol - 1 commas: as many in all, and the j-th group of them inside line j
    commas = np.flatnonzero(raw == 0x2C)
    k = ends.size
    if commas.size != k * (ncol - 1):
        return None
    if ncol > 1:
        groups = commas.reshape(k, ncol - 1)
        if not ((groups[:, 0] > starts).all() and (groups[:, -1] < ends).all()):
            return None
    del commas
    text = raw.tobytes().replace(b"\n", b",")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a field fromstring cannot read must not be dropped
        try:
            flat = np.fromstring(text, dtype=float, sep=",")
        except (ValueError, DeprecationWarning):
            return None
    if flat.size != k * ncol:
        return None
    return flat.reshape(k, ncol)


def _parse_numbers(body: bytes, ncol: int, path: str) -> np.ndarray:
    """Rows of ``ncol`` comma-separated floats; errors name the file line."""
    if not body.strip():
        return np.empty((0, ncol))
    data = _parse_fast(body, ncol)
    if data is not None:
        return data
    try:  # blank lines and other oddities the fast path leaves to numpy's reader
        data = np.loadtxt(io.BytesIO(body), delimiter=",", dtype=float, ndmin=2)
    except ValueError:
        data = None
    if data is not None and data.shape[1] == ncol:
        return data
    # slow path only to find and report the first bad row
    for i, line in enumerate(body.split(b"\n"), start=2):
        text = line.decode("ascii", "replace").strip()
        if not text:
            continue
        fields = text.split(",")
        if len(fields) != ncol:
            raise PlanFileError(
                f"row has {len(fields)} fields, the header has {ncol}", SourceLocation(path, i, 1, text)
            )
        for j, f in enumerate(fields):
            try:
                float(f)
            except ValueError:
                col = len(",".join(fields[:j])) + (1 if j else 0) + 1
                raise PlanFileError("not a number", SourceLocation(path, i, col, f)) from None
    raise PlanFileError("cannot read plan CSV", SourceLocation(path))
