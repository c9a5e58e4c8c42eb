"""A free-body :class:`~mbplan.OCP` as a shooting problem for SS-/MS-iLQR.

The state is the LGVI knot ``x_k = (R_k, p_k, F_k, v_k)`` of the RIPM's maximal formulation
(:func:`~mbplan.shooting.models.free_body_lgvi`, RIPM paper eq. 30–35, 60), the input ``u_k``
is held over ``[t_k, t_{k+1}]``. The cost is the OCP's: ``Σ ½ w ‖r(x_k)‖²`` of every state cost
at its knots plus ``Σ ½ w ‖r(u_k)‖²`` of every input cost on its intervals, each residual
its :meth:`~mbplan.residuals.base.Residual.body_rows`, with Gauss–Newton derivatives along
``x ⊕ δx`` (thesis §3-1: ``l_x = J̃ᵀr̃``, ``l_xx ≈ J̃ᵀJ̃`` for the stacked ``r̃ = √w r``;
``l_ux = 0``). Input limits (:class:`~mbplan.residuals.body.BodyInputLimits`) become the
bounds of the augmented-Lagrangian outer loop (thesis Alg. 3); a shooting method cannot impose
any other hard constraint, so :func:`check_shooting_ocp` refuses those before any solve.
"""

from __future__ import annotations

import casadi as cs
import numpy as np

from mbplan.errors import InputError
from mbplan.formulations.free_body import parameter_shapes, warm_start_inputs
from mbplan.lie import R
from mbplan.ocp.problem import OCP, Item
from mbplan.robots.free_body import FreeBody, body_state, free_flyer_state, path_state
from mbplan.shooting.compiled import BufferedFunction
from mbplan.shooting.models import FREE_BODY_SPACE, free_body_lgvi
from mbplan.shooting.problem import ShootingBase
from mbplan.shooting.space import StateSpace

STATE_NAMES = ("R", "p", "F", "v")


def check_shooting_ocp(ocp: OCP, method: str) -> None:
    """:class:`InputError` unless ``method`` (a shooting method) can plan ``ocp``: a free body
    whose only hard constraints are input limits."""
    if not isinstance(ocp.robot, FreeBody):
        raise InputError(
            f"{method} plans free bodies (mbplan.FreeBody) only; robot {ocp.robot.name!r} is a "
            "multi-body robot: use ripm, ipopt, fddp or csqp"
        )
    for item in ocp.constraints:
        if not item.residual.input_limits:
            raise InputError(
                f"{method} cannot impose constraint {item.name!r} "
                f"({type(item.residual).__name__}): a shooting method keeps only input limits "
                "(BodyInputLimits) as hard constraints; remove it or plan with ripm or ipopt"
            )


def _slots(items: list[Item], ocp: OCP) -> list[list[Item]]:
    """``items`` in groups of one residual kind and parameter shapes with disjoint knots: each
    group is one residual block, its targets and weights per knot."""
    slots: list[tuple[tuple, set[int], list[Item]]] = []
    for item in items:
        key = (type(item.residual), tuple(parameter_shapes(item.residual, ocp.scene)))
        knots = set(item.knots.tolist())
        for slot_key, used, members in slots:
            if slot_key == key and not used & knots:
                used |= knots
                members.append(item)
                break
        else:
            slots.append((key, knots, [item]))
    return [members for _, _, members in slots]


