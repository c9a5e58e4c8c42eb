"""The residual protocol: a residual kind defined outside the library plans with the RIPM and
IPOPT and verifies, with no edit to any formulation; every residual kind of the library, through
every formulation that expresses it, against finite differences."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as cs
import numpy as np
import pytest
from fd import check_generalized_derivatives
from test_free_body import factory_ocp as free_body_ocp
from test_ocp import factory_ocp, panda_ocp

import mbplan as mb
from mbplan.engine import RiemannianFunction
from mbplan.engine.checks import check_derivatives
from mbplan.formulations.free_body import FreeBodyNLP
from mbplan.formulations.generalized import GeneralizedNLP
from mbplan.formulations.joint_space import evaluate
from mbplan.formulations.maximal import MaximalNLP
from mbplan.lie import SO3, R
from mbplan.planning.initial_guess import initial_path
from mbplan.residuals import Distance
from mbplan.residuals.base import RESIDUALS, Residual, SymbolicRows
from mbplan.transcription.terms import Term


@dataclass(frozen=True, eq=False)
class FrameAbovePlane(Residual):
    """``nᵀ p_frame - offset``: the signed distance of a frame's origin to a plane (a cost
    ``½ w (nᵀ p - d)²``), written here only."""

    frame: str = ""
    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    offset: float = 0.0

    def dim(self, robot: Any, scene: Any) -> int:
        return 1

    def joint_space(self, robot: Any, scene: Any) -> SymbolicRows:
        theta = np.r_[self.normal, self.offset]
        return SymbolicRows((type(self), self.frame), theta, self._rows)

    def _rows(self, ctx) -> cs.SX:
        frame = ctx.robot.model.frames[ctx.robot.frame_id(self.frame)]
        Rj, pj = ctx.placements()[frame.parentJoint]
        p = pj + cs.mtimes(Rj, cs.DM(frame.placement.translation))
        return cs.dot(ctx.theta[:3], p) - ctx.theta[3]

    def maximal_terms(self, ctx: Any, item: Any) -> list[Term]:
        robot = ctx.ocp.robot
        frame = robot.model.frames[robot.frame_id(self.frame)]
        b = ctx.body_of_joint[int(frame.parentJoint)]
        params = {
            "c": frame.placement.translation - ctx.mm.com_in_joint[b],
            "n": np.asarray(self.normal, dtype=float),
            "d": self.offset,
            "w": item.weight,
        }
        fn = RiemannianFunction(
            "frame_above_plane",
            [("Rb", SO3), ("pb", R(3))],
            lambda Rb, pb, c, n, d, w: 0.5 * w * (cs.dot(n, pb + cs.mtimes(Rb, c)) - d) ** 2,
            [("c", 3), ("n", 3), ("d", 1), ("w", 1)],
            jit=ctx.jit,
        )
        sites = item.knots * ctx.mm.nb + b
        return [Term(item.name, "cost", fn, {"Rb": ("R", sites), "pb": ("p", sites)}, params)]


@dataclass(frozen=True, eq=False)
class JointSpaceOnly(FrameAbovePlane):
    """The same residual without a maximal-coordinate translation."""

    maximal_terms = Residual.maximal_terms


def plane_ocp(residual: Residual) -> mb.OCP:
    ocp = mb.OCP("iiwa", N=6, dt=0.075, q0=mb.tasks.paper.IIWA_START)
    ocp.add_cost("v", mb.residuals.JointVelocity(), 1e-2)
    ocp.add_cost("tau", mb.residuals.JointTorque(), 1e-4)
    ocp.add_terminal_cost("plane", residual, 10.0)
    return ocp


@pytest.mark.parametrize("method", ["ripm", "ipopt"])
def test_a_residual_defined_outside_the_library_plans_and_verifies(method: str) -> None:
    plane = FrameAbovePlane("iiwa_link_7", (0.0, 0.0, 1.0), 0.9)
    ocp = plane_ocp(plane)
    residual = ocp["plane"].residual
    start = evaluate(ocp.robot, ocp.scene, residual, ocp.q0[None], ocp.v0[None], None)[0, 0]
    result = mb.plan(ocp, method, jit=False)
    assert result.success, result.message
    assert mb.verify(ocp, result).passed
    end = evaluate(ocp.robot, ocp.scene, residual, result.q[-1:], result.v[-1:], None)[0, 0]
    assert abs(end) < 0.5 * abs(start)


def test_both_formulations_write_a_residual_defined_outside_the_library_alike() -> None:
    ocp = plane_ocp(FrameAbovePlane("iiwa_link_7", (0.3, 0.0, 0.9), 0.4))
    nlp = MaximalNLP(ocp, jit=False)
    q = np.linspace(ocp.q0, np.zeros(7), ocp.N + 1)
    x = nlp.initial_point(q)
    item = ocp["plane"]
    r = evaluate(ocp.robot, ocp.scene, item.residual, q[-1:], q[-1:], None)[0, 0]
    term = next(t for t in nlp.problem.terms if t.name == "plane")
    flat = {n: nlp.problem.variables.blocks[n].flat(a) for n, a in x.items()}
    value = term.function.value(term.gather(flat), term.parameters)
    np.testing.assert_allclose(np.ravel(value), 0.5 * item.weight * r**2, rtol=1e-9)


def test_a_residual_a_formulation_cannot_express_is_named_before_any_solve() -> None:
    ocp = plane_ocp(JointSpaceOnly("iiwa_link_7"))
    with pytest.raises(mb.InputError, match="JointSpaceOnly cannot be expressed in maximal"):
        mb.plan(ocp, "ripm", jit=False)
    body = free_body_ocp()
    with pytest.raises(mb.InputError, match="FrameAbovePlane is not a residual of a free body"):
        body.add_cost("plane", FrameAbovePlane("iiwa_link_7"))


def _library_kinds() -> list[str]:
    return sorted(n for n, c in RESIDUALS.items() if c.__module__.startswith("mbplan."))


def _factories() -> dict[str, mb.OCP]:
    return {"iiwa": factory_ocp(True), "panda": panda_ocp(), "free_body": free_body_ocp()}


def _only(ocp: mb.OCP, kind: str) -> mb.OCP:
    """``ocp`` with only its items of residual ``kind`` (and the robot's mimic couplings)."""
    out = mb.OCP(ocp.robot, ocp.scene, N=ocp.N, dt=ocp.dt, q0=ocp.q0, v0=ocp.v0)
    for i in ocp.items:
        if type(i.residual).__name__ == kind and i.name not in out.names:
            if i.role == "cost":
                out.add_cost(i.name, i.residual, i.weight, i.knots)
            else:
                out.add_constraint(i.name, i.residual, i.knots)
    return out


def test_the_factories_hold_every_residual_kind_of_the_library() -> None:
    """A new kind must join a factory OCP (tests/test_ocp.py, tests/test_free_body.py), which
    puts it through every formulation below."""
    held = {type(i.residual).__name__ for ocp in _factories().values() for i in ocp.items}
    assert set(_library_kinds()) <= held


@pytest.mark.parametrize("kind", _library_kinds())
def test_every_residual_kind_matches_finite_differences_in_every_formulation(kind: str) -> None:
    rng = np.random.default_rng(4)
    for name, factory in _factories().items():
        ocp = _only(factory, kind)
        if not ocp.items:
            continue
        if name == "free_body":
            nlp = FreeBodyNLP(ocp, jit=False)
            start = initial_path(ocp, "linear")
        else:
            nlp = MaximalNLP(ocp, jit=False)
            start = np.linspace(ocp.q0, ocp.q0 + 0.2, ocp.N + 1)
            gen = GeneralizedNLP(ocp)
            z = gen.initial_guess(start) + 0.05 * rng.standard_normal(gen.n)
            lam = rng.standard_normal(gen.m)
            for block in gen.own:  # coal's fixed witness points: tests/test_collision.py
                if isinstance(block.item.residual, Distance):
                    lam[block.row0 : block.row0 + block.size] = 0.0
            check_generalized_derivatives(gen, z, lam)
        prob = nlp.problem
        x = prob.retract(nlp.initial_point(start), 0.05 * rng.standard_normal(prob.n))
        flat = {n: b.flat(x[n]) for n, b in prob.variables.blocks.items()}
        for term in prob.terms:  # each term along X exp(tξ)
            item = term.name.removesuffix("/between_knots")
            if item in ocp.names or set(term.name.split("+")) <= set(ocp.names):
                variables = {n: a[term.sites - 1] for n, a in term.gather(flat).items()}
                params = _site_parameters(term, term.sites - 1)
                check = check_derivatives(term.function, variables, params, rng=rng)
                # coal distances: fixed-witness-point Hessian (tests/test_collision.py)
                exact = kind != "Distance"
                error = max(check.jacobian_error, check.hessian_error if exact else 0.0)
                assert error <= 1e-5, (name, term.name, check)


def _site_parameters(term: Term, site: int) -> dict:
    sizes = {spec.name: int(np.prod(spec.shape)) for spec in term.function.parameters}
    out = {}
    for name, value in term.parameters.items():
        a = np.asarray(value, dtype=float)
        per_site = a.ndim >= 1 and a.shape[0] == term.sites and a.size == term.sites * sizes[name]
        out[name] = a[site] if per_site else a
    return out
