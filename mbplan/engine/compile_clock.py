"""Time spent compiling kernels, apart from the work they then do.

Two kinds of kernel are compiled at their first use in a process: numba functions (compiled, or
loaded from numba's disk cache, at their first call) and CasADi functions (built, compiled to C
and loaded, :mod:`mbplan.engine.jit`). A :class:`CompileClock` measures the seconds its thread
spends in either while it runs, so that a solve's time can leave them out (a solve's first run
in a fresh environment would otherwise report tens of seconds of compilation as solve time).

Both are seen as events of numba's event system (:mod:`numba.core.event`): numba's own
``numba:compiler_lock`` (held while numba compiles or loads a kernel; waiting for another
thread's compilation counts too) and :data:`COMPILE_EVENT`, which :func:`compiling` triggers.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

from numba.core import event

COMPILE_EVENT = "mbplan:compile"
"""The event of a CasADi kernel's construction, compilation or loading (:func:`compiling`)."""

_NUMBA_EVENT = "numba:compiler_lock"


@contextmanager
def compiling() -> Iterator[None]:
    """Marks the block as kernel compilation for the calling thread's running clocks
    (:class:`CompileClock`)."""
    with event.trigger_event(COMPILE_EVENT):
        yield


class CompileClock:
    """Wall time since :meth:`start` (or construction) split into compilation (``compile_s``,
    this thread's only) and the rest (:meth:`elapsed`). Counts while started; :meth:`stop`
    (or leaving the ``with`` block) stops it, after which both stay fixed."""

    def __init__(self) -> None:
        self._depth = 0
        self._since = 0.0
        self._t0 = time.perf_counter()
        self._t1: float | None = None
        self.compile_s = 0.0

    def start(self) -> CompileClock:
        """Reset both times to zero and start counting (in the calling thread)."""
        self._t0, self._t1, self.compile_s, self._depth = time.perf_counter(), None, 0.0, 0
        clocks = _running()
        if self not in clocks:
            clocks.append(self)
        return self

    def stop(self) -> None:
        """Stop counting; :meth:`elapsed` and ``compile_s`` stay as they are now (call it in the
        thread that started the clock)."""
        clocks = _running()
        if self in clocks:
            clocks.remove(self)
            self._t1 = time.perf_counter()

    def __enter__(self) -> CompileClock:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def wall(self) -> float:
        """Seconds since :meth:`start` (until :meth:`stop`), compilation included."""
        return (time.perf_counter() if self._t1 is None else self._t1) - self._t0

    def elapsed(self) -> float:
        """Seconds since :meth:`start` (until :meth:`stop`), compilation left out (a compilation
        under way counts up to now)."""
        running = time.perf_counter() - self._since if self._depth and self._t1 is None else 0.0
        return self.wall() - self.compile_s - running

    def _begin(self) -> None:
        if self._depth == 0:
            self._since = time.perf_counter()
        self._depth += 1

    def _end(self) -> None:
        if self._depth:
            self._depth -= 1
            if self._depth == 0:
                self.compile_s += time.perf_counter() - self._since


_threads = threading.local()


def _running() -> list[CompileClock]:
    """The clocks started in the calling thread."""
    clocks = getattr(_threads, "clocks", None)
    if clocks is None:
        clocks = _threads.clocks = []
    return clocks


class _Listener(event.Listener):
    """Tells the calling thread's running clocks that a compilation begins or ends (numba
    broadcasts an event in the thread that compiles)."""

    def on_start(self, ev: event.Event) -> None:
        for clock in getattr(_threads, "clocks", ()):
            clock._begin()

    def on_end(self, ev: event.Event) -> None:
        for clock in getattr(_threads, "clocks", ()):
            clock._end()


# process-wide, registered once: numba's list of listeners is never changed while a thread
# broadcasts; each thread's clocks are its own (thread-local)
for _kind in (_NUMBA_EVENT, COMPILE_EVENT):
    event.register(_kind, _Listener())
