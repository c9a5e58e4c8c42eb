"""Results of deterministic per-process work kept on disk, so that a new process loads them.

A value is stored under its kind and the digest of its key (everything it is built from, as
for a :class:`~mbplan.workspace.Workspace` entry) and of :func:`code_version` (the package's
sources and the numerical libraries' versions: a changed build function is a new key), in
``<cache>/store/<kind>/<digest>.pkl`` beside the compiled kernels
(:func:`~mbplan.engine.jit.cache_dir`: ``$MBPLAN_CACHE_DIR``, default ``~/.cache/mbplan/jit``).
``MBPLAN_DISK_CACHE=off`` turns it off.

A loaded value equals the built one bit for bit, and so does everything computed from it:
arrays come back with their dtype, shape, memory order and write flag, two arrays on the same
memory stay one memory, and the caller's ``context`` object (its workspace) that a value holds
is the loading caller's. A value that pickling would not give back so (a view of part of
another array, a strided view, a ctypes pointer) is not stored. Entries are written to a
temporary file and renamed (:func:`os.replace`: a reader never sees a partial file); one that
cannot be read back (truncated, corrupt, another key's) is a miss: built and written again.
When the entries exceed :data:`MAX_BYTES`, the least recently used ones are removed. Entries
are pickles, as numba's cache is: the folder is the user's own.
"""

from __future__ import annotations

import hashlib
import io
import itertools
import os
import pickle
import sys
import threading
import time
from collections.abc import Callable, Hashable
from functools import cache
from importlib import metadata
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from mbplan.engine.jit import cache_dir

V = TypeVar("V")

MAX_BYTES = 512 * 1024**2
"""Size of the stored entries (all kinds) above which the least recently used are removed."""

MIN_BUILD_S = 0.005
"""A value built faster is not stored by :func:`cached` (reading it back would cost as much)."""

_MAGIC = b"mbplan-disk-cache-1\n"
_LIBRARIES = ("numpy", "scipy", "numba", "casadi", "pin", "pymetis", "qdldl", "coal")
_DIRECTORY = "store"
_OFF = ("off", "0", "false", "no")
_ABOVE = ("benchmarks", "cli", "taskfile", "tasks", "verification", "viz")
"""The package's layers that build no stored value (a value's inputs are in its key): their
edits keep the entries."""


class _Uncacheable(Exception):
    """A value that would not come back from the disk as it is."""


def enabled() -> bool:
    """False when ``MBPLAN_DISK_CACHE`` is ``off`` (or ``0``, ``false``, ``no``)."""
    return os.environ.get("MBPLAN_DISK_CACHE", "on").strip().lower() not in _OFF


def store_dir() -> Path:
    """Where the entries are kept (inside the JIT cache directory)."""
    return cache_dir() / _DIRECTORY


# process-wide cache, result-neutral: the sources and libraries of this process
@cache
def code_version() -> bytes:
    """A digest of the package's source files (path, size, modification time; but those of
    :data:`_ABOVE`), the Python version and the numerical libraries' versions: an entry is
    built by the code of its version only."""
    root = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256(sys.version.encode())
    for name in _LIBRARIES:
        try:
            digest.update(f"{name}={metadata.version(name)}".encode())
        except metadata.PackageNotFoundError:
            digest.update(f"{name}=-".encode())
    for path in sorted(root.rglob("*.py")):
        if path.relative_to(root).parts[0] in _ABOVE:
            continue
        st = path.stat()
        digest.update(f"{path.relative_to(root)}:{st.st_size}:{st.st_mtime_ns}\0".encode())
    return digest.digest()


def digest_of(kind: str, key: Hashable) -> str:
    """The file name (without suffix) of ``kind``'s entry for ``key``."""
    digest = hashlib.sha256(code_version() + kind.encode() + b"\0")
    digest.update(pickle.dumps(key, protocol=4))
    return digest.hexdigest()[:40]


def cached(
    kind: str, key: Callable[[], Hashable], build: Callable[[], V], context: Any = None
) -> V:
    """The entry of ``kind`` and ``key()`` from the disk, or ``build()``, written there if it
    took :data:`MIN_BUILD_S` or more. ``context``: an object that ``build`` may keep in the
    value (e.g. the caller's workspace), stored as a reference: a loaded value holds the
    loading call's ``context`` instead."""
    if not enabled():
        return build()
    k = key()
    found = lookup(kind, k, context)
    if found is not MISSING:
        return found
    start = time.perf_counter()
    value = build()
    if time.perf_counter() - start >= MIN_BUILD_S:
        store(kind, k, value, context)
    return value


MISSING: Any = object()
"""What :func:`lookup` returns for an entry it does not have."""


def _path(kind: str, key: Hashable) -> tuple[Path, str] | None:
    """Where the entry of ``kind`` and ``key`` is kept (None: a key that cannot be pickled)."""
    try:
        name = digest_of(kind, key)
    except Exception:  # an unpicklable key: never stored
        return None
    return store_dir() / kind / f"{name}.pkl", name


