"""Maximal coordinates of a free body: one rigid body on SO(3)×R³ with the forced LGVI, for the
RIPM (RIPM paper §VIII.B).

Knots ``k = 0..N`` carry ``(R_k, p_k, F_k, v_k)`` (knot 0 fixed to the OCP's initial state),
intervals ``k = 0..N-1`` the input ``u_k``; step ``k`` is
:func:`mbplan.dynamics.free_body_step` (eq. 30–35, 60). Each OCP item is one :class:`Term`: its
residual (:meth:`mbplan.residuals.Residual.body_rows`) at its knots, ``½ w ‖r‖²`` as a
cost. The items of one residual kind and role share one :class:`Term`, and the costs of one
space (state or input) one summed term: fewer kernel calls per iteration, the same sums.
"""

from __future__ import annotations

import hashlib
import time
from functools import cache
from typing import Any

import casadi as cs
import numpy as np

from mbplan.dynamics import free_body_step
from mbplan.engine import RiemannianFunction
from mbplan.errors import InputError
from mbplan.lie import SO3, R
from mbplan.ocp.problem import OCP, Item
from mbplan.ocp.scene import Scene
from mbplan.residuals.base import Residual
from mbplan.robots.free_body import FreeBody, body_state, free_flyer_state, path_state
from mbplan.transcription.terms import Term
from mbplan.transcription.trajectory import TrajectoryProblem
from mbplan.transcription.variables import Block, Point, TrajectoryVariables
from mbplan.workspace import Workspace

STATE = (("R", SO3), ("p", R(3)), ("F", SO3), ("v", R(3)))


def parameter_shapes(residual: Residual, scene: Scene) -> list[tuple[str, Any]]:
    """``(name, shape)`` of the residual's body parameters (a vector's length as an int)."""
    shapes = ((k, np.shape(v)) for k, v in residual.body_parameters(scene).items())
    return [(k, s[0] if len(s) == 1 else s) for k, s in shapes]


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def _step_function(actuation: bytes, nu: int, jit: bool) -> RiemannianFunction:
    """The LGVI step with the actuation map ``B`` a constant (its zeros are structural: the
    Jacobian and Hessian keep the sparsity of the map, e.g. eq. 60's thrust on ``u_z`` only)."""
    B = cs.DM(np.frombuffer(actuation).reshape(6, nu))
    variables = [(f"{n}{i}", g) for i in (0, 1) for n, g in STATE] + [("u", R(nu))]
    params = [("J", (3, 3)), ("mass", 1), ("gravity", 3), ("dt", 1)]

    def step(**args):
        return free_body_step(**args, B=cs.sparsify(B))

    name = f"free_body_step_{hashlib.sha1(actuation).hexdigest()[:10]}"
    return RiemannianFunction(name, variables, step, params, jit=jit)


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def _item_function(kind: type, shapes: tuple, cost: bool, nu: int, jit: bool) -> RiemannianFunction:
    """The residual ``kind`` (or its cost ``½ w ‖r‖²``) on the state or the input."""
    control = kind.space == "control"
    variables = [("u", R(nu))] if control else list(STATE)

    def fn(w=None, **args):
        x = {n: args.pop(n) for n in [v for v, _ in variables]}
        r = kind.body_rows(x, args)
        return 0.5 * w * cs.sumsqr(r) if cost else r

    params = list(shapes) + ([("w", 1)] if cost else [])
    name = f"body_{kind.__name__}_{'cost' if cost else 'constraint'}"
    return RiemannianFunction(name, variables, fn, params, jit=jit)


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def _cost_function(slots: tuple, space: str, nu: int, jit: bool) -> RiemannianFunction:
    """``Σ_j ½ w_j ‖r_j‖²`` of the residual kinds ``slots = ((kind, shapes), …)`` (parameters
    of slot ``j`` prefixed ``j_``): the costs of one space in one kernel call per iteration."""
    variables = [("u", R(nu))] if space == "control" else list(STATE)

    def fn(**args):
        x = {n: args[n] for n, _ in variables}
        total = 0
        for j, (kind, shapes) in enumerate(slots):
            r = kind.body_rows(x, {name: args[f"{j}_{name}"] for name, _ in shapes})
            total += 0.5 * args[f"{j}_w"] * cs.sumsqr(r)
        return total

    params = [(f"{j}_{n}", shape) for j, (_, shapes) in enumerate(slots) for n, shape in shapes]
    params += [(f"{j}_w", 1) for j in range(len(slots))]
    name = "body_costs_" + "_".join(kind.__name__ for kind, _ in slots)
    return RiemannianFunction(name, variables, fn, params, jit=jit)


