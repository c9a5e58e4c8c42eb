"""The RIPM's iterate and what is computed from it.

:class:`Iterate` is the primal-dual point, :class:`Trial` a candidate primal point with its
values, :class:`Step` a Newton direction and :class:`Residuals` the optimality residuals of
eq. (50) with the scaled KKT error ``E_0`` (eq. 55-56, WB eq. 5); :class:`Stop` ends a solve.
:class:`~mbplan.solvers.ripm.phase.Phase` computes them.
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mbplan.finite import finite_vector
from mbplan.solvers.nlp import NLPEvaluation, Point
from mbplan.solvers.result import RIPMStatus
from mbplan.solvers.ripm.kernels import abs_max, csr_transpose_times, frac_to_boundary

EPS = float(np.finfo(float).eps)


@dataclass
class Trial:
    """A candidate primal point with its values (``h``, ``g`` at ``x``; slacks ``s``).

    ``c`` are the constraints of the phase (``(h, g + s)``, minus ``p`` plus ``n`` in the
    restoration phase, whose trials also carry the elastic variables and the displacement ``ξ``).
    """

    x: Point
    s: np.ndarray
    f: float
    h: np.ndarray
    g: np.ndarray
    c: np.ndarray
    theta: float
    phi: float
    log_s: float  # Σ log s (φ_μ's barrier term without μ)
    p: np.ndarray | None = None
    n: np.ndarray | None = None
    xi: np.ndarray | None = None
    ev: NLPEvaluation | None = None  # with the Hessian at ``multipliers`` (Phase.trial_at)
    multipliers: tuple[np.ndarray, np.ndarray, float] | None = None  # y, z, α_z


@dataclass
class Step:
    """A Newton direction (the elastic parts only in the restoration phase)."""

    dx: np.ndarray
    ds: np.ndarray
    dy: np.ndarray
    dz: np.ndarray
    dp: np.ndarray | None = None
    dn: np.ndarray | None = None
    dzp: np.ndarray | None = None
    dzn: np.ndarray | None = None


class Stop(Exception):
    """Ends the solve with a status (raised from any part of an iteration)."""

    def __init__(self, status: RIPMStatus, message: str = "") -> None:
        super().__init__(message)
        self.status, self.message = status, message or status.value


@dataclass
class Iterate:
    """The primal-dual point ``x, s, y, z`` with its evaluation ``ev``; in the restoration phase
    also the elastic variables ``ep, en``, their multipliers ``zp, zn`` and the displacement
    ``xi``."""

    x: Point
    s: np.ndarray
    y: np.ndarray
    z: np.ndarray
    ev: NLPEvaluation | None = None
    ep: np.ndarray | None = None
    en: np.ndarray | None = None
    zp: np.ndarray | None = None
    zn: np.ndarray | None = None
    xi: np.ndarray | None = None

    @property
    def lam(self) -> np.ndarray:
        """Multipliers of all rows ``(y, z)``."""
        return np.concatenate([self.y, self.z])


@dataclass
class Residuals:
    """The residuals of (50) at an iterate (of the restoration problem in that phase: ``r_pn``
    are the elastic rows), the scalings ``s_d, s_c`` (WB eq. 5) and ``E_0``; ``of`` holds the
    ``ev, y, z, s`` they were measured at."""

    r_d: np.ndarray
    r_c: np.ndarray
    inf_du: float
    inf_pr: float
    s_d: float
    s_c: float
    kkt_error: float
    of: tuple
    r_pn: tuple[np.ndarray, np.ndarray] | None = None

    def at(self, it: Iterate) -> bool:
        """Measured at ``it`` as it is now."""
        return all(map(operator.is_, self.of, (it.ev, it.y, it.z, it.s)))


def finite(*arrays: Any) -> bool:
    """No NaN or infinity in any of the arrays (or floats)."""
    for a in arrays:
        if type(a) is np.ndarray and a.ndim == 1 and a.dtype == np.float64:
            if not finite_vector(a):
                return False
        elif isinstance(a, float):  # np.float64 too
            if not math.isfinite(a):
                return False
        elif not np.isfinite(a).all():
            return False
    return True


amax = abs_max
"""``‖v‖∞`` of a 1-D array (0 if empty)."""

__all__ = [
    "EPS",
    "Iterate",
    "Residuals",
    "Step",
    "Stop",
    "Trial",
    "amax",
    "finite",
    "frac_to_boundary",
    "transpose_times",
]


def transpose_times(a: sp.csr_matrix | sp.csr_array, x: np.ndarray) -> np.ndarray:
    """``aᵀ x`` for a CSR ``a`` without building the transpose (the sums of scipy's
    ``a.T @ x``, in its order)."""
    if not (
        sp.issparse(a) and a.format == "csr" and x.dtype == np.float64 and a.dtype == x.dtype
    ) or x.shape != (a.shape[0],):
        if x.shape == (a.shape[0],) and sp.issparse(a) and a.nnz == 0:
            return np.zeros(a.shape[1])  # an empty block of any dtype
        return a.T @ x  # scipy's product (and its error for a wrong length)
    return csr_transpose_times(a.indptr, a.indices, a.data, x, a.shape[1])
