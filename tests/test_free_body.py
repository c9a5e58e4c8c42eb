"""A free body on the OCP API: every body residual × both formulations against finite
differences (along the retraction on SO(3) in maximal coordinates), the drone docking task as
an OCP (the task's objective in both formulations, plans that verify), JSON and npz round trips,
bad input named before any solve."""

from __future__ import annotations

import json

import casadi as cs
import numpy as np
import pytest

import mbplan as mb
from mbplan import residuals as br
from mbplan import residuals as res
from mbplan.cli.main import main
from mbplan.engine.checks import check_derivatives
from mbplan.formulations.free_body import FreeBodyNLP, input_bounds, lgvi_inputs
from mbplan.formulations.quaternion import QuaternionNLP
from mbplan.lie import SO3
from mbplan.planning.initial_guess import initial_path
from mbplan.robots.free_body import FreeBody, body_state, free_flyer_state, quaternions
from mbplan.tasks import paper
from mbplan.tasks.drone import cluttered_task, sample_docking_cases, simulate, trajectory_cost
from mbplan.viz.drone import free_body_scene

GOAL_R = SO3.exp(np.array([0.3, -0.2, 0.5]))


def factory_ocp() -> mb.OCP:
    """Every body residual, as a cost and as a constraint where it can be one, on a free body
    with a general actuation map (5 inputs)."""
    B = np.random.default_rng(3).standard_normal((6, 5))
    body = FreeBody("box", 1.3, np.diag([0.02, 0.03, 0.04]), (0.0, 0.0, -9.81), B)
    scene = mb.Scene().add_cylinder("post", 0.2, 2.0, (2.0, 0.0, 0.0))
    q0 = np.r_[0.1, 0.2, 0.3, quaternions(SO3.exp(np.array([[0.1, 0.0, 0.2]])))[0]]
    ocp = mb.OCP(body, scene, N=3, dt=0.05, q0=q0, v0=[0.1, 0.0, 0.2, 0.3, -0.1, 0.2])
    ocp.add_cost("R", br.BodyOrientation(GOAL_R), 1.3)
    ocp.add_cost("p", br.BodyPosition([0.5, 0.1, 0.0]), 0.7)
    ocp.add_cost("F", br.BodyRotationStep(SO3.exp(np.array([0.0, 0.02, 0.0]))), 2.0)
    ocp.add_cost("v", br.BodyVelocity([0.1, 0.0, 0.0]), 0.4)
    ocp.add_cost("u", br.BodyInput(), 0.01)
    ocp.add_constraint("p_eq", br.BodyPosition([0.2, 0.2, 0.2]), knots=[2])
    ocp.add_constraint("v_eq", br.BodyVelocity([0.0, 0.1, 0.0]), knots=[1])
    ocp.add_constraint("u_eq", br.BodyInput(np.ones(5)), knots=[1])
    ocp.add_constraint("u_limits", br.BodyInputLimits(-20 * np.ones(5), 20 * np.ones(5)))
    ocp.add_constraint("post", res.ComOutsideCylinder("post", 0.05, between_knots=False))
    return ocp


def _start(ocp: mb.OCP) -> np.ndarray:
    """The geodesic warm start (a free body's ``"linear"``)."""
    return initial_path(ocp, "linear")


def _at_site(term, flat: dict, site: int) -> tuple[dict, dict]:
    """The variables and parameters of ``term`` at one site (per-site parameters sliced)."""
    variables = {n: a[site] for n, a in term.gather(flat).items()}
    sizes = {spec.name: int(np.prod(spec.shape)) for spec in term.function.parameters}
    params = {}
    for name, value in term.parameters.items():
        a = np.asarray(value, dtype=float)
        per_site = a.ndim >= 1 and a.shape[0] == term.sites and a.size == term.sites * sizes[name]
        params[name] = a[site] if per_site else a
    return variables, params


