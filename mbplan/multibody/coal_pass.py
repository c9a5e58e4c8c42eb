"""Coal distances of many sites in one compiled call.

:func:`~mbplan.multibody.collision.signed_distances` asks coal for hundreds of (robot
geometry, obstacle) distances per evaluation. Called from Python, each costs a transform, a
result object and the binding's dispatch around coal's few microseconds of GJK. Here a C++ loop
(``coal_pass.cpp``) calls ``coal::distance`` for every site, on the very shapes the Python
objects hold (eigenpy's ``id()`` is the C++ object's address; the loop checks each shape's node
type against Python's before using it), with the same request policy, so its answers are coal's
Python answers bit for bit.

The library is compiled once with the system C++ compiler (``$CXX``, default ``g++``) against
coal's headers and library and CasADi's Eigen headers, and cached beside the kernels
(:func:`~mbplan.engine.jit.cache_dir`). Where it cannot be built (no compiler, no headers) or
a site fails in it, :func:`site_distances` returns ``None`` and the caller asks coal pair by
pair (which raises the errors).
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import casadi
import coal
import numpy as np

from mbplan.engine.compile_clock import compiling
from mbplan.engine.jit import cache_dir

SOURCE = Path(__file__).with_name("coal_pass.cpp")
FLAGS = ("-O2", "-fPIC", "-shared", "-std=c++17", "-fopenmp")
DISABLE = "MBPLAN_COAL_PASS"
"""Set to ``off`` to ask coal pair by pair from Python."""

_DOUBLE = np.ctypeslib.ndpointer(np.float64, flags="C_CONTIGUOUS")


def _prefix() -> Path | None:
    """The install prefix whose ``include/coal`` and ``lib/libcoal*`` belong to the imported
    coal module."""
    for folder in Path(coal.__file__).resolve().parents:
        if (folder / "include" / "coal" / "distance.h").exists():
            return folder
    return None


def _eigen() -> Path | None:
    for folder in (_prefix(), Path(casadi.__file__).parent):
        if folder is not None and (folder / "include" / "eigen3" / "Eigen" / "Dense").exists():
            return folder / "include" / "eigen3"
    return None


def _command(target: Path) -> list[str] | None:
    """The compiler call that builds the library into ``target``; None if something is missing."""
    cxx, prefix, eigen = os.environ.get("CXX", "g++"), _prefix(), _eigen()
    if shutil.which(cxx) is None or prefix is None or eigen is None:
        return None
    libraries = sorted((prefix / "lib").glob("libcoal.so*"))
    if not libraries:
        return None
    lib = libraries[0].parent
    return [
        cxx,
        *FLAGS,
        f"-I{prefix / 'include'}",
        f"-I{eigen}",
        str(SOURCE),
        "-o",
        str(target),
        f"-L{lib}",
        "-lcoal",
        f"-Wl,-rpath,{lib}",
    ]


@cache  # process-wide, result-neutral: the library of this source and coal, or None
def library() -> ctypes.CDLL | None:
    """The compiled loop (built on first use, then loaded from the cache); None where it
    cannot be built or ``$MBPLAN_COAL_PASS`` is ``off`` (a line on stderr says why)."""
    if os.environ.get(DISABLE, "").lower() in ("off", "0", "false", "no"):
        return None
    probe = _command(Path("lib.so"))
    if probe is None:
        _note("no C++ compiler (set CXX) or no coal/Eigen headers")
        return None
    key = "\0".join([SOURCE.read_text(), *probe, coal.__version__])
    target = cache_dir() / f"coal_pass_{hashlib.sha256(key.encode()).hexdigest()[:24]}.so"
    if not target.exists():
        with compiling(), tempfile.TemporaryDirectory() as tmp:
            built = Path(tmp) / "coal_pass.so"
            proc = subprocess.run(_command(built), capture_output=True, text=True)
            if proc.returncode != 0:
                _note(f"its compilation failed:\n{proc.stderr[-1500:]}")
                return None
            partial = target.with_suffix(f".{os.getpid()}.tmp")
            shutil.copyfile(built, partial)
            os.replace(partial, target)  # atomic: a reader never sees a partial library
    lib = ctypes.CDLL(str(target))
    call = lib.mbplan_coal_distances
    int64 = np.ctypeslib.ndpointer(np.int64, flags="C_CONTIGUOUS")
    int32 = np.ctypeslib.ndpointer(np.int32, flags="C_CONTIGUOUS")
    uint8 = np.ctypeslib.ndpointer(np.uint8, flags="C_CONTIGUOUS")
    call.argtypes = [
        ctypes.c_longlong,
        *[int64] * 3,
        int32,
        uint8,
        *[_DOUBLE] * 11,
        ctypes.POINTER(ctypes.c_longlong),
    ]
    call.restype = ctypes.c_longlong
    return lib


def _note(why: str) -> None:
    print(f"mbplan: coal distances pair by pair from Python: {why}", file=sys.stderr, flush=True)


def addresses(shapes: Sequence[coal.CollisionGeometry]) -> tuple[np.ndarray, np.ndarray]:
    """The C++ addresses ``(n,)`` and node types ``(n,)`` of coal shapes."""
    address = np.array([s.id() for s in shapes], dtype=np.int64).reshape(-1)
    kind = np.array([int(s.getNodeType()) for s in shapes], dtype=np.int32).reshape(-1)
    return address, kind


@dataclass(frozen=True)
class PairShapes:
    """What the pass reads of ``P`` (robot geometry, obstacle) pairs: both shapes' addresses
    and node types (:func:`addresses`), the cross-check flag ``checked (P,)``, the local AABBs
    ``robot_box``, ``obstacle_box`` ``(P, 6)`` (center, half extents) and the obstacles' world
    poses (``obstacle_rotation (P, 3, 3)``, ``obstacle_translation (P, 3)``)."""

    robot: tuple[np.ndarray, np.ndarray]
    obstacle: tuple[np.ndarray, np.ndarray]
    checked: np.ndarray
    robot_box: np.ndarray
    obstacle_box: np.ndarray
    obstacle_rotation: np.ndarray
    obstacle_translation: np.ndarray


def site_distances(
    shapes: PairShapes,
    pair: np.ndarray,
    rotation: np.ndarray,
    translation: np.ndarray,
    cap: np.ndarray,
    tolerances: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int] | None:
    """Coal's distance ``(S,)`` capped at ``cap (S,)``, normal ``(S, 3)`` and robot witness
    point ``(S, 3)`` of each site: pair ``pair (S,)`` with the robot geometry at ``rotation
    (S, 3, 3)``, ``translation (S, 3)``; as
    :func:`~mbplan.multibody.collision.signed_distances` defines them (a site whose lower bound
    exceeds its cap is not sent to coal), with the number of sites sent to coal.
    ``tolerances`` as ``coal_pass.cpp`` reads them. None where the library is missing or a site
    failed in it."""
    lib = library()
    if lib is None:
        return None
    S = len(pair)
    distance, normal, point = np.empty(S), np.empty((S, 3)), np.empty((S, 3))
    sent = ctypes.c_longlong(0)
    failed = lib.mbplan_coal_distances(
        S,
        np.ascontiguousarray(pair, dtype=np.int64),
        shapes.robot[0],
        shapes.obstacle[0],
        np.ascontiguousarray(np.stack([shapes.robot[1], shapes.obstacle[1]], axis=1)),
        np.ascontiguousarray(shapes.checked, dtype=np.uint8),
        *(
            np.ascontiguousarray(a, dtype=np.float64)
            for a in (
                shapes.robot_box,
                shapes.obstacle_box,
                shapes.obstacle_rotation,
                shapes.obstacle_translation,
                rotation,
                translation,
                cap,
                tolerances,
            )
        ),
        distance,
        normal,
        point,
        ctypes.byref(sent),
    )
    return None if failed >= 0 else (distance, normal, point, sent.value)
