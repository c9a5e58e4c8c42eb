"""A cheap finiteness test for float vectors, shared by the solver and the transcription."""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg.blas import ddot

_DOT_MAX = 8192
"""Longest vector tested by its ``v·v``: BLAS may start threads for longer ones (OpenBLAS's
``ddot`` above 10 000 entries), which then spin beside the solver; NumPy's ``isfinite`` does
those."""


def finite_vector(v: np.ndarray) -> bool:
    """No NaN or infinity in the 1-D float64 array ``v`` (true if empty). Up to
    :data:`_DOT_MAX` entries its ``v·v`` is finite (one BLAS ``ddot``: no temporary and, unlike
    NumPy's ``dot``, no overflow warning; NaN or ±∞ anywhere makes it NaN or +∞), else every
    entry is (``v·v`` overflows from entries ≥ 1e154 on)."""
    if v.size == 0 or (v.size <= _DOT_MAX and math.isfinite(ddot(v, v))):
        return True
    return bool(np.isfinite(v).all())
