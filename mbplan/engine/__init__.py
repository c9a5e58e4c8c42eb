"""The derivative engine: exact Riemannian Jacobians/Hessians of residuals, compiled by CasADi."""

from mbplan.engine.checks import DerivativeCheck, check_derivatives
from mbplan.engine.riemannian import RiemannianFunction

__all__ = ["DerivativeCheck", "RiemannianFunction", "check_derivatives"]
