"""What a verification reports, and the checks every replay shares: each constraint of the OCP
by name at the planned knots, the soft goals at their last knot, the hard constraints met, the
obstacles along the replayed motion between knots.

Thresholds are documented in :mod:`mbplan.verification.multibody`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mbplan.formulations.joint_space import evaluate
from mbplan.ocp.problem import OCP, Item
from mbplan.residuals.base import CONSTRAINT_TOLERANCE, TORQUE_TOLERANCE

__all__ = ["CONSTRAINT_TOLERANCE", "MARGIN_KEPT", "TORQUE_TOLERANCE", "Verification"]

MARGIN_KEPT = 0.9
"""The fraction of its margin an obstacle constraint with ``between_knots`` keeps along the
replayed motion, or the plan fails."""


@dataclass(frozen=True)
class Verification:
    """Outcome of :func:`mbplan.verify` (:mod:`mbplan.verification.multibody` for the metrics and
    thresholds). ``min_obstacle_distance_m`` is the smallest clearance (without margins) along the
    replayed motion, knots and the samples between them; ``clearances`` that of every obstacle
    constraint by name; ``margin_kept`` the smallest fraction of its margin that an obstacle
    constraint with ``between_knots`` keeps there (NaN without one; below :data:`MARGIN_KEPT`
    the plan fails); :mod:`mbplan.verification.loops` for ``closure_residual``, the largest loop
    closure residual at the planned knots, and ``passive_torque_nm``, the largest torque of a
    passive joint)."""

    max_joint_deviation_rad: float
    min_obstacle_distance_m: float
    final_goal_error_rad: float
    torque_limit_violation: float
    passed: bool
    reasons: list[str] = field(default_factory=list)
    max_velocity_deviation: float = float("nan")
    joint_deviation_ratio: float = float("nan")
    velocity_deviation_ratio: float = float("nan")
    open_loop_deviation_rad: float = float("nan")
    violations: dict[str, float] = field(default_factory=dict)
    goal_errors: dict[str, float] = field(default_factory=dict)
    closure_residual: float = float("nan")
    passive_torque_nm: float = float("nan")
    clearances: dict[str, float] = field(default_factory=dict)
    margin_kept: float = float("nan")


def at_knots(ocp: OCP, item: Item, q, v, tau) -> np.ndarray:
    """The residual of ``item`` at its knots of the trajectory ``q, v (N+1, ·)``, ``tau``."""
    k = item.knots
    if item.residual.space == "control":
        return evaluate(ocp.robot, ocp.scene, item.residual, None, None, tau[k])
    return evaluate(ocp.robot, ocp.scene, item.residual, q[k], v[k], None, ocp.dt)


def constraint_violations(
    ocp: OCP, q: np.ndarray, v: np.ndarray, tau: np.ndarray, tau_knots: np.ndarray | None = None
) -> dict[str, float]:
    """Largest violation of every constraint of ``ocp`` at the planned knots (``|r|`` for an
    equality, ``max(r, 0)`` for an inequality; limits of the applied torques also at
    ``tau_knots``)."""
    out = {}
    for item in ocp.constraints:
        r = at_knots(ocp, item, q, v, tau)
        if item.residual.input_limits and tau_knots is not None:
            r = np.concatenate(
                [r, evaluate(ocp.robot, ocp.scene, item.residual, None, None, tau_knots)]
            )
        viol = np.abs(r) if item.residual.sense == "eq" else np.maximum(r, 0.0)
        out[item.name] = float(np.max(viol)) if viol.size else 0.0
    return out


def goal_errors(ocp: OCP, q: np.ndarray, v: np.ndarray) -> dict[str, float]:
    """∞-norm of every soft goal (cost with a tolerance) at its last knot of ``q, v``."""
    out = {}
    for item in ocp.costs:
        if item.tolerance is None or item.residual.space != "state":
            continue
        k = int(item.knots[-1])
        r = evaluate(ocp.robot, ocp.scene, item.residual, q[k : k + 1], v[k : k + 1], None, ocp.dt)
        out[item.name] = float(np.max(np.abs(r)))
    return out


def hard_constraints_met(ocp: OCP, violations: dict[str, float]) -> list[str]:
    """Reasons the planned knots violate a hard constraint (empty: all met)."""
    reasons = []
    for item in ocp.constraints:
        tol = item.residual.violation_tolerance(item.tolerance)
        if violations[item.name] > tol:
            reasons.append(item.residual.violation_reason(item.name, violations[item.name], tol))
    return reasons


def margin_kept(ocp: OCP, clearances: dict[str, float]) -> float:
    """The smallest ``clearance / margin`` of the obstacle constraints with ``between_knots``
    and a margin (NaN without one)."""
    kept = [
        clearances[i.name] / i.residual.margin
        for i in ocp.constraints
        if i.residual.is_obstacle and i.residual.between_knots and i.residual.margin > 0.0
    ]
    return min(kept, default=float("nan"))


def replay_reasons(
    ocp: OCP, violations: dict[str, float], clearances: dict[str, float], goals: dict[str, float]
) -> list[str]:
    """Reasons a replayed plan fails besides its dynamics: the replay entering an obstacle (a
    clearance in ``clearances`` < 0, without the margins), an obstacle constraint with
    ``between_knots`` keeping less than :data:`MARGIN_KEPT` of its margin along the replay, a
    hard constraint violated at the planned knots (obstacle constraints are judged by the
    replay's clearance instead), a soft goal missed at the end of the replay (``goals``)."""
    reasons = []
    clearance = min(clearances.values(), default=np.inf)
    if clearance < 0.0:
        reasons.append(f"the replayed motion enters an obstacle ({clearance:.3g} m)")
    for item in ocp.constraints:
        r = item.residual
        if (
            r.is_obstacle
            and r.between_knots
            and 0.0 <= clearances[item.name] < MARGIN_KEPT * r.margin
        ):
            reasons.append(
                f"obstacle constraint {item.name!r} keeps {clearances[item.name] / r.margin:.0%} "
                f"of its margin {r.margin:g} m between knots ({clearances[item.name]:.4f} m; "
                f"required {MARGIN_KEPT:.0%})"
            )
    reasons += hard_constraints_met(
        ocp,
        {i.name: 0.0 if i.residual.is_obstacle else violations[i.name] for i in ocp.constraints},
    )
    for item in ocp.costs:
        if item.name in goals and goals[item.name] > item.tolerance:
            reasons.append(
                f"goal {item.name!r}: final error {goals[item.name]:.3g} exceeds the tolerance "
                f"{item.tolerance:g}"
            )
    return reasons
