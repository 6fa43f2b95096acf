"""The progress bar: only on a terminal, only for long work, erased at the end."""

from __future__ import annotations

import io

import pytest

from cnc_interp.export.progress import ProgressBar, progress


class FakeTTY(io.StringIO):
    def isatty(self):
        return True


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_silent_when_not_a_terminal():
    stream = io.StringIO()
    clock = Clock()
    with progress(1000, "plan", stream=stream, clock=clock) as tick:
        for _ in range(10):
            clock.now += 1.0
            tick(100)
    assert stream.getvalue() == ""
    assert tick.done == 1000


def test_silent_when_disabled_or_short():
    stream, clock = FakeTTY(), Clock()
    with progress(10, "x", enabled=False, stream=stream, clock=clock) as tick:
        clock.now += 5.0
        tick(10)
    assert stream.getvalue() == ""
    with progress(10, "x", stream=stream, clock=clock) as tick:
        clock.now += 0.5  # finished before the delay: never drawn
        tick(10)
    assert stream.getvalue() == ""


def test_drawn_after_delay_and_erased():
    stream, clock = FakeTTY(), Clock()
    with progress(1000, "plan", stream=stream, clock=clock) as tick:
        tick(100)
        assert stream.getvalue() == ""
        clock.now += 2.0
        tick(400)
        text = stream.getvalue()
        assert text.startswith("\r") and "plan [" in text and " 50%" in text
        assert "500/1.0k" in text and "ETA 2s" in text
        clock.now += 0.01  # within the refresh interval: no redraw
        tick(1)
        assert stream.getvalue() == text
    assert stream.getvalue().endswith("\r\x1b[K")  # erased on exit


def test_unknown_total_and_large_counts():
    bar = ProgressBar(None, "read", stream=FakeTTY(), clock=Clock())
    bar(2_500_000)
    assert bar.line().startswith("read 2.5M done")
    bar = ProgressBar(3_000_000, "", stream=FakeTTY(), clock=Clock(), unit="samples")
    bar(1_500_000)
    assert "1.5M/3.0M samples" in bar.line()
    bar = ProgressBar(None, "plan", stream=FakeTTY(), clock=Clock(), unit="paths")
    bar(25)
    assert bar.line() == "plan 25 paths, 0s"


def test_erased_on_exception():
    stream, clock = FakeTTY(), Clock()
    with pytest.raises(KeyboardInterrupt):
        with progress(10, "x", stream=stream, clock=clock) as tick:
            clock.now += 3
            tick(1)
            raise KeyboardInterrupt
    assert stream.getvalue().endswith("\r\x1b[K")


def test_closed_stream_never_fails():
    stream, clock = FakeTTY(), Clock()
    bar = ProgressBar(10, "x", stream=stream, clock=clock)
    stream.close()
    clock.now += 3
    bar(5)  # ValueError from the closed stream is swallowed
    assert not bar.active


def test_progress_line_format():
    from cnc_interp.export.progress import progress_line

    line = progress_line("plan", "line 250/1.0k, 35 mm", 10.0, 0.25, 79)
    assert line.startswith("plan [") and len(line) == 79
    assert " 25% line 250/1.0k, 35 mm ETA 30s" in line  # 10 s for a quarter: 30 s to go
    bar = line[line.index("[") + 1 : line.index("]")]
    assert bar.count("#") == round(0.25 * len(bar))
    # nothing done yet: no ETA; over 100 %: clipped, nothing left
    assert line_end(progress_line("", "x", 5.0, 0.0, 60)) == "  0% x ETA ?"
    assert line_end(progress_line("", "x", 5.0, 1.2, 60)) == "100% x ETA 0s"
    assert progress_line("p", "x", 3725.0, 0.5, 60).endswith("ETA 1h02m")
    # share unknown: the count and the elapsed time, no bar
    assert progress_line("plan", "35.0 mm", 65.0, None, 79) == "plan 35.0 mm, 1m05s"
    # a narrow terminal still gets a bar of 5
    assert "[....." in progress_line("a long label", "line 1/1.0k", 1.0, 0.001, 20)


def line_end(line: str) -> str:
    return line[line.index("]") + 2 :]


def test_share_measured_by_source_line():
    """A streamed plan's total path length is unknown: the program's line count gives the
    percentage and ETA, the count still shows the mm planned."""
    stream, clock = FakeTTY(), Clock()
    with progress(None, "plan", stream=stream, clock=clock, unit="mm") as tick:
        tick.measure(1000, "line")
        tick(350.0)
        tick.reach(250)
        tick.reach(100)  # a subroutine called from an earlier line: the furthest counts
        clock.now += 10.0
        tick(1.0)
        text = stream.getvalue()
    assert " 25% line 250/1.0k, 351 mm ETA 30s" in text
    bar = ProgressBar(None, "plan", stream=FakeTTY(), clock=Clock(), unit="mm")
    bar.measure(0, "line")  # an empty program: today's display
    bar(12)
    assert bar.line() == "plan 12 mm, 0s"
