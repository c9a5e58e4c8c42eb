"""Checks of user input shared by tasks and baselines; each raises :class:`InputError` naming it."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from mbplan.errors import InputError

ROTATION_TOL = 1e-8  # max |RᵀR - I| accepted for a rotation matrix


def as_array(value: ArrayLike, shape: tuple[int, ...], name: str) -> np.ndarray:
    """Read-only float copy of ``value``; raise on a non-numeric value, bad shape or NaN/inf."""
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name}: not a numeric array ({exc})") from None
    if arr.shape != shape:
        raise InputError(f"{name}: expected shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name}: contains NaN or inf")
    arr.setflags(write=False)
    return arr


def as_arrays(
    values: Mapping[str, ArrayLike], shapes: Mapping[str, tuple[int, ...]], name: str
) -> dict[str, np.ndarray]:
    """:func:`as_array` of ``values[key]`` for every key of ``shapes``; raise if one is missing."""
    arrays = {}
    for key, shape in shapes.items():
        if key not in values:
            raise InputError(f"{name}: missing {key!r}, expected {name}[{key!r}] of shape {shape}")
        arrays[key] = as_array(values[key], shape, f"{name}[{key!r}]")
    return arrays


def as_real(value: object, name: str, *, positive: bool = False) -> float:
    """``value`` as a finite float ``>= 0`` (``> 0`` if ``positive``); bools are rejected."""
    if not isinstance(value, int | float | np.floating | np.integer) or isinstance(value, bool):
        raise InputError(f"{name}: expected a real number, got {value!r}")
    value = float(value)
    if not math.isfinite(value) or value < 0.0 or (positive and value == 0.0):
        raise InputError(f"{name}: must be finite and {'> 0' if positive else '>= 0'}, got {value}")
    return value


def as_bool(value: object, name: str) -> bool:
    """``value`` as a bool; anything but ``True``/``False`` (numpy's included) is rejected."""
    if not isinstance(value, bool | np.bool_):
        raise InputError(f"{name}: expected true or false, got {value!r}")
    return bool(value)


def as_int(value: object, name: str, *, minimum: int, what: str) -> int:
    """``value`` (``what`` it counts) as an int ``>= minimum``; bools are rejected."""
    if not isinstance(value, int | np.integer) or isinstance(value, bool) or value < minimum:
        raise InputError(f"{name}: {what} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def as_rotation(value: ArrayLike, name: str) -> np.ndarray:
    """:func:`as_array` of a 3x3 rotation matrix (``|RᵀR - I| ≤`` :data:`ROTATION_TOL`, det +1)."""
    R = as_array(value, (3, 3), name)
    err = np.max(np.abs(R.T @ R - np.eye(3)))
    if err > ROTATION_TOL:
        raise InputError(f"{name}: not a rotation matrix (max |RᵀR - I| = {err:.2e})")
    if np.linalg.det(R) <= 0.0:
        raise InputError(f"{name}: determinant is not +1 (a reflection)")
    return R


def output_file(path: str | os.PathLike[str], suffixes: tuple[str, ...], name: str) -> Path:
    """``path`` as a :class:`Path` to a file that can be written (checked before any work):
    one of ``suffixes``, not a directory, every existing ancestor a writable directory."""
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        raise InputError(
            f"{name}: {str(path)!r} must end in {' or '.join(suffixes)}, got "
            f"{path.suffix or 'no suffix'!r}"
        )
    if path.is_dir():
        raise InputError(f"{name}: {path} is a directory, expected a {suffixes[0]} file")
    if path.exists() and not os.access(path, os.W_OK):
        raise InputError(f"{name}: {path} exists and is not writable")
    _writable_folder(path.parent, name)
    return path


def output_dir(path: str | os.PathLike[str], name: str) -> Path:
    """``path`` as a :class:`Path` to a folder that exists or can be created and written."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError(f"{name}: {path} is a file, expected a directory")
    _writable_folder(path, name)
    return path


def _writable_folder(folder: Path, name: str) -> None:
    """The nearest existing ancestor of ``folder`` (itself included) is a writable directory."""
    probe = folder.absolute()
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir():
        if probe == folder.absolute():
            raise InputError(f"{name}: {probe} is a file, not a directory")
        raise InputError(f"{name}: {probe} is a file, so {folder} cannot be created under it")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise InputError(f"{name}: cannot write in {probe} (permission denied)")
