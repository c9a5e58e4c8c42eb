"""A cheap finiteness test for float vectors, shared by the solver and the transcription."""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg.blas import ddot


def finite_vector(v: np.ndarray) -> bool:
    """No NaN or infinity in the 1-D float64 array ``v``: its ``v·v`` is finite (one BLAS
    ``ddot``: no temporary and, unlike NumPy's ``dot``, no overflow warning; NaN or ±∞ anywhere
    makes it NaN or +∞), else every entry is (``v·v`` overflows from entries ≥ 1e154 on)."""
    return not v.size or math.isfinite(ddot(v, v)) or bool(np.isfinite(v).all())
