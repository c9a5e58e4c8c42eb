"""Independent verification of a plan: :func:`verify` replays it with dynamics that share no
code with the planners and checks every constraint and goal of its OCP by name.

:mod:`.multibody` replays a robot's plan with Pinocchio, :mod:`.free_body` a free body's with the
LGVI in NumPy; :mod:`.report` holds what both report and the checks they share."""

from __future__ import annotations

import numpy as np

from mbplan.errors import InputError
from mbplan.ocp.problem import OCP
from mbplan.results import PlanResult
from mbplan.robots.free_body import FreeBody
from mbplan.verification.free_body import verify_free_body
from mbplan.verification.multibody import check_shapes, verify_multibody
from mbplan.verification.report import Verification

__all__ = ["Verification", "verify"]


def verify(ocp: OCP | PlanResult, result: PlanResult | None = None) -> Verification:
    """Check ``result`` against ``ocp`` with Pinocchio's continuous-time dynamics and every
    constraint of the OCP by name; ``verify(result)`` uses the OCP the result carries.

    Raises :class:`InputError` if the result does not belong to the OCP (shapes, ``dt``, knot 0).
    A result with NaN or inf fails with that reason and NaN metrics.
    """
    if result is None and isinstance(ocp, PlanResult):
        result = ocp
        ocp = result.ocp
        if ocp is None:
            why = result.extra.get("ocp_unavailable", "the result carries no OCP (an old file)")
            raise InputError(f"verify: {why}; pass the OCP: verify(ocp, result)")
    if not isinstance(ocp, OCP):
        raise InputError(f"verify: expected an OCP, got {type(ocp).__name__}")
    if not isinstance(result, PlanResult):
        raise InputError(f"verify: expected a PlanResult, got {type(result).__name__}")
    check_shapes(ocp, result)
    applied = result.tau if result.tau_knots is None else result.tau_knots
    if not all(np.all(np.isfinite(a)) for a in (result.q, result.v, result.tau, applied)):
        nan = float("nan")
        return Verification(nan, nan, nan, nan, False, ["the trajectory contains NaN or inf"])
    if isinstance(ocp.robot, FreeBody):
        return verify_free_body(ocp, result)
    return verify_multibody(ocp, result)
