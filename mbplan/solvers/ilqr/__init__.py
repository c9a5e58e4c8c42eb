"""Single- and multiple-shooting iLQR on Lie-group state spaces (Lin thesis, Alg. 1 and 2)."""

from mbplan.solvers.ilqr.bounds import ALOptions, solve_ilqr_bounded
from mbplan.solvers.ilqr.options import ILQROptions
from mbplan.solvers.ilqr.result import ILQRHistory, ILQRResult, ILQRStatus
from mbplan.solvers.ilqr.solver import solve_ilqr

__all__ = [
    "ALOptions",
    "ILQRHistory",
    "ILQROptions",
    "ILQRResult",
    "ILQRStatus",
    "solve_ilqr",
    "solve_ilqr_bounded",
]
