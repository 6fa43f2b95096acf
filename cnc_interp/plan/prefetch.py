"""Run a generator ahead in its own thread: two pipeline stages on two cores.

``ahead(items, depth)`` yields exactly what ``items`` yields, in order, and raises what it
raises, at the same point of the sequence; a worker thread computes up to ``depth`` items
before the consumer asks for them. The planners' stages are compiled loops that release
the GIL, so a producing stage (the optimal planner's feed profile and sampler) and a
consuming one (its window refinement) then run at once. The items do not depend on the
timing: the output is the same bytes as without the thread.
"""

from __future__ import annotations

import queue
import threading
from typing import Iterator, TypeVar

T = TypeVar("T")

#: how often a blocked producer checks that the consumer still wants items, s
_POLL_S = 0.1

_END = object()


class _Raised:
    """An exception raised by the producer, handed over to be raised by the consumer."""

    __slots__ = ("exc",)

    def __init__(self, exc: BaseException):
        self.exc = exc


def ahead(items: Iterator[T], depth: int = 8) -> Iterator[T]:
    """``items``, computed by a daemon thread up to ``depth`` items ahead of the caller.

    Closing the returned generator (or an exception in the caller) stops the producer at
    its next item; a daemon thread never keeps an interrupted process alive.
    """
    out: queue.Queue = queue.Queue(maxsize=max(1, depth))
    stop = threading.Event()

    def put(value) -> bool:
        while not stop.is_set():
            try:
                out.put(value, timeout=_POLL_S)
                return True
            except queue.Full:
                continue
        return False

    def produce() -> None:
        try:
            for item in items:
                if not put(item):
                    return
            put(_END)
        except BaseException as exc:  # raised again by the consumer, where it belongs
            put(_Raised(exc))

    worker = threading.Thread(target=produce, daemon=True, name="cnc-interp-ahead")
    worker.start()
    try:
        while True:
            got = out.get()
            if got is _END:
                return
            if isinstance(got, _Raised):
                raise got.exc
            yield got
    finally:
        stop.set()
