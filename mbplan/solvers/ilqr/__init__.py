"""Single- and multiple-shooting iLQR on Lie-group state spaces (Lin thesis, Alg. 1 and 2)."""

from mbplan.solvers.ilqr.options import ILQROptions
from mbplan.solvers.ilqr.result import ILQRHistory, ILQRResult, ILQRStatus
from mbplan.solvers.ilqr.solver import solve_ilqr

__all__ = ["ILQRHistory", "ILQROptions", "ILQRResult", "ILQRStatus", "solve_ilqr"]