def test_maximal_derivatives_match_finite_differences_along_the_retraction() -> None:
    """Every term (the LGVI step and each item), Jacobian and Hessian at a random point, against
    central differences along ``X exp(tξ)`` (:func:`mbplan.engine.checks.check_derivatives`)."""
    ocp = factory_ocp()
    nlp = FreeBodyNLP(ocp, jit=False)
    prob = nlp.problem
    rng = np.random.default_rng(1)
    x = prob.retract(nlp.initial_point(_start(ocp)), 0.05 * rng.standard_normal(prob.n))
    flat = {name: b.flat(x[name]) for name, b in prob.variables.blocks.items()}
    checked = set()
    for term in prob.terms:
        variables, params = _at_site(term, flat, term.sites - 1)
        check = check_derivatives(term.function, variables, params, rng=rng)
        assert check.ok(1e-5), (term.name, check)
        checked.update(term.name.split("+"))  # items of one kind or all costs share a term
    assert checked == {"dynamics", *ocp.names}
    # every item has its rows: 12 dynamics per step, 3 + 3 + 5 equalities, 2·5·3 + 3 limits
    assert prob.n_eq == 12 * 3 + 11 and prob.n_ineq == 30 + 3


def _central(fn, x, h):
    return np.column_stack([(fn(x + h * e) - fn(x - h * e)) / (2 * h) for e in np.eye(x.size)])


def test_quaternion_derivatives_match_finite_differences() -> None:
    ocp = factory_ocp()
    nlp = QuaternionNLP(ocp)
    z = cs.SX(nlp.problem["x"])
    rng = np.random.default_rng(2)
    z0 = nlp.initial_guess(_start(ocp)) + 0.05 * rng.standard_normal(nlp.n)
    lam = rng.standard_normal(nlp.m)
    g = cs.Function("g", [z], [nlp.problem["g"]])
    f = cs.Function("f", [z], [nlp.problem["f"]])
    jac = cs.Function("J", [z], [cs.jacobian(nlp.problem["g"], z)])
    lagr = nlp.problem["f"] + cs.dot(cs.DM(lam), nlp.problem["g"])
    grad = cs.Function("dL", [z], [cs.gradient(lagr, z)])
    hess = cs.Function("H", [z], [cs.hessian(lagr, z)[0]])
    J = np.array(jac(z0))
    np.testing.assert_allclose(J, _central(lambda x: np.array(g(x)).ravel(), z0, 1e-6), atol=2e-5)
    fd = _central(lambda x: np.array(f(x)).ravel(), z0, 1e-6)[0]
    np.testing.assert_allclose(
        np.array(cs.Function("df", [z], [cs.gradient(nlp.problem["f"], z)])(z0)).ravel(),
        fd,
        rtol=1e-6,
        atol=1e-6,
    )
    H = np.array(hess(z0))
    fd = _central(lambda x: np.array(grad(x)).ravel(), z0, 1e-5)
    np.testing.assert_allclose(H, 0.5 * (fd + fd.T), atol=1e-4 * max(1, np.abs(H).max()))
    # input limits are bounds; rows: 13 per step, ‖q_2‖, ‖q_3‖, ‖f_3‖, 11 equalities, 3 cylinder
    assert nlp.m == 13 * 3 + 3 + 11 + 3
    assert np.all(nlp.lbz[-15:] == -20) and np.all(nlp.ubz[-15:] == 20)


def test_both_formulations_and_the_task_have_the_same_objective() -> None:
    task = sample_docking_cases(2, 0, with_input_limits=True)[1]
    ocp = paper.drone_docking(task)
    path = initial_path(ocp, "via")
    maximal = FreeBodyNLP(ocp, jit=False)
    x = maximal.initial_point(path)
    np.testing.assert_allclose(x["R"][[0, -1]], [task.R0, task.R_goal], atol=1e-12)
    np.testing.assert_allclose(x["p"][[0, -1]], [task.p0, task.p_goal], atol=1e-12)
    expected = trajectory_cost(task, {key: x[key] for key in ("R", "p", "F", "v", "u")})
    f_max = maximal.problem.values(x)[0]
    quat = QuaternionNLP(ocp)
    f_quat = float(
        cs.Function("f", [quat.problem["x"]], [quat.problem["f"]])(quat.initial_guess(path))
    )
    np.testing.assert_allclose([f_max, f_quat], expected, rtol=1e-12)