class _LeastSquares:
    """``Σ_k ½ ‖r̃(z_k, P_k)‖²`` of the residual blocks ``slots`` at ``K`` knots, ``z`` the state
    (on :data:`FREE_BODY_SPACE`) or the input, ``r̃`` the blocks ``√w r`` stacked, compiled with
    the Gauss–Newton gradient ``J̃ᵀr̃`` and Hessian ``J̃ᵀJ̃`` along ``z ⊕ δz``."""

    def __init__(self, ocp: OCP, slots: list[list[Item]], control: bool, K: int, jit: bool):
        space = StateSpace([R(ocp.robot.nu)]) if control else FREE_BODY_SPACE
        z, dz = cs.SX.sym("z", space.nq), cs.SX.sym("dz", space.nx)
        blocks: list[tuple[type, dict[str, cs.SX], cs.SX]] = []
        columns: list[np.ndarray] = []
        for j, items in enumerate(slots):
            shapes = parameter_shapes(items[0].residual, ocp.scene)
            P = {
                n: cs.SX.sym(f"{j}_{n}", *(s if isinstance(s, tuple) else (s, 1)))
                for n, s in shapes
            }
            blocks.append((type(items[0].residual), P, cs.SX.sym(f"{j}_sqrt_w")))
            columns.append(_parameters(ocp, items, [n for n, _ in shapes], K))
        flat = [cs.vec(a) for _, P, sw in blocks for a in (*P.values(), sw)]

        def residual(zs: cs.SX) -> cs.SX:
            parts = space.sym_unpack(zs)
            x = {"u": parts[0]} if control else dict(zip(STATE_NAMES, parts, strict=True))
            return cs.vertcat(cs.SX(0, 1), *[sw * k.body_rows(x, P) for k, P, sw in blocks])

        r = residual(z)
        Jr = cs.jacobian(residual(space.sym_retract(z, dz, second_order=True)), dz)
        Jr = cs.substitute(Jr, dz, cs.DM.zeros(space.nx))
        params = cs.vertcat(cs.SX.sym("unused"), *flat)  # never empty
        value = 0.5 * cs.sumsqr(r)
        outputs = [value, cs.densify(cs.mtimes(Jr.T, r)), cs.densify(cs.vec(cs.mtimes(Jr.T, Jr)))]
        self.P = np.hstack([np.zeros((K, 1)), *columns])
        self.n = space.nx
        fns = (
            cs.Function("least_squares_value", [z, params], [value]),
            cs.Function("least_squares_derivatives", [z, params], outputs),
        )
        self._value, self._derivs = (BufferedFunction(f.map(K, "serial"), jit=jit) for f in fns)

    def value(self, Z: np.ndarray) -> float:
        return float(np.sum(self._value(Z, self.P)[0]))

    def derivatives(self, Z: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """Total value, gradients ``(K, n)`` and Hessians ``(K, n, n)``."""
        l, g, H = self._derivs(Z, self.P)
        return float(np.sum(l)), g, H.reshape(len(Z), self.n, self.n)


def _parameters(ocp: OCP, items: list[Item], names: list[str], K: int) -> np.ndarray:
    """``(K, n_P)``: each item's parameters (matrices column-major) and ``√w`` at its knots
    (state knots ``k``, intervals ``k``), the first item's parameters and ``√w = 0`` elsewhere."""
    rows = np.empty(0)
    for i, item in enumerate(items):
        values = item.residual.body_parameters(ocp.scene)
        row = np.concatenate([np.ravel(values[n], order="F") for n in names])
        if i == 0:
            rows = np.tile(np.r_[row, 0.0], (K, 1))
        rows[item.knots] = np.r_[row, np.sqrt(item.weight)]
    return rows


class FreeBodyShooting(ShootingBase):
    """The shooting problem of a free-body ``ocp`` (module docstring) from ``x0`` (the OCP's
    initial state); ``x_ref`` holds the states of the warm start ``q_guess (N+1, 7)``
    (:func:`~mbplan.robots.free_body.path_state`), ``lower``/``upper`` ``(N, nu)`` the input limits
    (``±inf`` where none)."""

    def __init__(self, ocp: OCP, q_guess: np.ndarray, method: str, jit: bool) -> None:
        check_shooting_ocp(ocp, method)
        body, N = ocp.robot, ocp.N
        self.ocp = ocp
        self.dynamics = free_body_lgvi("free_body_lgvi", body, ocp.dt, jit=jit)
        start = body_state(ocp.q0, ocp.v0, ocp.dt)
        self.x0 = FREE_BODY_SPACE.pack([start[n][0] for n in STATE_NAMES])
        guess = path_state(q_guess, ocp.q0, ocp.v0, ocp.dt)
        self.x_ref = FREE_BODY_SPACE.pack([guess[n] for n in STATE_NAMES])
        self.u_guess = warm_start_inputs(ocp, guess)
        costs = {s: [i for i in ocp.costs if i.residual.space == s] for s in ("state", "control")}
        self._state = _LeastSquares(ocp, _slots(costs["state"], ocp), False, N + 1, jit)
        self._input = _LeastSquares(ocp, _slots(costs["control"], ocp), True, N, jit)
        self.lower, self.upper = np.full((N, body.nu), -np.inf), np.full((N, body.nu), np.inf)
        for item in ocp.constraints:  # BodyInputLimits only (check_shooting_ocp)
            r = item.residual
            self.lower[item.knots] = np.maximum(self.lower[item.knots], r.lower)
            self.upper[item.knots] = np.minimum(self.upper[item.knots], r.upper)

    def cost_value(self, X: np.ndarray, U: np.ndarray) -> float:
        return self._state.value(X) + self._input.value(U)

    def cost_derivatives(
        self, X: np.ndarray, U: np.ndarray
    ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        Jx, lx, lxx = self._state.derivatives(X)
        Ju, lu, luu = self._input.derivatives(U)
        return Jx + Ju, lx, lxx, lu, luu

    def trajectory(self, X: np.ndarray, U: np.ndarray) -> dict:
        """:class:`~mbplan.results.PlanResult` fields of a trajectory: ``q, v`` (free flyer),
        ``tau = u``, ``R, p``, ``body_names``."""
        R_, p, F, v = FREE_BODY_SPACE.unpack(X)
        q, v = free_flyer_state(R_, p, F, v, self.ocp.dt)
        return {
            "q": q,
            "v": v,
            "tau": np.array(U),
            "R": R_[:, None],
            "p": p[:, None],
            "body_names": (self.ocp.robot.name,),
        }
