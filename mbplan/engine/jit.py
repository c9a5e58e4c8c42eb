"""Compile CasADi Functions to C with the system compiler, cached on disk by content hash.

A second run with the same Function (same expression graph, compiler and flags) loads the
shared object from the cache instead of recompiling. The cache directory is
``$MBPLAN_CACHE_DIR`` or ``~/.cache/mbplan/jit``.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import threading
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import casadi as cs

from mbplan.errors import MbplanError

DEFAULT_FLAGS = ("-O2", "-fPIC", "-shared", "-march=native")


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


def compile_function(fn: cs.Function, flags: tuple[str, ...] = DEFAULT_FLAGS) -> cs.Function:
    """Return ``fn`` compiled to native code (loaded with ``casadi.external``)."""
    return compile_functions({"fn": fn}, flags)["fn"]


def compile_functions(
    fns: Mapping[str, cs.Function], flags: tuple[str, ...] = DEFAULT_FLAGS
) -> dict[str, cs.Function]:
    """:func:`compile_function` of each value; the C compilers of uncached ones run in parallel."""
    cc = compiler()
    targets = {}
    for key, fn in fns.items():
        digest = hashlib.sha256(
            "\0".join([fn.serialize(), cc, *flags, cs.__version__]).encode()
        ).hexdigest()[:24]
        targets[key] = cache_dir() / f"{fn.name()}_{digest}.so"
    missing = [k for k in fns if not targets[k].exists()]
    if missing:
        _announce_compilation()
        with tempfile.TemporaryDirectory() as tmp:
            sources = {k: _generate(fns[k], Path(tmp)) for k in missing}  # CasADi: one thread
            with ThreadPoolExecutor(max_workers=min(len(missing), os.cpu_count() or 1)) as pool:
                list(pool.map(lambda k: _build(cc, flags, sources[k], targets[k]), missing))
    return {k: cs.external(fn.name(), str(targets[k])) for k, fn in fns.items()}


def _generate(fn: cs.Function, folder: Path) -> Path:
    src = folder / f"{fn.name()}.c"
    cg = cs.CodeGenerator(src.name, {"with_header": False})
    cg.add(fn)
    cg.generate(str(folder) + os.sep)
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
            "mbplan: compiling kernels, first run only (cached on disk; up to a minute) ...",
            file=sys.stderr,
            flush=True,
        )


def announce_uncached_numba(*dispatchers: object) -> None:
    """Print the first-run line if a numba ``cache=True`` dispatcher has no cache index yet
    (numba then compiles it at its first call)."""
    if not all(numba_cached(d) for d in dispatchers):
        _announce_compilation()


def numba_cached(dispatcher: object) -> bool:
    """False if ``dispatcher`` (numba, ``cache=True``) has no on-disk cache index yet."""
    cache_file = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    index = getattr(cache_file, "_index_path", None)
    return index is None or Path(index).exists()


def jit_available() -> bool:
    """True if a C compiler is on the PATH (``$CC`` or gcc)."""
    return shutil.which(os.environ.get("CC", "gcc")) is not None