def lookup(kind: str, key: Hashable, context: Any = None) -> Any:
    """The stored entry of ``kind`` and ``key`` (with ``context``: :func:`cached`), or
    :data:`MISSING` (none, or the cache is off)."""
    where = _path(kind, key) if enabled() else None
    return MISSING if where is None else load(*where, context)


def store(kind: str, key: Hashable, value: Any, context: Any = None) -> bool:
    """Store ``value`` as the entry of ``kind`` and ``key`` (:func:`save`)."""
    where = _path(kind, key) if enabled() else None
    return where is not None and save(*where, value, context)


def load(path: Path, name: str, context: Any = None) -> Any:
    """The value stored at ``path`` under ``name`` (with ``context`` for the stored one), or
    ``MISSING`` (no file, or one that is not such an entry: truncated, corrupt, another
    key's)."""
    try:
        data = path.read_bytes()
    except OSError:
        return MISSING
    head = _MAGIC + name.encode() + b"\n"
    if not data.startswith(head):
        return MISSING
    try:
        unpickler = _Unpickler(io.BytesIO(data[len(head) :]), context)
        value = unpickler.load()
        for array in unpickler.load():  # then the arrays that were read-only
            array.flags.writeable = False
    except Exception:  # any damage: a miss, built and written again
        return MISSING
    try:
        os.utime(path)  # recently used (eviction)
    except OSError:
        pass
    return value


def save(path: Path, name: str, value: Any, context: Any = None) -> bool:
    """Write ``value`` at ``path`` (atomically; ``context`` as a reference); False if it cannot
    come back as it is or the disk refuses it (the caller has the value anyway)."""
    buffer = io.BytesIO()
    buffer.write(_MAGIC + name.encode() + b"\n")
    try:
        pickler = _Pickler(buffer, context)
        pickler.dump(value)
        pickler.check_aliasing()
        pickler.dump(pickler.read_only)  # references to arrays of the value (pickled once)
    except Exception:  # _Uncacheable, or not picklable at all
        return False
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_bytes(buffer.getbuffer())
        os.replace(tmp, path)
    except OSError:
        return False
    finally:
        tmp.unlink(missing_ok=True)
    _evict(path.parent.parent, MAX_BYTES)
    return True


def _evict(root: Path, limit: int) -> None:
    """Remove the least recently used entries under ``root`` until they fit in ``limit``."""
    try:
        entries = [(p.stat(), p) for p in root.glob("*/*.pkl")]
    except OSError:
        return
    total = sum(st.st_size for st, _ in entries)
    for st, p in sorted(entries, key=lambda e: e[0].st_mtime_ns):
        if total <= limit:
            break
        p.unlink(missing_ok=True)
        total -= st.st_size


_CONTEXT = "context"


class _Pickler(pickle.Pickler):
    """Pickles arrays as they are (:func:`_array`) and the context as a reference."""

    def __init__(self, file: io.BytesIO, context: Any) -> None:
        super().__init__(file, protocol=4)
        self._context = context
        self._views: dict[tuple, np.ndarray] = {}
        self.read_only: list[np.ndarray] = []

    def persistent_id(self, obj: Any) -> str | None:
        return _CONTEXT if obj is self._context and obj is not None else None

    def reducer_override(self, obj: Any) -> Any:
        if type(obj) is not np.ndarray:
            return NotImplemented
        if obj.dtype.hasobject:
            raise _Uncacheable("an object array")
        if not (obj.flags.c_contiguous or obj.flags.f_contiguous):
            raise _Uncacheable("a strided view")
        if not obj.flags.writeable:
            self.read_only.append(obj)  # made read-only once every view of it exists
        where = (obj.__array_interface__["data"][0], obj.shape, obj.strides, obj.dtype.str)
        first = self._views.setdefault(where, obj) if obj.size else obj
        if first is not obj:  # another array on the same memory: a view of the first one
            return np.ndarray.view, (first,)
        fortran = obj.flags.f_contiguous and not obj.flags.c_contiguous
        return _array, (obj.tobytes(order="A"), obj.dtype.str, obj.shape, fortran)

    def check_aliasing(self) -> None:
        """Raise :class:`_Uncacheable` if two pickled arrays share part of their memory (they
        would come back as two memories)."""
        spans = sorted(
            (start, start + a.nbytes) for (start, *_), a in self._views.items() if a.nbytes
        )
        for (_, end), (start, _) in itertools.pairwise(spans):
            if start < end:
                raise _Uncacheable("arrays that share part of their memory")


class _Unpickler(pickle.Unpickler):
    def __init__(self, file: io.BytesIO, context: Any) -> None:
        super().__init__(file)
        self._context = context

    def persistent_load(self, pid: Any) -> Any:
        if pid != _CONTEXT:
            raise pickle.UnpicklingError(f"unknown reference {pid!r}")
        return self._context


def _array(data: bytes, dtype: str, shape: tuple, fortran: bool) -> np.ndarray:
    """An array of its own (NumPy's allocation, as a built one) holding ``data``."""
    out = np.empty(shape, np.dtype(dtype), order="F" if fortran else "C")
    out.reshape(-1, order="A")[...] = np.frombuffer(data, np.dtype(dtype))
    return out