@pytest.mark.parametrize("method", ["ripm", "ipopt"])
def test_cluttered_docking_plans_verifies_and_round_trips(method: str, tmp_path) -> None:
    """Fig. 5: three cylinders and input limits. The paper's constraints hold at the knots
    only: the RIPM's plan cuts a cylinder between knots, which verify reports; with a 2 cm
    margin both formulations' plans verify."""
    task = cluttered_task(with_input_limits=True)
    if method == "ripm":
        at_knots = mb.plan(paper.drone_docking(task), method)
        assert at_knots.success, at_knots.message
        check = mb.verify(at_knots)
        assert not check.passed and "enters an obstacle" in check.reasons[0]
    ocp = paper.drone_docking(task, margin=0.02)
    result = mb.plan(ocp, method)
    assert result.success, result.message
    assert result.q.shape == (41, 7) and result.v.shape == (41, 6) and result.tau.shape == (40, 4)
    check = mb.verify(result)
    assert check.passed, check.reasons
    assert check.min_obstacle_distance_m >= 0.0 and check.torque_limit_violation <= 1e-6
    assert set(check.violations) == {"input_limits", "cylinder_0", "cylinder_1", "cylinder_2"}
    loaded = mb.load_npz(result.save(tmp_path / "drone.npz"))
    assert loaded.ocp.names == ocp.names and isinstance(loaded.ocp.robot, FreeBody)
    assert mb.verify(loaded).passed
    # `mbplan replay` draws it from the file alone: the flight, the goal, the three cylinders
    page = tmp_path / "drone.html"
    assert main(["replay", str(tmp_path / "drone.npz"), "--html", str(page)]) == 0
    assert "quadrotor docking" in page.read_text()
    layers = {la.name: la for la in free_body_scene([loaded], loaded.ocp).layers}
    assert len(layers["obstacles"].objects) == 3
    flown = layers["drone"].placements[:, 0, :3, 3] - layers["drone"].placements[:1, 0, :3, 3]
    np.testing.assert_allclose(flown, result.q[:, :3] - result.q[:1, :3], atol=1e-12)
    with pytest.raises(mb.InputError, match="one at a time"):
        mb.viz.static_html([loaded, loaded], tmp_path / "two.html")


def test_ocp_round_trips_through_json() -> None:
    ocp = factory_ocp()
    again = mb.OCP.from_dict(json.loads(json.dumps(ocp.to_dict())))
    assert again.names == ocp.names and again.robot.source == ocp.robot.source
    np.testing.assert_array_equal(again.q0, ocp.q0)
    for a, b in zip(ocp.items, again.items, strict=True):
        assert a.residual.to_dict() == b.residual.to_dict()
        assert np.array_equal(a.knots, b.knots) and a.weight == b.weight


def test_free_flyer_state_round_trip() -> None:
    rng = np.random.default_rng(5)
    R = SO3.exp(rng.standard_normal((4, 3)))
    F = SO3.exp(0.05 * rng.standard_normal((4, 3)))
    p, v = rng.standard_normal((4, 3)), rng.standard_normal((4, 3))
    q, vel = free_flyer_state(R, p, F, v, 0.05)
    back = body_state(q, vel, 0.05)
    for key, a in (("R", R), ("p", p), ("F", F), ("v", v)):
        np.testing.assert_allclose(back[key], a, atol=1e-12)


