"""Compile CasADi Functions to C with the system compiler, cached on disk by content hash.

A second run with the same Function (same expression graph, compiler, flags and site-loop
generator) loads the shared object from the cache instead of recompiling. The cache
directory is ``$MBPLAN_CACHE_DIR`` or ``~/.cache/mbplan/jit``. Every shared object also holds
``<name>_sites``, the function evaluated at ``K`` sites in one C call (:class:`SiteLoop`;
its source: :mod:`mbplan.engine.site_loop_source`).
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import threading
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import casadi as cs
import numba as nb
import numpy as np
from numba.core import event

from mbplan.engine.compile_clock import compiling
from mbplan.engine.site_loop_source import COMPILE_FLAGS, GENERATOR_KEY, site_loop_source
from mbplan.errors import InputError, MbplanError

DEFAULT_FLAGS = ("-O2", "-fPIC", "-shared", "-march=native", *COMPILE_FLAGS)


def cache_dir() -> Path:
    root = os.environ.get("MBPLAN_CACHE_DIR")
    path = Path(root) if root else Path.home() / ".cache" / "mbplan" / "jit"
    path.mkdir(parents=True, exist_ok=True)
    return path


def compiler() -> str:
    cc = os.environ.get("CC", "gcc")
    if shutil.which(cc) is None:
        raise MbplanError(f"JIT compilation needs a C compiler; '{cc}' was not found (set CC)")
    return cc


class SiteLoop:
    """A compiled function evaluated at ``K`` sites by one C call: each input and output is a
    C-ordered float ``(K, nnz)`` array, row ``k`` the site's argument or result."""

    def __init__(self, fn: cs.Function, path: Path) -> None:
        self.name = fn.name()
        self._nnz_in = [fn.nnz_in(i) for i in range(fn.n_in())]
        self._nnz_out = [fn.nnz_out(i) for i in range(fn.n_out())]
        self.c_loop = ctypes.CDLL(str(path))[f"{self.name}_sites"]
        self.c_loop.argtypes = [ctypes.c_longlong, ctypes.c_void_p, ctypes.c_void_p]
        self.c_loop.restype = ctypes.c_int
        self.entry_point = int(ctypes.cast(self.c_loop, ctypes.c_void_p).value or 0)

    def bind(self, inputs: Sequence[np.ndarray], outputs: Sequence[np.ndarray]) -> BoundLoop:
        """The evaluation at the sites of these arrays, bound to their memory: every call reads
        the inputs' current values and overwrites the outputs."""
        K = check_site_arrays(self.name, inputs, outputs, self._nnz_in, self._nnz_out)
        return BoundLoop(self, K, inputs, outputs)

    def evaluate(self, inputs: Sequence[np.ndarray]) -> list[np.ndarray]:
        """The outputs, new ``(K, nnz)`` arrays, at the sites of ``inputs``."""
        K = inputs[0].shape[0] if inputs else 0
        outputs = [np.empty((K, width)) for width in self._nnz_out]
        self.bind(inputs, outputs)()
        return outputs


def check_site_arrays(
    name: str,
    inputs: Sequence[np.ndarray],
    outputs: Sequence[np.ndarray],
    in_widths: Sequence[int],
    out_widths: Sequence[int],
) -> int:
    """The number of sites ``K`` of arrays to bind a site function's evaluation to; an
    :class:`InputError` naming ``name`` unless every array is a C-ordered float array of shape
    ``(K, width)`` and every output is writeable."""
    K = inputs[0].shape[0] if inputs else 0
    for what, arrays, widths in (("input", inputs, in_widths), ("output", outputs, out_widths)):
        if len(arrays) != len(widths):
            raise InputError(f"{name}: {len(widths)} {what}s expected, got {len(arrays)}")
        for a, width in zip(arrays, widths, strict=True):
            if a.dtype != np.float64 or a.shape != (K, width) or not a.flags.c_contiguous:
                raise InputError(
                    f"{name}: {what} must be a C-ordered float array of shape "
                    f"{(K, width)}, got {a.dtype} {a.shape}"
                )
            if what == "output" and not a.flags.writeable:
                raise InputError(f"{name}: output arrays must be writeable")
    return K


class BoundLoop:
    """:meth:`SiteLoop.bind`'s call; holds the arrays whose memory it reads and writes and the
    array of their addresses that the loop reads (inputs, then outputs)."""

    __slots__ = ("_args", "_keep", "_loop", "_pointers", "_res", "_sites")

    def __init__(
        self, loop: SiteLoop, K: int, inputs: Sequence[np.ndarray], outputs: Sequence[np.ndarray]
    ) -> None:
        self._loop, self._sites = loop, K
        self._keep = (tuple(inputs), tuple(outputs))
        arg = [data_address(a) for a in inputs] or [0]
        res = [data_address(o) for o in outputs] or [0]
        self._pointers = np.array(arg + res, np.uintp)
        self._args = data_address(self._pointers)
        self._res = self._args + len(arg) * self._pointers.itemsize

    def __call__(self) -> None:
        if self._loop.c_loop(self._sites, self._args, self._res):
            raise self.failure()

    def failure(self) -> MbplanError:
        """The error of a call whose loop reported a failure."""
        return MbplanError(f"{self._loop.name}: compiled evaluation failed")

    def table_row(self) -> tuple[int, int, int, int]:
        """``(entry point, sites, argument pointers, result pointers)`` as addresses: how a
        compiled caller makes this call (:mod:`mbplan.engine.site_table`); valid while this
        object lives."""
        return (self._loop.entry_point, self._sites, self._args, self._res)


