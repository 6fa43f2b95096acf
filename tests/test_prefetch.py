"""``plan.prefetch.Prefetch``: the same items, in order, and the producer's exception at
the same point of the sequence."""

import threading
import time

import pytest

from cnc_interp.plan.prefetch import Prefetch


def test_prefetch_yields_the_items_in_order_from_another_thread():
    producers = set()

    def items():
        for i in range(100):
            producers.add(threading.current_thread().name)
            yield i

    assert list(Prefetch(items(), ahead=3, name="cnc-interp-test")) == list(range(100))
    assert producers == {"cnc-interp-test"}


def test_prefetch_raises_the_producers_exception_after_the_items_before_it():
    def items():
        yield 1
        yield 2
        raise ValueError("stuck at 3")

    got = []
    with pytest.raises(ValueError, match="stuck at 3"):
        for x in Prefetch(items()):
            got.append(x)
    assert got == [1, 2]


def test_closing_the_iteration_stops_the_producer():
    made = []

    def items():
        for i in range(10_000):
            made.append(i)
            yield i

    it = iter(Prefetch(items(), ahead=2))
    assert next(it) == 0
    it.close()
    time.sleep(0.3)  # the producer notices within its poll (0.1 s)
    count = len(made)
    time.sleep(0.3)
    assert len(made) == count < 100