def test_bad_input_is_named_before_any_solve() -> None:
    body = FreeBody.quadrotor(0.5, np.diag([2.3e-3, 2.3e-3, 4e-3]))
    with pytest.raises(mb.InputError, match=r"FreeBody\.inertia"):
        FreeBody.quadrotor(0.5, np.diag([1.0, 1.0, 3.0]))
    with pytest.raises(mb.InputError, match="actuation: expected shape"):
        FreeBody("x", 1.0, np.eye(3), (0, 0, -9.81), np.ones((5, 2)))
    with pytest.raises(mb.InputError, match="q0: quaternion"):
        mb.OCP(body, q0=[0, 0, 0, 0, 0, 0, 2.0])
    ocp = mb.OCP(body, N=4)
    with pytest.raises(mb.InputError, match="can only be a cost"):
        ocp.add_constraint("R", br.BodyOrientation(np.eye(3)))
    with pytest.raises(mb.InputError, match=r"BodyPosition\.translation: contains NaN"):
        ocp.add_cost("p", br.BodyPosition([np.nan, 0, 0]))
    with pytest.raises(mb.InputError, match="lower >= upper for input 0"):
        ocp.add_constraint("u", br.BodyInputLimits([1, 0, 0, 0], [1, 1, 1, 1]))
    with pytest.raises(mb.InputError, match=r"BodyInput.target: expected shape \(4,\)"):
        ocp.add_cost("u", br.BodyInput([1.0, 2.0]))
    with pytest.raises(mb.InputError, match="robot 'iiwa' is not one"):
        mb.OCP("iiwa", N=4).add_cost("p", br.BodyPosition([0, 0, 0]))
    with pytest.raises(mb.InputError, match="JointPosition is not a residual of a free body"):
        ocp.add_cost("q", res.JointPosition([0.0]))
    blocked = mb.OCP(body, mb.Scene().add_cylinder("c", 0.3, 1.0, (0.1, 0, 0)), N=4)
    blocked.add_constraint("c", res.ComOutsideCylinder("c", between_knots=False))
    with pytest.raises(mb.InfeasibleRequestError, match="'c'"):
        mb.plan(blocked, "ripm")
    ocp.add_cost("p", br.BodyPosition([1.0, 0.0, 0.0]))
    for method in ("ripm", "ipopt"):
        with pytest.raises(mb.InputError, match="warm_start: knot 0 has a zero quaternion"):
            mb.plan(ocp, method, warm_start=np.zeros((5, 7)))


def test_a_plan_the_lgvi_cannot_replay_fails_verification() -> None:
    """Torques that drive eq. (34) past its roots make `verify` fail with the reason (a
    benchmark of a diverged MLG-IPM plan stopped on this error before)."""
    import dataclasses

    ocp = paper.drone_docking(sample_docking_cases(1, 0)[0])
    plan = mb.plan(ocp, "ripm")
    tau = plan.tau.copy()
    tau[2, 1:] = 1e6
    check = mb.verify(dataclasses.replace(plan, tau=tau))
    assert not check.passed and "the LGVI replay fails at step 2" in check.reasons[0]
    assert check.max_joint_deviation_rad == np.inf


def test_inverse_dynamics_inputs_reproduce_the_warm_start_under_the_lgvi() -> None:
    """A path flown by the LGVI (quadrotor, inputs inside the limits): the ``"inverse"`` warm
    start recovers those inputs, so every dynamics row of the point vanishes; outside the limits
    the inputs are clipped strictly inside them."""
    task = sample_docking_cases(1, 0, with_input_limits=True)[0]
    ocp = paper.drone_docking(task)
    rng = np.random.default_rng(5)
    u = ocp.robot.hover_input + rng.uniform(-1.0, 1.0, (ocp.N, 4)) * [1.0, 0.05, 0.05, 0.05]
    flown = simulate(task, u)
    q, _ = free_flyer_state(flown["R"], flown["p"], flown["F"], flown["v"], ocp.dt)
    # the warm start rests at knot N (F_N = I, v_N = 0): the last step is no flight
    nlp = FreeBodyNLP(ocp, jit=False)
    x = nlp.initial_point(q, inputs="inverse")
    np.testing.assert_allclose(x["u"][:-1], u[:-1], atol=1e-9)
    h = nlp.problem.values(x)[1].reshape(ocp.N, 12)  # the LGVI steps, 12 rows each
    assert np.max(np.abs(h[:-1])) < 1e-9 and np.max(np.abs(h[-1])) > 1e-3  # stop: not flyable
    lower, upper = input_bounds(ocp)
    np.testing.assert_array_equal(lower, [0.0, -0.1, -0.1, -0.1])
    hover = nlp.initial_point(initial_path(ocp, "linear"), inputs="hover")["u"]
    np.testing.assert_array_equal(hover, np.tile(ocp.robot.hover_input, (ocp.N, 1)))
    clipped = nlp.initial_point(initial_path(ocp, "linear"), inputs="inverse")["u"]
    assert np.all(clipped > lower) and np.all(clipped < upper)
    with pytest.raises(mb.InputError, match="warm-start inputs"):
        nlp.initial_point(q, inputs="zero")


