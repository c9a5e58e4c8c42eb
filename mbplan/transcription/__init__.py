"""Transcription: trajectory variables on a product manifold, cost and constraint terms, and the
sparse NLP (values, Riemannian Jacobians, Lagrangian Hessian) that a solver sees."""

from mbplan.transcription.terms import Term
from mbplan.transcription.trajectory import TrajectoryProblem
from mbplan.transcription.variables import Block, TrajectoryVariables

__all__ = ["Block", "Term", "TrajectoryProblem", "TrajectoryVariables"]
