"""Checks of user input shared by tasks and baselines; each raises :class:`InputError` naming it."""

from __future__ import annotations

import math
from collections.abc import Mapping

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
