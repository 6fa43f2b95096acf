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
