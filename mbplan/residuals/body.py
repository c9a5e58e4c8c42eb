"""Residuals of a free body's state and input (:class:`~mbplan.robots.free_body.FreeBody`).

Each residual is written once, as a CasADi expression of the body state ``x = (R, p, F, v)``
(orientation, COM position, rotation step ``F_k = R_kᵀ R_{k+1}``, linear velocity, eq. 30) or of
the input ``u``, with its targets as parameters (:meth:`~mbplan.residuals.base.Residual.body_rows`,
:meth:`~mbplan.residuals.base.Residual.body_parameters`). The maximal formulation evaluates it on
SO(3)×R³ points, the quaternion formulation on ``Rot(q)``, ``Rot(f)``, the verifier on plans.
Costs are ``½ w ‖r‖²``: the chordal residuals ``vec(R R_tᵀ - I)`` give eq. (57) with ``W = w I``,
the others eq. (59).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, ClassVar

import casadi as cs
import numpy as np

from mbplan.errors import InputError
from mbplan.residuals.base import Residual
from mbplan.robots.free_body import FreeBody
from mbplan.validation import as_array, as_rotation


@dataclass(frozen=True, eq=False)
class _BodyResidual(Residual):
    """A residual of a free body only."""

    free_body: ClassVar[bool] = True

    def _body(self, robot: Any) -> FreeBody:
        if not isinstance(robot, FreeBody):
            raise InputError(
                f"{type(self).__name__} is a residual of a free body; robot {robot.name!r} is "
                "not one"
            )
        return robot

    def row_label(self, robot: Any, scene: Any, row: int) -> str:
        return f"row {row} of {type(self).__name__} on the free body {robot.name!r}"


@dataclass(frozen=True, eq=False)
class _Chordal(_BodyResidual):
    """``vec(X R_tᵀ - I)`` of a rotation ``X`` (eq. 57; 9 rows of rank 3, so a cost only)."""

    constraint: ClassVar[bool] = False
    rotation: np.ndarray | None = None

    def resolve(self, robot: Any, scene: Any) -> Residual:
        self._body(robot)
        name = type(self).__name__
        target = np.eye(3) if self.rotation is None else self.rotation
        return replace(self, rotation=as_rotation(target, f"{name}.rotation"))

    def dim(self, robot: Any, scene: Any) -> int:
        return 9

    def body_parameters(self, scene: Any) -> dict[str, Any]:
        return {"R_t": self.rotation}


@dataclass(frozen=True, eq=False)
class BodyOrientation(_Chordal):
    """``vec(R R_tᵀ - I)`` (eq. 57; 9 rows of rank 3, so a cost only)."""

    @classmethod
    def body_rows(cls, x: dict[str, Any], P: dict[str, Any]) -> Any:
        return cs.vec(cs.mtimes(x["R"], P["R_t"].T) - cs.DM.eye(3))


@dataclass(frozen=True, eq=False)
class BodyRotationStep(_Chordal):
    """``vec(F R_tᵀ - I)`` of the rotation step ``F = exp(Δt ω)`` (eq. 57; target ``I``: at
    rest). A cost only."""

    steps: ClassVar[bool] = True

    @classmethod
    def body_rows(cls, x: dict[str, Any], P: dict[str, Any]) -> Any:
        return cs.vec(cs.mtimes(x["F"], P["R_t"].T) - cs.DM.eye(3))


@dataclass(frozen=True, eq=False)
class BodyPosition(_BodyResidual):
    """``p - p_t`` (m, world; eq. 59)."""

    translation: np.ndarray | None = None

    def resolve(self, robot: Any, scene: Any) -> Residual:
        self._body(robot)
        t = as_array(self.translation, (3,), "BodyPosition.translation")
        return replace(self, translation=t)

    def dim(self, robot: Any, scene: Any) -> int:
        return 3

    def body_parameters(self, scene: Any) -> dict[str, Any]:
        return {"t": self.translation}

    @classmethod
    def body_rows(cls, x: dict[str, Any], P: dict[str, Any]) -> Any:
        return x["p"] - P["t"]


@dataclass(frozen=True, eq=False)
class BodyVelocity(_BodyResidual):
    """``v - v_t`` (m/s, world; target zero by default; eq. 59)."""

    target: np.ndarray | None = None

    def resolve(self, robot: Any, scene: Any) -> Residual:
        self._body(robot)
        t = np.zeros(3) if self.target is None else self.target
        return replace(self, target=as_array(t, (3,), "BodyVelocity.target"))

    def dim(self, robot: Any, scene: Any) -> int:
        return 3

    def body_parameters(self, scene: Any) -> dict[str, Any]:
        return {"t": self.target}

    @classmethod
    def body_rows(cls, x: dict[str, Any], P: dict[str, Any]) -> Any:
        return x["v"] - P["t"]


@dataclass(frozen=True, eq=False)
class BodyInput(_BodyResidual):
    """``u - u_t`` on the intervals (target: the hover input by default; eq. 59)."""

    space: ClassVar[str] = "control"
    target: np.ndarray | None = None

    def resolve(self, robot: Any, scene: Any) -> Residual:
        body = self._body(robot)
        t = body.hover_input if self.target is None else self.target
        return replace(self, target=as_array(t, (body.nu,), "BodyInput.target"))

    def dim(self, robot: Any, scene: Any) -> int:
        return robot.nu

    def body_parameters(self, scene: Any) -> dict[str, Any]:
        return {"t": self.target}

    @classmethod
    def body_rows(cls, x: dict[str, Any], P: dict[str, Any]) -> Any:
        return x["u"] - P["t"]


@dataclass(frozen=True, eq=False)
class BodyInputLimits(_BodyResidual):
    """``(lower - u, u - upper) ≤ 0`` on the intervals. Constraint only: bounds on ``u``
    where a formulation has them."""

    space: ClassVar[str] = "control"
    sense: ClassVar[str] = "ineq"
    cost: ClassVar[bool] = False
    input_limits: ClassVar[bool] = True
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None

    def resolve(self, robot: Any, scene: Any) -> Residual:
        body = self._body(robot)
        lo = as_array(self.lower, (body.nu,), "BodyInputLimits.lower")
        hi = as_array(self.upper, (body.nu,), "BodyInputLimits.upper")
        if np.any(lo >= hi):
            i = int(np.argmax(lo >= hi))
            raise InputError(f"BodyInputLimits: lower >= upper for input {i} ({lo[i]}, {hi[i]})")
        return replace(self, lower=lo, upper=hi)

    def dim(self, robot: Any, scene: Any) -> int:
        return 2 * robot.nu

    def variable_bounds(self, robot: Any) -> tuple[str, np.ndarray, np.ndarray]:
        return "u", self.lower, self.upper

    def body_parameters(self, scene: Any) -> dict[str, Any]:
        return {"lo": self.lower, "hi": self.upper}

    @classmethod
    def body_rows(cls, x: dict[str, Any], P: dict[str, Any]) -> Any:
        return cs.vertcat(P["lo"] - x["u"], x["u"] - P["hi"])
