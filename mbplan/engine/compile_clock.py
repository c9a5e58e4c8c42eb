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
    """Marks the block as kernel compilation for every running :class:`CompileClock`."""
    with event.trigger_event(COMPILE_EVENT):
        yield


class CompileClock(event.Listener):
    """Wall time since :meth:`start` (or construction) split into compilation (``compile_s``,
    this thread's only) and the rest (:meth:`elapsed`). Listens while started; :meth:`stop`
    (or leaving the ``with`` block) stops listening, after which both stay fixed."""

    def __init__(self) -> None:
        self._thread = threading.get_ident()
        self._depth = 0
        self._since = 0.0
        self._t0 = time.perf_counter()
        self._t1: float | None = None
        self.compile_s = 0.0
        self._listening = False

    def start(self) -> CompileClock:
        """Reset both times to zero and start listening."""
        self._t0, self._t1, self.compile_s, self._depth = time.perf_counter(), None, 0.0, 0
        if not self._listening:
            for kind in (_NUMBA_EVENT, COMPILE_EVENT):
                event.register(kind, self)
            self._listening = True
        return self

    def stop(self) -> None:
        """Stop listening; :meth:`elapsed` and ``compile_s`` stay as they are now."""
        if self._listening:
            for kind in (_NUMBA_EVENT, COMPILE_EVENT):
                event.unregister(kind, self)
            self._listening = False
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

    def on_start(self, ev: event.Event) -> None:
        if threading.get_ident() == self._thread:
            if self._depth == 0:
                self._since = time.perf_counter()
            self._depth += 1

    def on_end(self, ev: event.Event) -> None:
        if threading.get_ident() == self._thread and self._depth:
            self._depth -= 1
            if self._depth == 0:
                self.compile_s += time.perf_counter() - self._since
