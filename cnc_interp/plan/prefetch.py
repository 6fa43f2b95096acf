"""Run an iterable ahead of its consumer in a thread of its own (``Prefetch``).

Three users: the streamed pipeline fits the program while the timeline hands out samples,
and the optimal planner profiles a long path while it refines the stretch before or,
without refinement, solves a long path's profile windows while it samples the ones
before (the planners' compiled loops release the GIL, so both stages run at once). The items, their
order and where an exception is raised do not depend on the thread: the output is the
same bytes as without it.
"""

from __future__ import annotations

import queue
import threading

#: how often a blocked producer checks that the consumer still wants items, s
_POLL_S = 0.1


class Prefetch:
    """Iterates ``iterable`` in a thread of its own (named ``name``), ``ahead`` items
    ahead: the fit runs while the timeline hands out samples, and ``ready()`` tells the
    timeline whether the next item is there (so that it consumes planned samples instead
    of waiting). The thread's CPU time is ``cpu_s``; an exception is raised where the
    consumer reaches it. Closing the iteration (or an exception in the consumer) stops the
    thread at its next item; a daemon thread never keeps an interrupted process alive."""

    def __init__(self, iterable, ahead: int = 512, name: str = "cnc-interp-fit"):
        self.q: queue.Queue = queue.Queue(maxsize=max(1, ahead))
        self.cpu_s = 0.0
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, args=(iterable,), daemon=True, name=name)
        self.thread.start()

    def _put(self, value) -> bool:
        while not self.stop.is_set():
            try:
                self.q.put(value, timeout=_POLL_S)
                return True
            except queue.Full:
                continue
        return False

    def _run(self, iterable) -> None:
        import time

        t0 = time.thread_time()
        try:
            for item in iterable:
                if not self._put(("item", item)):
                    return
            self._put(("end", None))
        except BaseException as exc:
            self._put(("error", exc))
        finally:
            self.cpu_s = time.thread_time() - t0

    def ready(self) -> bool:
        return not self.q.empty()

    def __iter__(self):
        try:
            while True:
                kind, value = self.q.get()
                if kind == "end":
                    return
                if kind == "error":
                    raise value
                yield value
        finally:
            self.close()

    def close(self) -> None:
        self.stop.set()