def test_inverse_dynamics_inputs_are_exact_for_a_fully_actuated_body() -> None:
    """``B`` of full row rank: the least-squares input gives the wrench eq. (34)–(35) need."""
    B = np.random.default_rng(4).standard_normal((6, 6))
    body = FreeBody("box", 1.3, np.diag([0.02, 0.03, 0.04]), (0.0, 0.0, -9.81), B)
    factory = factory_ocp()
    ocp = mb.OCP(body, mb.Scene(), N=4, dt=0.05, q0=factory.q0, v0=factory.v0)
    ocp.add_cost("R", br.BodyOrientation(GOAL_R), 1.0)
    ocp.add_cost("p", br.BodyPosition([0.5, 0.1, 0.0]), 1.0)
    point = FreeBodyNLP(ocp, jit=False).initial_point(_start(ocp), inputs="hover")
    u = lgvi_inputs(body, ocp.dt, point)
    R, F, v = point["R"], point["F"], point["v"]
    J = body.nonstandard_inertia
    for k in range(ocp.N):
        wrench = body.actuation @ u[k]
        torque = SO3.vee(F[k + 1] @ J - J @ F[k + 1].T - J @ F[k] + F[k].T @ J) / ocp.dt**2
        force = R[k + 1].T @ (body.mass * ((v[k + 1] - v[k]) / ocp.dt - body.gravity))
        np.testing.assert_allclose(wrench, np.r_[force, torque], atol=1e-9)


def test_mehrotra_barrier_options_plan_the_docking_with_input_limits() -> None:
    """The drone docking with input limits (bang-bang torques) planned with Mehrotra's probing
    μ capped at μ_init and the corrector (the defaults): converges, verifies, and reaches the
    monotone barrier's trajectory along different iterates."""
    ocp = paper.drone_docking(sample_docking_cases(2, 0, with_input_limits=True)[0])
    options = {"mu_strategy": "adaptive", "mu_oracle": "probing", "mu_max_fact": 0.0}
    monotone = {"mu_strategy": "monotone", "corrector": False}
    default = mb.plan(ocp, "ripm", warm_start="linear", options=monotone)
    mehrotra = mb.plan(ocp, "ripm", warm_start="linear", options=options | {"corrector": True})
    assert default.success and mehrotra.success
    assert mb.verify(ocp, mehrotra).passed
    np.testing.assert_allclose(mehrotra.q, default.q, atol=1e-5)
    np.testing.assert_allclose(mehrotra.tau, default.tau, atol=1e-4)
    assert mehrotra.iterations != default.iterations or not np.allclose(
        mehrotra.kkt_history, default.kkt_history
    )


def test_lgvi_plans_start_from_zero_equality_multipliers(monkeypatch: pytest.MonkeyPatch) -> None:
    """``plan`` on the LGVI skips the least-squares ``y₀`` (``LGVI_RIPM_OPTIONS``): on a docking
    case that ``y₀`` exceeds ``constr_mult_init_max = 1`` and is discarded, so the plan with it
    takes the same iterates; a user's option brings it back."""
    from mbplan.solvers.ripm.newton import NewtonStep

    kept = []
    original = NewtonStep.least_squares_y
    monkeypatch.setattr(
        NewtonStep,
        "least_squares_y",
        lambda self, ev, z, limit: kept.append(original(self, ev, z, limit)) or kept[-1],
    )
    ocp = paper.drone_docking(sample_docking_cases(1, 0)[0])
    fast = mb.plan(ocp, "ripm")
    assert kept == []
    least_squares = mb.plan(ocp, "ripm", options={"constr_mult_init_max": 1.0})
    assert len(kept) == 1 and kept[0] is None  # computed, larger than 1, discarded
    assert fast.success and fast.iterations == least_squares.iterations
    np.testing.assert_array_equal(fast.kkt_history, least_squares.kkt_history)
    np.testing.assert_array_equal(fast.tau, least_squares.tau)
