"""Generic solvers for Problem 2 of the RIPM paper (eq. 46): a problem interface on manifolds
with Euclidean tangent coordinates and the Riemannian interior point method. Nothing here knows
about robots.

Sub-packages: :mod:`.ripm` (the RIPM), :mod:`.kkt` (its KKT systems and their factorization),
:mod:`.lie_ipm` (MLG-IPM and Lai–Yoshise), :mod:`.ilqr` (Lie-group iLQR); :mod:`.nlp` is the
problem protocol every solver takes, :mod:`.result` what the interior point methods return."""

from mbplan.solvers.lie_ipm.lai_yoshise import LaiYoshiseOptions, solve_lai_yoshise
from mbplan.solvers.lie_ipm.mlgipm import MLGIPMOptions, solve_mlgipm
from mbplan.solvers.nlp import EuclideanNLP, ManifoldNLP, NLPEvaluation, RIPMProblem
from mbplan.solvers.result import IterationHistory, RIPMResult, RIPMStatus
from mbplan.solvers.ripm.driver import solve_ripm
from mbplan.solvers.ripm.options import RIPMOptions
from mbplan.workspace import Workspace

__all__ = [
    "EuclideanNLP",
    "IterationHistory",
    "LaiYoshiseOptions",
    "MLGIPMOptions",
    "ManifoldNLP",
    "NLPEvaluation",
    "RIPMOptions",
    "RIPMProblem",
    "RIPMResult",
    "RIPMStatus",
    "Workspace",
    "solve_lai_yoshise",
    "solve_mlgipm",
    "solve_ripm",
]
