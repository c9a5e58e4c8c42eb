"""Coal distances: ``margin - min(d, margin + activation) ≤ 0`` for the signed distance ``d`` of
every collision geometry on a moving link and every scene object, through the one coal path of
:mod:`mbplan.multibody.collision` (witness-point gradient ``nᵀ J₁``, fixed-witness-point Hessian)
in joint space, :mod:`mbplan.transcription.distance` on the body poses in maximal coordinates.

The cap leaves the feasible set unchanged (``min(d, D) ≥ margin ⇔ d ≥ margin`` for
``D > margin``) and makes a far pair's row the constant ``-activation`` with zero derivatives:
continuous, never violated, its multiplier ~0 (an interior point method drives it to
``μ / activation``), so it does not steer the step; a pair whose bounding-volume lower bound
exceeds ``D`` costs no coal call at all."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Any, ClassVar

import numpy as np

from mbplan.errors import InputError
from mbplan.multibody.collision import (
    CollisionPairs,
    chain_kinematics,
    collision_pairs,
    joint_placements,
    joint_space_contacts,
    joint_support,
    placed_contacts,
    point_hessians,
)
from mbplan.multibody.convex import GEOMETRIES, collision_geometry
from mbplan.residuals.base import Residual, ShootingResidual
from mbplan.transcription.distance import (
    distance_constraint_function,
    interval_distance_function,
    pair_bodies,
)
from mbplan.transcription.intervals import interval_samples
from mbplan.transcription.terms import Term
from mbplan.validation import as_bool, as_real


# process-wide cache, result-neutral: geometry pairs of the robot, scene and object names
@lru_cache(maxsize=64)
def distance_pairs(
    robot: Any, scene: Any, objects: tuple[str, ...], geometry: str = "convex"
) -> CollisionPairs:
    """The (moving collision geometry, scene object) pairs of a distance residual, meshes as
    their convex hulls (``geometry="convex"``) or as they are (``"mesh"``)."""
    solids = [
        (
            collision_geometry(
                scene[n].geometry(), geometry, f"scene object {n!r} ({scene[n].mesh})", InputError
            ),
            scene[n].pose,
        )
        for n in objects
    ]
    return collision_pairs(robot.collision_model, solids, geometry)


def distance_values(
    robot: Any, scene: Any, residual: Distance, q: np.ndarray, order: int = 0
) -> tuple[np.ndarray, ...]:
    """``margin - min(d, margin + activation)`` ``(K, P)`` at ``q (K, nq)``; with ``order >= 1``
    also the Jacobian ``(K, P, nv)`` ``nᵀ J₁`` (and the kinematics and contacts for second
    order)."""
    pairs = distance_pairs(robot, scene, residual.objects, residual.geometry)
    cap = residual.margin + residual.activation
    if order == 0:  # placements alone: no Jacobians
        placements = joint_placements(robot.model, robot.model.createData(), np.atleast_2d(q))
        return (residual.margin - placed_contacts(pairs, *placements, cap).distance,)
    kin = chain_kinematics(robot.model, robot.model.createData(), np.atleast_2d(q))
    contacts, J = joint_space_contacts(pairs, kin, cap)
    value = residual.margin - contacts.distance
    grad = np.einsum("kpa,kpja->kpj", contacts.normal, J)
    return value, grad, kin, contacts, J


class DistanceRows:
    """The rows ``margin - d`` of a :class:`Distance` at knots ``q (K, nq)`` with their own
    derivatives in ``q`` (the joint-space form of a residual CasADi cannot write)."""

    def __init__(self, robot: Any, scene: Any, residual: Distance):
        self.robot, self.scene, self.residual = robot, scene, residual
        self.margin = residual.margin
        self.pairs = distance_pairs(robot, scene, residual.objects, residual.geometry)
        self.size = self.pairs.size

    def values(self, q: np.ndarray) -> np.ndarray:
        """``margin - d`` ``(K, P)``."""
        return distance_values(self.robot, self.scene, self.residual, q)[0]

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """``∂(margin - d)/∂q = nᵀ J₁`` ``(K, P, nv)``."""
        return distance_values(self.robot, self.scene, self.residual, q, 1)[1]

    def jacobian_support(self) -> np.ndarray:
        """``(P, nv)`` bool: the velocities that move each pair's link."""
        return joint_support(self.robot.model)[self.pairs.joint]

    def hessian(self, q: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """``Σ_p μ_kp ∇²(margin - d_p)`` ``(K, nv, nv)`` at fixed witness points."""
        _, _, kin, contacts, J = distance_values(self.robot, self.scene, self.residual, q, 1)
        P = point_hessians(kin, self.pairs.joint, J)
        return np.einsum("kp,kpa,kpjla->kjl", mu, contacts.normal, P)


@dataclass(frozen=True, eq=False)
class Distance(Residual):
    """``margin - d ≤ 0`` for coal's signed distance ``d`` of every collision geometry on a
    moving link and every scene object in ``objects`` (all if None). Constraint only.

    ``geometry="convex"``: meshes (robot and scene) as their convex hulls, which contain them (a
    conservative distance, exact for convex meshes); ``"mesh"``: the exact meshes, ~7x slower.
    Pairs farther apart than ``margin + activation`` (m) are rows at ``-activation`` with zero
    derivatives (module docstring). The activation must exceed what one Newton step moves a
    link, or a pair crosses from the flat part into the margin unseen: on the UR5 shelf at
    ``N = 12`` the RIPM failed at 0.2 m and converged at 0.3 m.

    ``between_knots=True`` also keeps the margin along each interval's motion (rows at
    configurations between the knots, :mod:`mbplan.residuals.base`); False constrains the
    knots only, as the RIPM paper does. Those rows read the velocities, which the first
    iterates change by more than the knots: capped at ``margin + interval_activation``. On the
    UR5 shelf (``N = 40``) IPOPT did not converge in 300 iterations with their cap at 0.3 m, and
    converged in 57 at 1 m (39 and 52 at ``N = 20, 30``)."""

    sense: ClassVar[str] = "ineq"
    cost: ClassVar[bool] = False
    is_obstacle: ClassVar[bool] = True
    margin: float = 0.0
    objects: tuple[str, ...] | None = None
    geometry: str = "convex"
    activation: float = 0.3
    between_knots: bool = True
    interval_activation: float = 1.0

    def resolve(self, robot: Any, scene: Any) -> Residual:
        margin = as_real(self.margin, "Distance.margin")
        activation = as_real(self.activation, "Distance.activation", positive=True)
        between = as_bool(self.between_knots, "Distance.between_knots")
        interval = as_real(self.interval_activation, "Distance.interval_activation", positive=True)
        if self.geometry not in GEOMETRIES:
            raise InputError(
                f"Distance.geometry must be one of {GEOMETRIES}, got {self.geometry!r}"
            )
        if robot.collision_model is None or not any(
            g.parentJoint > 0 for g in robot.collision_model.geometryObjects
        ):
            raise InputError(
                f"Distance: robot {robot.name!r} has no collision geometry on a moving link "
                "(pass collision_model= with a pinocchio.Model)"
            )
        names = scene.names if self.objects is None else list(self.objects)
        for n in names:
            scene[n]
        if not names:
            raise InputError("Distance: the scene has no objects")
        resolved = replace(
            self,
            margin=margin,
            objects=tuple(names),
            activation=activation,
            between_knots=between,
            interval_activation=interval,
        )
        distance_pairs(
            robot, scene, resolved.objects, self.geometry
        )  # bad geometry: before a solve
        return resolved

    def dim(self, robot: Any, scene: Any) -> int:
        n = sum(g.parentJoint > 0 for g in robot.collision_model.geometryObjects)
        return n * len(self.objects or ())

    def joint_space(self, robot: Any, scene: Any) -> DistanceRows:
        return DistanceRows(robot, scene, self)

    def between_knots_form(self) -> Distance:
        """This residual as its rows between knots evaluate it (their own cap)."""
        return replace(self, activation=self.interval_activation)

    def row_label(self, robot: Any, scene: Any, row: int) -> str:
        pairs = distance_pairs(robot, scene, self.objects, self.geometry)
        geometry = pairs.names[row].split("/")[0]
        obj = self.objects[int(pairs.obstacle[row])]
        return f"geometry {geometry!r} and scene object {obj!r}"

    def start_violation(self, robot: Any, scene: Any, row: int, value: float) -> str:
        distance = f" (distance {self.margin - value:.4f} m, margin {self.margin:g} m)"
        return super().start_violation(robot, scene, row, value) + distance

    def maximal_terms(self, ctx: Any, item: Any) -> list[Term]:
        mm = ctx.mm
        pairs = distance_pairs(ctx.ocp.robot, ctx.ocp.scene, self.objects, self.geometry)
        bodies = pair_bodies(mm, pairs)
        k, i = (a.ravel() for a in np.meshgrid(item.knots, np.arange(pairs.size), indexing="ij"))
        sites = k * mm.nb + bodies[i]
        fn = distance_constraint_function(mm, pairs, self.activation)
        bind = {"R": ("R", sites), "p": ("p", sites)}
        params = {"pair": i.astype(float), "margin": self.margin}
        terms = [Term(item.name, "ineq", fn, bind, params)]
        if not self.between_knots:
            return terms
        k, s = interval_samples(item.knots)
        j, i = (
            a.ravel() for a in np.meshgrid(np.arange(k.size), np.arange(pairs.size), indexing="ij")
        )
        sites = k[j] * mm.nb + bodies[i]
        fn = interval_distance_function(mm, pairs, self.interval_activation, ctx.jit)
        bind = {n: (n, sites) for n in ("R", "p", "F", "v")}
        params = {"pair": i.astype(float), "margin": self.margin, "s": s[j], "dt": ctx.ocp.dt}
        return [*terms, Term(f"{item.name}/between_knots", "ineq", fn, bind, params)]

    def shooting(self, ctx: Any, item: Any) -> ShootingResidual:
        self.knots_only("shooting")
        model = ctx.coal_distance(self)
        return ShootingResidual(  # r = d (the signed distance) ≥ margin
            model, np.full(model.nr, self.margin), np.full(model.nr, np.inf), ctx.obstacle_weight
        )

    def clearance(
        self, robot: Any, scene: Any, path: np.ndarray, evaluate: Callable | None
    ) -> float:
        """The smallest distance along ``path``, uncapped (no activation distance)."""
        return float(np.min(self.margin - evaluate(replace(self, activation=np.inf), path)))
