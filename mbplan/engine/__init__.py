"""The derivative engine: exact Riemannian Jacobians/Hessians of residuals, compiled by CasADi."""

from mbplan.engine.callback import CallbackFunction
from mbplan.engine.checks import DerivativeCheck, check_derivatives
from mbplan.engine.riemannian import RiemannianFunction
from mbplan.engine.site_function import SiteFunction

__all__ = [
    "CallbackFunction",
    "DerivativeCheck",
    "RiemannianFunction",
    "SiteFunction",
    "check_derivatives",
]
