"""A small progress bar on standard error for long work.

Usage::

    with progress(total, "plan", enabled=not quiet) as tick:
        for chunk in work:
            ...
            tick(len(chunk))

When the total of what is counted is not known up front (the path length of a streamed
plan) but another measure of the way through is (the program's line count),
``measure(total, unit)`` and ``reach(position)`` give the percentage and ETA from it,
while the count still shows what ``tick`` counts.

The bar is drawn only when it helps a person watching: ``enabled`` is true, the
stream is a terminal, and the work has already run for ``PROGRESS_DELAY_S``.
Otherwise ``tick`` only counts, so pipelines and logs see nothing. The line is
erased when the work ends, leaving standard error as it was for the summary.
(tqdm would do the same; it is not worth a dependency for one line of output.)
"""

from __future__ import annotations

import shutil
import sys
import time
from contextlib import contextmanager
from typing import Callable, Iterator, TextIO


#: a progress bar appears only once the work has run this long (s)
PROGRESS_DELAY_S = 1.0

#: least time between two redraws of the progress bar (s)
PROGRESS_REFRESH_S = 0.1

#: widest progress line drawn, characters
PROGRESS_MAX_WIDTH = 80


class ProgressBar:
    """Counts work done and redraws a one-line bar at most every ``refresh_s``.

    ``total`` may be ``None`` (unknown): the bar then shows the count only. ``unit``
    names what is counted (``"samples"``, ``"paths"``). ``clock`` is injectable for tests
    (seconds, monotonic).
    """

    def __init__(
        self,
        total: int | float | None,
        label: str = "",
        enabled: bool = True,
        stream: TextIO | None = None,
        unit: str = "",
        delay_s: float = PROGRESS_DELAY_S,
        refresh_s: float = PROGRESS_REFRESH_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.total = total if total is None or total > 0 else None
        self.label = label
        self.unit = f" {unit}" if unit else ""
        self.stream = stream if stream is not None else sys.stderr
        self.delay_s = delay_s
        self.refresh_s = refresh_s
        self.clock = clock
        self.done = 0
        self.reach_total: float | None = None  # the other measure of the way through
        self.reach_unit = ""
        self.reached = 0.0
        self.drawn = False
        self._start = clock()
        self._last_draw = -float("inf")
        self.active = bool(enabled) and _is_tty(self.stream)

    def __call__(self, n: int | float = 1) -> None:
        """Record ``n`` more units of work; redraw if it is time to."""
        self.done += n
        if not self.active:
            return
        now = self.clock()
        if now - self._start < self.delay_s or now - self._last_draw < self.refresh_s:
            return
        self._last_draw = now
        self._draw(now)

    def measure(self, total: float, unit: str) -> None:
        """Take the percentage and ETA from positions ``reach``ed out of ``total``
        (``unit``: what a position counts, e.g. ``"line"``) while the total of what
        ``tick`` counts is unknown; a ``total`` <= 0 is ignored."""
        if total > 0:
            self.reach_total = float(total)
            self.reach_unit = unit

    def reach(self, position: float) -> None:
        """The work has reached ``position`` (of ``measure``'s total; the furthest counts)."""
        self.reached = max(self.reached, float(position))

    def line(self, now: float | None = None) -> str:
        """The text of the bar as it would be drawn now (without ``\\r``)."""
        now = self.clock() if now is None else now
        elapsed = max(now - self._start, 0.0)
        width = min(_terminal_width(), PROGRESS_MAX_WIDTH) - 1
        if self.total is not None:
            frac = self.done / self.total
            count = f"{_count(self.done)}/{_count(self.total)}{self.unit}"
        elif self.reach_total is not None:
            frac = self.reached / self.reach_total
            where = f"{self.reach_unit} {_count(self.reached)}/{_count(self.reach_total)}"
            count = f"{where}, {_count(self.done)}{self.unit or ' done'}"
        else:
            frac = None
            count = f"{_count(self.done)}{self.unit or ' done'}"
        return progress_line(self.label, count, elapsed, frac, width)

    def _draw(self, now: float) -> None:
        text = self.line(now)
        self._write("\r" + text + "\x1b[K")
        self.drawn = True

    def close(self) -> None:
        """Erase the bar if it was drawn."""
        if self.drawn:
            self._write("\r\x1b[K")
            self.drawn = False

    def _write(self, text: str) -> None:
        try:
            self.stream.write(text)
            self.stream.flush()
        except (OSError, ValueError):  # stderr closed: progress is never worth failing for
            self.active = False


@contextmanager
def progress(
    total: int | float | None,
    label: str = "",
    enabled: bool = True,
    stream: TextIO | None = None,
    unit: str = "",
    **kwargs,
) -> Iterator[ProgressBar]:
    """Context manager yielding a ``tick(n)`` callable (a ``ProgressBar``); see module doc."""
    bar = ProgressBar(total, label, enabled=enabled, stream=stream, unit=unit, **kwargs)
    try:
        yield bar
    finally:
        bar.close()


def progress_line(label: str, count: str, elapsed_s: float, frac: float | None, width: int) -> str:
    """One progress line: ``label``, then, with the share done ``frac`` known, a bar,
    the percentage, ``count`` and the ETA (elapsed time × what is left / what is done),
    fitted into ``width`` characters; with ``frac`` unknown (``None``), ``count`` and
    the elapsed time."""
    head = f"{label} " if label else ""
    if frac is None:
        return f"{head}{count}, {_duration(elapsed_s)}"
    frac = min(max(frac, 0.0), 1.0)
    eta = elapsed_s * (1.0 - frac) / frac if frac > 0 else float("nan")
    eta_txt = f"ETA {_duration(eta)}" if eta == eta else "ETA ?"
    tail = f" {frac * 100:3.0f}% {count} {eta_txt}"
    bar_w = max(width - len(head) - len(tail) - 2, 5)
    filled = int(round(frac * bar_w))
    return f"{head}[{'#' * filled}{'.' * (bar_w - filled)}]{tail}"


def _is_tty(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False


def _terminal_width() -> int:
    return shutil.get_terminal_size((PROGRESS_MAX_WIDTH, 24)).columns


def _count(n: float) -> str:
    n = float(n)
    for unit, scale in (("G", 1e9), ("M", 1e6), ("k", 1e3)):
        if abs(n) >= scale:
            return f"{n / scale:.1f}{unit}"
    return f"{n:.0f}"


def _duration(seconds: float) -> str:
    seconds = max(seconds, 0.0)
    if seconds < 60:
        return f"{seconds:.0f}s"
    minutes, sec = divmod(int(round(seconds)), 60)
    if minutes < 60:
        return f"{minutes}m{sec:02d}s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours}h{minutes:02d}m"
