"""Centre-of-mass residuals: eq. (62), the COM of every moving link (of a free body: its position)
outside a vertical scene cylinder, ``(r + margin)² - ‖(x_i, y_i) - c‖² ≤ 0`` (for a robot also
between the knots), and the robot's COM at a target (linear in the bodies' positions in maximal
coordinates)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import cache
from typing import Any, ClassVar

import casadi as cs
import numpy as np

from mbplan.engine import RiemannianFunction
from mbplan.errors import InputError
from mbplan.lie import R
from mbplan.residuals.base import Residual, ShootingResidual, SymbolicContext, SymbolicRows
from mbplan.robots.free_body import FreeBody
from mbplan.transcription.constraints import (
    cylinder_clearance,
    cylinder_clearance_function,
    interval_cylinder_clearance_function,
)
from mbplan.transcription.intervals import interval_samples
from mbplan.transcription.terms import Term
from mbplan.validation import as_array, as_bool, as_real


@dataclass(frozen=True, eq=False)
class ComOutsideCylinder(Residual):
    """Eq. (62): ``(r + margin)² - ‖(x_i, y_i) - c‖² ≤ 0`` for the COM ``p_i`` of every moving
    link and the vertical scene cylinder ``obstacle`` (infinite in z). Constraint only.

    ``between_knots=True`` also keeps the COMs out along each interval's motion (a robot only,
    :mod:`mbplan.residuals.base`); False constrains the knots only, as the RIPM paper does."""

    sense: ClassVar[str] = "ineq"
    cost: ClassVar[bool] = False
    free_body: ClassVar[bool] = True
    is_obstacle: ClassVar[bool] = True
    obstacle: str = ""
    margin: float = 0.0
    between_knots: bool = True

    def resolve(self, robot: Any, scene: Any) -> Residual:
        o = scene[self.obstacle]
        if o.shape != "cylinder" or not np.allclose(o.pose[:3, 2], [0, 0, 1], atol=1e-9):
            raise InputError(f"ComOutsideCylinder: {o} is not a vertical cylinder")
        between = as_bool(self.between_knots, "ComOutsideCylinder.between_knots")
        if between and isinstance(robot, FreeBody):
            self.knots_only(f"the free body {robot.name!r}'s coordinates")
        margin = as_real(self.margin, "ComOutsideCylinder.margin")
        return replace(self, margin=margin, between_knots=between)

    def dim(self, robot: Any, scene: Any) -> int:
        return 1 if isinstance(robot, FreeBody) else robot.model.njoints - 1

    def circle(self, scene: Any) -> np.ndarray:
        """``(x_c, y_c, r + margin)``."""
        o = scene[self.obstacle]
        return np.array([*o.pose[:2, 3], o.size[0] + self.margin])

    def joint_space(self, robot: Any, scene: Any) -> SymbolicRows:
        return SymbolicRows((type(self),), self.circle(scene), self._rows)

    def _rows(self, ctx: SymbolicContext) -> cs.SX:
        model, placements = ctx.robot.model, ctx.placements()
        rows = []
        for j in range(1, model.njoints):
            Rj, pj = placements[j]
            com = pj + cs.mtimes(Rj, cs.DM(model.inertias[j].lever))
            rows.append(cylinder_clearance(com, ctx.theta))
        return cs.vertcat(*rows)

    def row_label(self, robot: Any, scene: Any, row: int) -> str:
        if isinstance(robot, FreeBody):
            return f"row {row} of ComOutsideCylinder on the free body {robot.name!r}"
        name = robot.model.names[row + 1]
        return f"the COM of the link of joint {name!r} near cylinder {self.obstacle!r}"

    def maximal_terms(self, ctx: Any, item: Any) -> list[Term]:
        nb = ctx.mm.nb
        k, b = (a.ravel() for a in np.meshgrid(item.knots, np.arange(nb), indexing="ij"))
        circle = self.circle(ctx.ocp.scene)
        fn = cylinder_clearance_function(ctx.jit)
        terms = [Term(item.name, "ineq", fn, {"p": ("p", k * nb + b)}, {"c": circle})]
        if not self.between_knots:
            return terms
        k, s = interval_samples(item.knots)
        j, b = (a.ravel() for a in np.meshgrid(np.arange(k.size), np.arange(nb), indexing="ij"))
        sites = k[j] * nb + b
        fn = interval_cylinder_clearance_function(ctx.jit)
        bind = {"p": ("p", sites), "v": ("v", sites)}
        params = {"c": circle, "s": s[j], "dt": ctx.ocp.dt}
        return [*terms, Term(f"{item.name}/between_knots", "ineq", fn, bind, params)]

    def body_parameters(self, scene: Any) -> dict[str, Any]:
        return {"c": self.circle(scene)}

    @classmethod
    def body_rows(cls, x: dict[str, Any], P: dict[str, Any]) -> Any:
        return cylinder_clearance(x["p"], P["c"])

    def shooting(self, ctx: Any, item: Any) -> ShootingResidual:
        """``‖(x_i, y_i) - c‖ - r ≥ margin`` (in metres, the form the FDDP penalty is tuned
        for)."""
        self.knots_only("shooting")
        x, y, radius = self.circle(ctx.ocp.scene)
        model = ctx.com_clearance((x, y), radius - self.margin)
        lower, upper = np.full(model.nr, self.margin), np.full(model.nr, np.inf)
        return ShootingResidual(model, lower, upper, ctx.obstacle_weight)

    def clearance(
        self, robot: Any, scene: Any, path: np.ndarray, evaluate: Callable | None
    ) -> float:
        """A free body's ``path`` is its positions ``(K, ≥3)``; a robot's, configurations."""
        xc, yc, radius = self.circle(scene)
        base = radius - self.margin
        if isinstance(robot, FreeBody):
            return float(np.min(np.hypot(path[:, 0] - xc, path[:, 1] - yc) - base))
        dist2 = radius**2 - evaluate(self, path)  # squared horizontal distance to the axis
        return float(np.min(np.sqrt(np.maximum(dist2, 0.0)) - base))


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def _com_function(nb: int, cost: bool, jit: bool) -> RiemannianFunction:
    """``Σ m_b p_b / Σ m_b - target`` of ``nb`` bodies' COMs ``p0 … p{nb-1}`` (as a cost
    ``½ w ‖r‖²``)."""

    def fn(mass, target, w=None, **p):
        com = sum(mass[b] * p[f"p{b}"] for b in range(nb)) / cs.sum1(mass)
        return 0.5 * w * cs.sumsqr(com - target) if cost else com - target

    params = [("mass", nb), ("target", 3)] + ([("w", 1)] if cost else [])
    name = f"com_position_{nb}_{'cost' if cost else 'eq'}"
    return RiemannianFunction(name, [(f"p{b}", R(3)) for b in range(nb)], fn, params, jit=jit)


@dataclass(frozen=True, eq=False)
class ComPosition(Residual):
    """``c(q) - target`` (m, world frame): the centre of mass of the robot's moving links."""

    target: np.ndarray | None = None

    def resolve(self, robot: Any, scene: Any) -> Residual:
        if isinstance(robot, FreeBody):
            raise InputError("ComPosition: a free body's COM is its position: use BodyPosition")
        return replace(self, target=as_array(self.target, (3,), "ComPosition.target"))

    def dim(self, robot: Any, scene: Any) -> int:
        return 3

    def joint_space(self, robot: Any, scene: Any) -> SymbolicRows:
        return SymbolicRows((type(self),), np.asarray(self.target, dtype=float), self._rows)

    def _rows(self, ctx: SymbolicContext) -> cs.SX:
        model, placements = ctx.robot.model, ctx.placements()
        total, mass = cs.DM.zeros(3), 0.0
        for j in range(1, model.njoints):
            Rj, pj = placements[j]
            inertia = model.inertias[j]
            total += inertia.mass * (pj + cs.mtimes(Rj, cs.DM(inertia.lever)))
            mass += inertia.mass
        return total / mass - ctx.theta

    def maximal_terms(self, ctx: Any, item: Any) -> list[Term]:
        nb, cost = ctx.mm.nb, item.role == "cost"
        bind = {f"p{b}": ("p", item.knots * nb + b) for b in range(nb)}
        params = {"mass": ctx.mm.mass, "target": np.asarray(self.target, dtype=float)}
        if cost:
            params["w"] = item.weight
        fn = _com_function(nb, cost, ctx.jit)
        return [Term(item.name, "cost" if cost else self.sense, fn, bind, params)]
