"""Dispatch between the numeric (NumPy) and symbolic (CasADi) variants of the group maths.

Every group function in :mod:`mbplan.lie` accepts either NumPy arrays or CasADi ``SX``/``MX``
matrices; :func:`is_symbolic` decides which code path runs. Numeric inputs are validated
(shape, finiteness, group membership); symbolic ones cannot be and are only shape-checked.
"""

from __future__ import annotations

from typing import Any

import casadi as cs
import numpy as np

from mbplan.errors import InputError

Array = Any  # np.ndarray | cs.SX | cs.MX | cs.DM

_SYMBOLIC = (cs.SX, cs.MX)


def is_symbolic(*xs: Array) -> bool:
    """True if any argument is a CasADi symbolic matrix (SX or MX)."""
    return any(isinstance(x, _SYMBOLIC) for x in xs)


def as_numeric(x: Array, shape: tuple[int, ...], what: str) -> np.ndarray:
    """Convert ``x`` to a float array whose trailing dimensions are ``shape``; reject NaN/inf."""
    if isinstance(x, cs.DM):
        x = x.full()
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{what}: cannot convert {type(x).__name__} to a float array") from exc
    if shape == (1,) and a.ndim == 0:
        a = a.reshape(1)
    if a.ndim < len(shape) or a.shape[a.ndim - len(shape) :] != shape:
        raise InputError(
            f"{what}: expected shape (..., {', '.join(map(str, shape))}), got {a.shape}"
        )
    if not np.all(np.isfinite(a)):
        raise InputError(f"{what}: contains NaN or inf")
    return a


def check_symbolic_shape(x: Array, shape: tuple[int, int], what: str) -> None:
    """Shape check for a CasADi matrix (vectors are columns)."""
    if (x.size1(), x.size2()) != shape:
        raise InputError(f"{what}: expected a {shape[0]}x{shape[1]} CasADi matrix, got {x.shape}")


def column(x: Array) -> Array:
    """A CasADi vector as a column (row vectors are transposed)."""
    return x.T if x.size1() == 1 and x.size2() > 1 else x
