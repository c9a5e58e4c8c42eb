"""Generic solvers for Problem 2 of the RIPM paper (eq. 46): a problem interface on manifolds
with Euclidean tangent coordinates and the Riemannian interior point method. Nothing here knows
about robots."""

from mbplan.solvers.lai_yoshise import LaiYoshiseOptions, solve_lai_yoshise
from mbplan.solvers.mlgipm import MLGIPMOptions, solve_mlgipm
from mbplan.solvers.options import RIPMOptions
from mbplan.solvers.problem import EuclideanNLP, ManifoldNLP, NLPEvaluation, RIPMProblem
from mbplan.solvers.result import IterationHistory, RIPMResult, RIPMStatus
from mbplan.solvers.ripm import solve_ripm

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
    "solve_lai_yoshise",
    "solve_mlgipm",
    "solve_ripm",
]
