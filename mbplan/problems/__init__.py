"""Optimization problems on matrix Lie groups that are not trajectories (the MLG-IPM paper's)."""

from mbplan.problems.lie_ipm import (
    LieIPMInstance,
    SLTraceProblem,
    SOLogProblem,
    haar_so,
    make_problem,
    sample_instance,
    sample_sl,
)

__all__ = [
    "LieIPMInstance",
    "SLTraceProblem",
    "SOLogProblem",
    "haar_so",
    "make_problem",
    "sample_instance",
    "sample_sl",
]
