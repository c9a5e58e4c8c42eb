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
import tempfile
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
    cc = compiler()
    key = hashlib.sha256(
        "\0".join([fn.serialize(), cc, *flags, cs.__version__]).encode()
    ).hexdigest()[:24]
    name = fn.name()
    target = cache_dir() / f"{name}_{key}.so"
    if not target.exists():
        with tempfile.TemporaryDirectory() as tmp:
            src = Path(tmp) / f"{name}.c"
            cg = cs.CodeGenerator(src.name, {"with_header": False})
            cg.add(fn)
            cg.generate(tmp + os.sep)
            obj = Path(tmp) / f"{name}.so"
            proc = subprocess.run(
                [cc, *flags, str(src), "-o", str(obj), "-lm"], capture_output=True, text=True
            )
            if proc.returncode != 0:
                raise MbplanError(f"JIT compilation of {name} failed:\n{proc.stderr[-2000:]}")
            # Atomic publish: a concurrent or interrupted build never leaves a half-written file.
            partial = target.with_suffix(f".{os.getpid()}.tmp")
            shutil.copyfile(obj, partial)
            os.replace(partial, target)
    return cs.external(name, str(target))


def jit_available() -> bool:
    """True if a C compiler is on the PATH (``$CC`` or gcc)."""
    return shutil.which(os.environ.get("CC", "gcc")) is not None