class FreeBodyNLP:
    """The TrajectoryProblem of a free-body ``ocp`` (module docstring)."""

    def __init__(self, ocp: OCP, jit: bool, workspace: Workspace | None = None):
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
        }
        step = _step_function(np.ascontiguousarray(body.actuation).tobytes(), body.nu, jit)
        terms = [Term.at_knots("dynamics", "eq", step, bind, range(N), dynamics)]
        groups: dict[tuple, list[Item]] = {}
        for item in ocp.items:
            r = item.residual
            key = (type(r), item.role, tuple(parameter_shapes(r, ocp.scene)))
            groups.setdefault(key, []).append(item)
        for space in ("state", "control"):  # the costs of a space as one term
            costs = [k for k in groups if k[1] == "cost" and k[0].space == space]
            knots = [np.concatenate([i.knots for i in groups[k]]) for k in costs]
            if len(costs) > 1 and all(len(np.unique(k)) == len(k) for k in knots):
                terms.append(self._cost_term(space, [(k, groups.pop(k)) for k in costs]))
        for (kind, role, shapes), items in groups.items():
            try:
                terms.append(self._term(kind, role == "cost", shapes, items))
            except InputError as err:
                names = [i.name for i in items]
                raise InputError(f"maximal formulation, {role} {names}: {err}") from None
        self.problem = TrajectoryProblem(variables, terms, workspace)

    def _per_site(self, shapes: tuple, items: list[Item]) -> tuple[np.ndarray, dict]:
        """The knots of ``items`` concatenated and their parameters and weights per site."""
        knots = np.concatenate([i.knots for i in items])
        params: dict[str, np.ndarray] = {}
        for name, shape in shapes:
            shape = shape if isinstance(shape, tuple) else (shape,)
            params[name] = np.concatenate(
                [
                    np.broadcast_to(
                        i.residual.body_parameters(self.ocp.scene)[name], (len(i.knots), *shape)
                    )
                    for i in items
                ]
            )
        params["w"] = np.concatenate([np.full(len(i.knots), i.weight) for i in items])
        return knots, params

    def _cost_term(self, space: str, groups: list[tuple[tuple, list[Item]]]) -> Term:
        """One term for all cost groups of ``space`` at the union of their knots (weight 0 at
        a knot a group does not cost; the same sums)."""
        per = [self._per_site(shapes, items) for (_, _, shapes), items in groups]
        union = np.unique(np.concatenate([k for k, _ in per]))
        params: dict[str, np.ndarray] = {}
        for j, (knots, values) in enumerate(per):
            at = np.searchsorted(union, knots)
            for name, value in values.items():
                full = np.repeat(value[:1], len(union), axis=0)
                full[at] = value
                if name == "w":
                    full[np.setdiff1d(np.arange(len(union)), at)] = 0.0
                params[f"{j}_{name}"] = full
        slots = tuple((kind, shapes) for (kind, _, shapes), _ in groups)
        fn = _cost_function(slots, space, self.ocp.robot.nu, self.jit)
        names = ["u"] if space == "control" else [n for n, _ in STATE]
        name = "+".join(i.name for _, items in groups for i in items)
        return Term(name, "cost", fn, {n: (n, union) for n in names}, params)

    def _term(self, kind: type, cost: bool, shapes: tuple, items: list[Item]) -> Term:
        """One term for the items of one residual kind and role (e.g. a running and a
        terminal cost): their knots concatenated, targets and weights per site (fewer kernel
        calls per iteration; the same sums)."""
        fn = _item_function(kind, shapes, cost, self.ocp.robot.nu, self.jit)
        knots, params = self._per_site(shapes, items)
        if not cost:
            del params["w"]
        names = ["u"] if kind.space == "control" else [n for n, _ in STATE]
        bind = {n: (n, knots) for n in names}
        sense = "cost" if cost else kind.sense
        return Term("+".join(i.name for i in items), sense, fn, bind, params)

    def initial_point(self, q_path: np.ndarray, inputs: str | None = None) -> Point:
        """The point along a pose path ``q_path (N+1, 7)`` (:func:`path_state`) with the
        :func:`warm_start_inputs` of kind ``inputs``."""
        ocp = self.ocp
        point = path_state(q_path, ocp.q0, ocp.v0, ocp.dt)
        point["u"] = warm_start_inputs(ocp, point, inputs)
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


WARM_START_INPUTS = "inverse"
"""The default kind of :func:`warm_start_inputs` (fewer RIPM iterations on the drone than the hover input)."""
BOUND_PUSH = BOUND_FRAC = 0.01
"""How far inside the input limits warm-start inputs stay, at both bounds:
``min(BOUND_FRAC (upper - lower), BOUND_PUSH max(1, |lower|))`` (IPOPT's
``bound_push``/``bound_frac`` rule, scaled by the lower bound's magnitude at both ends)."""


