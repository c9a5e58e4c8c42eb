"""A per-process memo of the values built for the last few keys (thread-safe): what every
problem of a task family builds alike (patterns, analyses, plans, reduction choices) is built
once."""

from __future__ import annotations

import threading
import weakref
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

V = TypeVar("V")


class RecentMemo(Generic[V]):
    """The values of the ``kept`` keys used last; the least recently used is dropped first."""

    def __init__(self, kept: int) -> None:
        self.kept = kept
        self._values: OrderedDict[Hashable, V] = OrderedDict()
        self._lock = threading.Lock()
        with _MEMOS_LOCK:
            _MEMOS.add(self)

    def __len__(self) -> int:
        return len(self._values)

    def get(self, key: Hashable) -> V | None:
        """The value of ``key`` (now the most recent), or ``None``."""
        hash(key)  # outside the lock: bytes in the key cache their hash
        with self._lock:
            hit = self._values.get(key)
            if hit is not None:
                self._values.move_to_end(key)
            return hit

    def put(self, key: Hashable, value: V, replace: bool = True) -> V:
        """Keep ``value`` for ``key`` and return it; ``replace=False``: a value already kept for
        ``key`` stays and is returned instead."""
        return self.update(key, lambda kept: value if replace or kept is None else kept)

    def update(self, key: Hashable, change: Callable[[V | None], V]) -> V:
        """Keep ``change(value of key or None)`` for ``key`` (read and write under the memo's
        lock: ``change`` must be quick and must not use this memo); returns it."""
        hash(key)  # outside the lock, as in get
        with self._lock:
            value = change(self._values.get(key))
            self._values[key] = value
            self._values.move_to_end(key)
            while len(self._values) > self.kept:
                self._values.popitem(last=False)
        return value

    def get_or_build(self, key: Hashable, build: Callable[[], V]) -> V:
        """The value of ``key``, built by ``build()`` (outside the lock) if it is not kept; of
        two threads that build the same key at once, both get the value stored first."""
        hit = self.get(key)
        if hit is not None:
            return hit
        return self.put(key, build(), replace=False)

    def clear(self) -> None:
        with self._lock:
            self._values.clear()


_MEMOS: weakref.WeakSet[RecentMemo] = weakref.WeakSet()
_MEMOS_LOCK = threading.Lock()


def clear_all() -> None:
    """Empty every :class:`RecentMemo` of the process: the next solve builds (and picks, e.g. the
    joint reduction's pivots on its own first matrix) as in a fresh process, so that it does not
    depend on the problems solved before it (at the cost of the symbolic phases again; while no
    other thread is solving)."""
    with _MEMOS_LOCK:
        memos = list(_MEMOS)
    for memo in memos:
        memo.clear()
