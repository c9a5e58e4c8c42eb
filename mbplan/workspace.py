"""What the solves of one problem family share, in an object the caller owns.

A :class:`Workspace` keeps what building and solving a problem derives from its structure
(variable layouts, term structures, sparse patterns, elimination plans, KKT patterns, symbolic
analyses) and the joint reductions, keyed by everything each one is built from: an entry is a
function of its key alone, so a solve gives the same result with a fresh workspace, a reused
one or none, and only the time to build differs. Pass the same workspace to the solves of one
family (every case of a benchmark, every solve of a receding-horizon loop) to build each entry
once; without one, a solve builds what it needs for itself. The costly kinds are also kept on
disk (:func:`shared`'s ``disk``), so that a new process loads them."""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any, TypeVar

from mbplan.engine.disk_cache import cached

V = TypeVar("V")


class Workspace:
    """Entries by kind (e.g. ``"kkt_pattern"``) and key; of each kind the ``kept`` used last
    (an entry dropped is built again when needed: the same value). Thread-safe."""

    def __init__(self, kept: int = 8) -> None:
        self.kept = kept
        self._entries: dict[str, OrderedDict[Hashable, Any]] = {}
        self._lock = threading.Lock()

    def __getstate__(self) -> dict[str, Any]:
        """A workspace sent to another process (a benchmark job) arrives empty: its entries are
        rebuilt there, with the same values."""
        return {"kept": self.kept}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["kept"])

    def count(self, kind: str) -> int:
        """Entries of ``kind`` kept."""
        return len(self._entries.get(kind, ()))

    def get_or_build(self, kind: str, key: Hashable, build: Callable[[], V]) -> V:
        """The entry of ``kind`` and ``key``, built by ``build()`` (outside the lock) if it is not
        kept; of two threads that build one key at once, both get the value stored first."""
        hash(key)  # outside the lock: bytes in the key cache their hash
        with self._lock:
            entries = self._entries.setdefault(kind, OrderedDict())
            if key in entries:
                entries.move_to_end(key)
                return entries[key]
        value = build()
        with self._lock:
            value = entries.setdefault(key, value)
            entries.move_to_end(key)
            while len(entries) > self.kept:
                entries.popitem(last=False)
        return value


def shared(
    workspace: Workspace | None,
    kind: str,
    key: Callable[[], Hashable],
    build: Callable[[], V],
    *,
    disk: bool = False,
) -> V:
    """``build()``, kept in ``workspace`` under ``key()`` (``None``: built for this call);
    ``disk``: also kept on disk (:mod:`mbplan.engine.disk_cache`), loaded instead of built by
    a new process (a value whose arrays or workspace would not come back as they are is not
    stored: it is built)."""
    if workspace is None and not disk:
        return build()
    k = key()
    make = build
    if disk:
        make = lambda: cached(kind, lambda: k, build, workspace)  # noqa: E731
    return make() if workspace is None else workspace.get_or_build(kind, k, make)