def warm_start_inputs(ocp: OCP, point: Point, inputs: str | None = None) -> np.ndarray:
    """Inputs ``(N, nu)`` of a warm start ``point`` (its state): ``"hover"`` (the hover input
    everywhere) or ``"inverse"`` (:func:`lgvi_inputs`, clipped strictly inside the tightest
    input limits of :func:`input_bounds`); default :data:`WARM_START_INPUTS`."""
    inputs = WARM_START_INPUTS if inputs is None else inputs
    if inputs == "hover":
        return np.tile(ocp.robot.hover_input, (ocp.N, 1))
    if inputs != "inverse":
        raise InputError(f"warm-start inputs: expected 'hover' or 'inverse', got {inputs!r}")
    lower, upper = input_bounds(ocp)
    push = np.minimum(BOUND_FRAC * (upper - lower), BOUND_PUSH * np.maximum(1.0, np.abs(lower)))
    push = np.where(np.isfinite(push), push, 0.0)
    return np.clip(lgvi_inputs(ocp.robot, ocp.dt, point), lower + push, upper - push)


def lgvi_inputs(body: FreeBody, dt: float, point: Point) -> np.ndarray:
    """Inputs ``u_k`` (``k < N``) of the forced LGVI steps between the knots of ``point``: the
    least-squares ``u`` of ``B u = (f, τ)`` with the body wrench that eq. (34)–(35), (60) need,
    ``τ_k = (F_{k+1}J - JF_{k+1}ᵀ - JF_k + F_kᵀJ)^∨ / Δt²`` and
    ``f_k = R_{k+1}ᵀ (m (v_{k+1} - v_k) / Δt - m g)`` (exact where ``B`` spans the wrench)."""
    R, F, v = (np.asarray(point[n], dtype=float) for n in ("R", "F", "v"))
    J = body.nonstandard_inertia
    F0, F1 = F[:-1], F[1:]
    skew = F1 @ J - J @ np.swapaxes(F1, 1, 2) - J @ F0 + np.swapaxes(F0, 1, 2) @ J
    torque = np.stack([skew[:, 2, 1], skew[:, 0, 2], skew[:, 1, 0]], axis=1) / dt**2
    world = body.mass * (np.diff(v, axis=0) / dt - body.gravity)
    force = np.einsum("kji,kj->ki", R[1:], world)
    wrench = np.hstack([force, torque])
    return np.linalg.lstsq(body.actuation, wrench.T, rcond=None)[0].T


def input_bounds(ocp: OCP) -> tuple[np.ndarray, np.ndarray]:
    """The tightest ``lower, upper`` (nu,) of the OCP's input-limit constraints (±inf without)."""
    nu = ocp.robot.nu
    lower, upper = np.full(nu, -np.inf), np.full(nu, np.inf)
    for item in ocp.constraints:
        bounds = item.residual.variable_bounds(ocp.robot)
        if bounds is not None and bounds[0] == "u":
            lower, upper = np.maximum(lower, bounds[1]), np.minimum(upper, bounds[2])
    return lower, upper


def build(ocp: OCP, jit: bool, workspace: Workspace | None = None) -> tuple[FreeBodyNLP, float]:
    """:class:`FreeBodyNLP` of ``ocp`` (its structures kept in ``workspace``) and the build
    time (s)."""
    t0 = time.perf_counter()
    return FreeBodyNLP(ocp, jit, workspace), time.perf_counter() - t0


# process-wide cache, result-neutral: compiled from its symbolic key alone
@cache
def _numeric(kind: type, shapes: tuple, nu: int) -> cs.Function:
    x = {"R": cs.SX.sym("R", 3, 3), "p": cs.SX.sym("p", 3), "F": cs.SX.sym("F", 3, 3)}
    x |= {"v": cs.SX.sym("v", 3), "u": cs.SX.sym("u", nu)}
    P = {k: cs.SX.sym(k, *(s if isinstance(s, tuple) else (s, 1))) for k, s in shapes}
    r = kind.body_rows(x, P)
    inputs = list(x.values()) + list(P.values())
    return cs.Function(f"body_{kind.__name__}", inputs, [r])


def evaluate_body(
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
    params = residual.body_parameters(scene)
    fn = _numeric(type(residual), tuple(parameter_shapes(residual, scene)), body.nu)
    if residual.space == "control":
        u = np.atleast_2d(u)
        K = len(u)
        x = {"R": np.eye(3), "p": np.zeros(3), "F": np.eye(3), "v": np.zeros(3)}
        states = [x | {"u": u[k]} for k in range(K)]
    else:
        if residual.steps and dt is None:
            raise InputError(f"{type(residual).__name__}: evaluating the rotation step needs dt")
        s = body_state(q, np.zeros((len(np.atleast_2d(q)), 6)) if v is None else v, dt or 1.0)
        K = len(s["R"])
        states = [
            {"R": s["R"][k], "p": s["p"][k], "F": s["F"][k], "v": s["v"][k], "u": np.zeros(body.nu)}
            for k in range(K)
        ]
    rows = [np.array(fn(*x.values(), *params.values())).ravel() for x in states]
    return np.array(rows).reshape(K, -1)
