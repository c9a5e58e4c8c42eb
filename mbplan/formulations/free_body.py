"""Maximal coordinates of a free body: one rigid body on SO(3)×R³ with the forced LGVI, for the
RIPM (RIPM paper §VIII.B).

Knots ``k = 0..N`` carry ``(R_k, p_k, F_k, v_k)`` (knot 0 fixed to the OCP's initial state),
intervals ``k = 0..N-1`` the input ``u_k``; step ``k`` is
:func:`mbplan.dynamics.free_body_step` (eq. 30–35, 60). Each OCP item is one :class:`Term`: its
residual (:func:`mbplan.ocp.body_residuals.body_expression`) at its knots, ``½ w ‖r‖²`` as a
cost.
"""

from __future__ import annotations

import time
from functools import cache

import casadi as cs
import numpy as np

from mbplan.dynamics import free_body_step
from mbplan.engine import RiemannianFunction
from mbplan.errors import InputError
from mbplan.lie import SO3, R
from mbplan.ocp.body_residuals import body_expression, body_parameters, parameter_shapes
from mbplan.ocp.free_body import free_flyer_state, path_state
from mbplan.ocp.problem import OCP, Item
from mbplan.transcription.problem import TrajectoryProblem
from mbplan.transcription.terms import Term
from mbplan.transcription.variables import Block, Point, TrajectoryVariables

STATE = (("R", SO3), ("p", R(3)), ("F", SO3), ("v", R(3)))


@cache
def _step_function(nu: int, jit: bool) -> RiemannianFunction:
    variables = [(f"{n}{i}", g) for i in (0, 1) for n, g in STATE] + [("u", R(nu))]
    params = [("J", (3, 3)), ("mass", 1), ("gravity", 3), ("dt", 1), ("B", (6, nu))]
    return RiemannianFunction("free_body_step", variables, free_body_step, params, jit=jit)


@cache
def _item_function(kind: type, shapes: tuple, cost: bool, nu: int, jit: bool) -> RiemannianFunction:
    """The residual ``kind`` (or its cost ``½ w ‖r‖²``) on the state or the input."""
    control = kind.space == "control"
    variables = [("u", R(nu))] if control else list(STATE)

    def fn(w=None, **args):
        x = {n: args.pop(n) for n in [v for v, _ in variables]}
        r = body_expression(kind, x, args)
        return 0.5 * w * cs.sumsqr(r) if cost else r

    params = list(shapes) + ([("w", 1)] if cost else [])
    name = f"body_{kind.__name__}_{'cost' if cost else 'constraint'}"
    return RiemannianFunction(name, variables, fn, params, jit=jit)


class FreeBodyNLP:
    """The TrajectoryProblem of a free-body ``ocp`` (module docstring)."""

    def __init__(self, ocp: OCP, jit: bool):
        self.ocp, self.jit = ocp, jit
        body, N = ocp.robot, ocp.N
        variables = TrajectoryVariables(
            [Block(n, g, N + 1, fixed=(0,)) for n, g in STATE] + [Block("u", R(body.nu), N)]
        )
        bind = {f"{n}{i}": (n, i) for i in (0, 1) for n, _ in STATE} | {"u": ("u", 0)}
        dynamics = {
            "J": body.nonstandard_inertia,
            "mass": body.mass,
            "gravity": body.gravity,
            "dt": ocp.dt,
            "B": body.actuation,
        }
        step = _step_function(body.nu, jit)
        terms = [Term.at_knots("dynamics", "eq", step, bind, range(N), dynamics)]
        for item in ocp.items:
            try:
                terms.append(self._term(item))
            except InputError as err:
                raise InputError(f"maximal formulation, {item.role} {item.name!r}: {err}") from None
        self.problem = TrajectoryProblem(variables, terms)

    def _term(self, item: Item) -> Term:
        r, cost = item.residual, item.role == "cost"
        params = body_parameters(r, self.ocp.scene)
        shapes = tuple(parameter_shapes(r, self.ocp.scene))
        fn = _item_function(type(r), shapes, cost, self.ocp.robot.nu, self.jit)
        names = ["u"] if r.space == "control" else [n for n, _ in STATE]
        bind = {n: (n, 0) for n in names}
        params = params | ({"w": item.weight} if cost else {})
        return Term.at_knots(item.name, "cost" if cost else r.sense, fn, bind, item.knots, params)

    def initial_point(self, q_path: np.ndarray) -> Point:
        """The point along a pose path ``q_path (N+1, 7)`` (:func:`path_state`), hover input."""
        ocp = self.ocp
        point = path_state(q_path, ocp.q0, ocp.v0, ocp.dt)
        point["u"] = np.tile(ocp.robot.hover_input, (ocp.N, 1))
        return self.problem.check_point(point)

    def trajectory(self, x: Point) -> dict:
        """PlanResult fields of a point: ``q, v`` (free flyer), ``tau = u``, ``R, p``."""
        q, v = free_flyer_state(x["R"], x["p"], x["F"], x["v"], self.ocp.dt)
        return {
            "q": q,
            "v": v,
            "tau": np.array(x["u"]),
            "R": x["R"][:, None],
            "p": x["p"][:, None],
            "body_names": (self.ocp.robot.name,),
        }


def build(ocp: OCP, jit: bool) -> tuple[FreeBodyNLP, float]:
    """:class:`FreeBodyNLP` of ``ocp`` and the build time (s)."""
    t0 = time.perf_counter()
    return FreeBodyNLP(ocp, jit), time.perf_counter() - t0