@nb.njit(cache=True)
def data_address(a: np.ndarray) -> int:  # pragma: no cover - compiled
    """The address of ``a``'s first element (``a.ctypes.data`` without its ctypes object)."""
    return a.ctypes.data


def compile_function(fn: cs.Function, flags: tuple[str, ...] = DEFAULT_FLAGS) -> cs.Function:
    """Return ``fn`` compiled to native code (loaded with ``casadi.external``)."""
    return compile_functions({"fn": fn}, flags)["fn"]


def compile_functions(
    fns: Mapping[str, cs.Function], flags: tuple[str, ...] = DEFAULT_FLAGS
) -> dict[str, cs.Function]:
    """:func:`compile_function` of each value; the C compilers of uncached ones run in parallel."""
    with compiling():
        paths = _compiled(fns, flags)
        return {k: cs.external(fn.name(), str(paths[k])) for k, fn in fns.items()}


def compile_site_loops(
    fns: Mapping[str, cs.Function], flags: tuple[str, ...] = DEFAULT_FLAGS
) -> dict[str, tuple[cs.Function, SiteLoop]]:
    """Each value compiled, as :func:`compile_functions` gives it and as a :class:`SiteLoop`."""
    paths = library_paths(fns, flags)
    return load_site_loops({k: (fn.name(), paths[k]) for k, fn in fns.items()})


def library_paths(
    fns: Mapping[str, cs.Function], flags: tuple[str, ...] = DEFAULT_FLAGS
) -> dict[str, Path]:
    """The shared object of each value in the cache, compiled if missing."""
    with compiling():
        return _compiled(fns, flags)


def load_site_loops(
    libraries: Mapping[str, tuple[str, Path]],
) -> dict[str, tuple[cs.Function, SiteLoop]]:
    """The compiled function ``name`` of each value's shared object ``path`` (as
    :func:`library_paths` gives it), as :func:`compile_functions` gives it and as a
    :class:`SiteLoop`."""
    out = {}
    with compiling():
        for key, (name, path) in libraries.items():
            fn = cs.external(name, str(path))
            out[key] = (fn, SiteLoop(fn, path))
    return out


def _compiled(fns: Mapping[str, cs.Function], flags: tuple[str, ...]) -> dict[str, Path]:
    """The cached shared object of each function, compiling the missing ones."""
    cc = compiler()
    targets = {}
    for key, fn in fns.items():
        digest = hashlib.sha256(
            "\0".join([fn.serialize(), cc, *flags, cs.__version__, GENERATOR_KEY]).encode()
        ).hexdigest()[:24]
        targets[key] = cache_dir() / f"{fn.name()}_{digest}.so"
    missing = [k for k in fns if not targets[k].exists()]
    if missing:
        _announce_compilation()
        with tempfile.TemporaryDirectory() as tmp:
            sources = {k: _generate(fns[k], Path(tmp)) for k in missing}  # CasADi: one thread
            with ThreadPoolExecutor(max_workers=min(len(missing), os.cpu_count() or 1)) as pool:
                list(pool.map(lambda k: _build(cc, flags, sources[k], targets[k]), missing))
    return targets


def _generate(fn: cs.Function, folder: Path) -> Path:
    src = folder / f"{fn.name()}.c"
    cg = cs.CodeGenerator(src.name, {"with_header": False})
    cg.add(fn)
    cg.generate(str(folder) + os.sep)
    loop = site_loop_source(fn, src.read_text())
    with src.open("a") as out:
        out.write(loop)
    return src


def _build(cc: str, flags: tuple[str, ...], src: Path, target: Path) -> None:
    obj = src.with_suffix(".so")
    proc = subprocess.run(
        [cc, *flags, str(src), "-o", str(obj), "-lm"], capture_output=True, text=True
    )
    if proc.returncode != 0:
        raise MbplanError(f"JIT compilation of {src.stem} failed:\n{proc.stderr[-2000:]}")
    # Atomic publish: a concurrent or interrupted build never leaves a half-written file.
    partial = target.with_suffix(f".{os.getpid()}.{threading.get_ident()}.tmp")
    try:
        shutil.copyfile(obj, partial)
        os.replace(partial, target)
    finally:
        partial.unlink(missing_ok=True)


_announced: list[bool] = []


def _announce_compilation() -> None:
    """One line on stderr at the first compilation of the process (silent once cached)."""
    if not _announced:
        _announced.append(True)
        print(
            "mbplan: compiling kernels, first run only (cached on disk; up to a minute; "
            "`mbplan warmup` compiles them ahead) ...",
            file=sys.stderr,
            flush=True,
        )


class _NumbaCompilation(event.Listener):
    """The first-run line when numba compiles a kernel (one loaded from numba's disk cache is
    no compilation: its ``numba:compile`` event is not triggered)."""

    def on_start(self, ev: event.Event) -> None:
        _announce_compilation()

    def on_end(self, ev: event.Event) -> None:
        pass


event.register("numba:compile", _NumbaCompilation())  # process-wide: the line is printed once


_INDEXES_SEEN: set[str] = set()


def numba_cached(dispatcher: object) -> bool:
    """False if ``dispatcher`` (numba, ``cache=True``) has no on-disk cache index yet (an index
    once seen is not looked up again: every plan asks)."""
    cache_file = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    index = getattr(cache_file, "_index_path", None)
    if index is None or str(index) in _INDEXES_SEEN:
        return True
    if Path(index).exists():
        _INDEXES_SEEN.add(str(index))
        return True
    return False


def jit_available() -> bool:
    """True if a C compiler is on the PATH (``$CC`` or gcc)."""
    return shutil.which(os.environ.get("CC", "gcc")) is not None
