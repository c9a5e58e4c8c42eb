"""Residuals of a free body's state and input (:class:`~mbplan.ocp.free_body.FreeBody`).

Each residual is written once, as a CasADi expression of the body state ``x = (R, p, F, v)``
(orientation, COM position, rotation step ``F_k = R_kᵀ R_{k+1}``, linear velocity, eq. 30) or of
the input ``u``, with its targets as parameters: :func:`body_expression`. The maximal
formulation evaluates it on SO(3)×R³ points, the quaternion formulation on ``Rot(q)``,
``Rot(f)``, and :func:`evaluate` on plans (the verifier). Costs are ``½ w ‖r‖²``: the chordal
residuals ``vec(R R_tᵀ - I)`` give eq. (57) with ``W = w I``, the others eq. (59).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cache
from typing import Any, ClassVar

import casadi as cs
import numpy as np

from mbplan.errors import InputError
from mbplan.ocp.free_body import FreeBody, body_state
from mbplan.ocp.residuals import RESIDUALS, ComOutsideCylinder, Residual
from mbplan.ocp.scene import Scene
from mbplan.transcription.constraints import cylinder_clearance
from mbplan.validation import as_array, as_rotation


def _free_body(robot: Any, name: str) -> FreeBody:
    if not isinstance(robot, FreeBody):
        raise InputError(f"{name} is a residual of a free body; robot {robot.name!r} is not one")
    return robot


@dataclass(frozen=True, eq=False)
class BodyOrientation(Residual):
    """``vec(R R_tᵀ - I)`` (eq. 57; 9 rows of rank 3, so a cost only)."""

    constraint: ClassVar[bool] = False
    rotation: np.ndarray | None = None

    def resolve(self, robot: Any, scene: Scene) -> Residual:
        _free_body(robot, "BodyOrientation")
        target = np.eye(3) if self.rotation is None else self.rotation
        return replace(self, rotation=as_rotation(target, "BodyOrientation.rotation"))

    def dim(self, robot: Any, scene: Scene) -> int:
        return 9


@dataclass(frozen=True, eq=False)
class BodyRotationStep(Residual):
    """``vec(F R_tᵀ - I)`` of the rotation step ``F = exp(Δt ω)`` (eq. 57; target ``I``: at
    rest). A cost only."""

    constraint: ClassVar[bool] = False
    rotation: np.ndarray | None = None

    def resolve(self, robot: Any, scene: Scene) -> Residual:
        _free_body(robot, "BodyRotationStep")
        target = np.eye(3) if self.rotation is None else self.rotation
        return replace(self, rotation=as_rotation(target, "BodyRotationStep.rotation"))

    def dim(self, robot: Any, scene: Scene) -> int:
        return 9


@dataclass(frozen=True, eq=False)
class BodyPosition(Residual):
    """``p - p_t`` (m, world; eq. 59)."""

    translation: np.ndarray | None = None

    def resolve(self, robot: Any, scene: Scene) -> Residual:
        _free_body(robot, "BodyPosition")
        t = as_array(self.translation, (3,), "BodyPosition.translation")
        return replace(self, translation=t)

    def dim(self, robot: Any, scene: Scene) -> int:
        return 3


@dataclass(frozen=True, eq=False)
class BodyVelocity(Residual):
    """``v - v_t`` (m/s, world; target zero by default; eq. 59)."""

    target: np.ndarray | None = None

    def resolve(self, robot: Any, scene: Scene) -> Residual:
        _free_body(robot, "BodyVelocity")
        t = np.zeros(3) if self.target is None else self.target
        return replace(self, target=as_array(t, (3,), "BodyVelocity.target"))

    def dim(self, robot: Any, scene: Scene) -> int:
        return 3


@dataclass(frozen=True, eq=False)
class BodyInput(Residual):
    """``u - u_t`` on the intervals (target: the hover input by default; eq. 59)."""

    space: ClassVar[str] = "control"
    target: np.ndarray | None = None

    def resolve(self, robot: Any, scene: Scene) -> Residual:
        body = _free_body(robot, "BodyInput")
        t = body.hover_input if self.target is None else self.target
        return replace(self, target=as_array(t, (body.nu,), "BodyInput.target"))

    def dim(self, robot: Any, scene: Scene) -> int:
        return robot.nu


@dataclass(frozen=True, eq=False)
class BodyInputLimits(Residual):
    """``(lower - u, u - upper) ≤ 0`` on the intervals. Constraint only."""

    space: ClassVar[str] = "control"
    sense: ClassVar[str] = "ineq"
    cost: ClassVar[bool] = False
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None

    def resolve(self, robot: Any, scene: Scene) -> Residual:
        body = _free_body(robot, "BodyInputLimits")
        lo = as_array(self.lower, (body.nu,), "BodyInputLimits.lower")
        hi = as_array(self.upper, (body.nu,), "BodyInputLimits.upper")
        if np.any(lo >= hi):
            i = int(np.argmax(lo >= hi))
            raise InputError(f"BodyInputLimits: lower >= upper for input {i} ({lo[i]}, {hi[i]})")
        return replace(self, lower=lo, upper=hi)

    def dim(self, robot: Any, scene: Scene) -> int:
        return 2 * robot.nu


BODY_RESIDUALS = (
    BodyOrientation,
    BodyRotationStep,
    BodyPosition,
    BodyVelocity,
    BodyInput,
    BodyInputLimits,
)
FREE_BODY_RESIDUALS = (*BODY_RESIDUALS, ComOutsideCylinder)


def body_parameters(residual: Residual, scene: Scene) -> dict[str, Any]:
    """The numbers :func:`body_expression` reads (targets, limits, the cylinder)."""
    if isinstance(residual, BodyOrientation | BodyRotationStep):
        return {"R_t": residual.rotation}
    if isinstance(residual, BodyPosition):
        return {"t": residual.translation}
    if isinstance(residual, BodyVelocity | BodyInput):
        return {"t": residual.target}
    if isinstance(residual, BodyInputLimits):
        return {"lo": residual.lower, "hi": residual.upper}
    if isinstance(residual, ComOutsideCylinder):
        return {"c": residual.circle(scene)}
    raise InputError(f"{type(residual).__name__} is not a residual of a free body")


_EXPRESSIONS: dict[type, Any] = {
    BodyOrientation: lambda x, P: cs.vec(cs.mtimes(x["R"], P["R_t"].T) - cs.DM.eye(3)),
    BodyRotationStep: lambda x, P: cs.vec(cs.mtimes(x["F"], P["R_t"].T) - cs.DM.eye(3)),
    BodyPosition: lambda x, P: x["p"] - P["t"],
    BodyVelocity: lambda x, P: x["v"] - P["t"],
    BodyInput: lambda x, P: x["u"] - P["t"],
    BodyInputLimits: lambda x, P: cs.vertcat(P["lo"] - x["u"], x["u"] - P["hi"]),
    ComOutsideCylinder: lambda x, P: cylinder_clearance(x["p"], P["c"]),  # eq. (62), the COM
}


def body_expression(kind: type, x: dict[str, Any], P: dict[str, Any]) -> Any:
    """The residual of class ``kind`` at the state ``x = {R, p, F, v}`` or the input
    ``x = {u}`` with parameters ``P`` (:func:`body_parameters`), CasADi symbols or numbers."""
    if kind not in _EXPRESSIONS:
        raise InputError(f"{kind.__name__} is not a residual of a free body")
    return _EXPRESSIONS[kind](x, P)


def parameter_shapes(residual: Residual, scene: Scene) -> list[tuple[str, tuple[int, ...]]]:
    """``(name, shape)`` of :func:`body_parameters` (a vector's length as an int)."""
    shapes = ((k, np.shape(v)) for k, v in body_parameters(residual, scene).items())
    return [(k, s[0] if len(s) == 1 else s) for k, s in shapes]


# process-wide cache, result-neutral: CasADi function of the residual kind and shapes
@cache
def _numeric(kind: type, shapes: tuple, nu: int) -> cs.Function:
    x = {"R": cs.SX.sym("R", 3, 3), "p": cs.SX.sym("p", 3), "F": cs.SX.sym("F", 3, 3)}
    x |= {"v": cs.SX.sym("v", 3), "u": cs.SX.sym("u", nu)}
    P = {k: cs.SX.sym(k, *(s if isinstance(s, tuple) else (s, 1))) for k, s in shapes}
    r = body_expression(kind, x, P)
    inputs = list(x.values()) + list(P.values())
    return cs.Function(f"body_{kind.__name__}", inputs, [r])


def evaluate(
    body: FreeBody,
    scene: Scene,
    residual: Residual,
    q: np.ndarray | None,
    v: np.ndarray | None,
    u: np.ndarray | None,
    dt: float | None,
) -> np.ndarray:
    """The residual ``(K, m)`` at ``K`` knots of a plan: ``q (K, 7)``, ``v (K, 6)`` for state
    residuals (``dt`` for the rotation step), ``u (K, nu)`` for input residuals."""
    params = body_parameters(residual, scene)
    fn = _numeric(type(residual), tuple(parameter_shapes(residual, scene)), body.nu)
    if residual.space == "control":
        u = np.atleast_2d(u)
        K = len(u)
        x = {"R": np.eye(3), "p": np.zeros(3), "F": np.eye(3), "v": np.zeros(3)}
        states = [x | {"u": u[k]} for k in range(K)]
    else:
        if isinstance(residual, BodyRotationStep) and dt is None:
            raise InputError("BodyRotationStep: evaluating the rotation step needs dt")
        s = body_state(q, np.zeros((len(np.atleast_2d(q)), 6)) if v is None else v, dt or 1.0)
        K = len(s["R"])
        states = [
            {"R": s["R"][k], "p": s["p"][k], "F": s["F"][k], "v": s["v"][k], "u": np.zeros(body.nu)}
            for k in range(K)
        ]
    rows = [np.array(fn(*x.values(), *params.values())).ravel() for x in states]
    return np.array(rows).reshape(K, -1)


RESIDUALS.update({cls.__name__: cls for cls in BODY_RESIDUALS})
