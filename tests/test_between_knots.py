"""Obstacle constraints between knots (``between_knots``): the rows' derivatives in both
formulations, the margin kept along the replayed motion, the verifier's rule, and the knot-only
option leaving the paper's tasks as they were."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import pytest
from fd import check_generalized_derivatives
from scipy.spatial.transform import Rotation
from test_generalized import small_cases

import mbplan as mb
from mbplan.engine import check_derivatives
from mbplan.formulations.generalized import GeneralizedNLP
from mbplan.formulations.interval_rows import SecantRows, secant
from mbplan.formulations.joint_space import evaluate
from mbplan.formulations.maximal import MaximalNLP
from mbplan.multibody import body_poses, maximal_model
from mbplan.multibody.collision import chain_kinematics, collision_pairs, signed_distances
from mbplan.planning.initial_guess import initial_path
from mbplan.residuals import ComOutsideCylinder, Distance, Residual
from mbplan.residuals.distance import distance_values
from mbplan.robots import load
from mbplan.taskfile import load_task
from mbplan.tasks.paper import (
    IIWA_TARGET,
    add_obstacle_constraint,
    drone_docking,
    iiwa_obstacle,
    tracking_ocp,
)
from mbplan.transcription.constraints import interval_cylinder_clearance_function
from mbplan.transcription.distance import (
    distance_constraint_function,
    interval_distance_function,
    pair_bodies,
)
from mbplan.transcription.intervals import (
    INTERVAL_ROWS,
    SECANT_ENDS,
    SECANT_HALF_WIDTH,
    interval_pose,
    secant_weights,
)
from mbplan.verification.report import MARGIN_KEPT

PANDA_TASK = Path(__file__).resolve().parents[1] / "examples" / "tasks" / "panda_boxes.toml"
Q0 = np.array([0.3, 0.5, -0.4, -1.2, 0.6, 0.8, -0.2])


def _distance_scene() -> mb.Scene:
    """Tilted shapes near the arm (no parallel faces: no degenerate contacts)."""
    scene = mb.Scene().add_sphere("sphere", 0.1, (0.35, 0.25, 0.6))
    rotation = pin.rpy.rpyToMatrix(0.2, -0.5, 0.3)
    return scene.add_box("box", (0.2, 0.15, 0.3), (-0.35, 0.2, 0.5), rotation)


def _nlp(constraint: str) -> tuple[GeneralizedNLP, np.ndarray]:
    """A 4-step iiwa NLP with ``constraint`` between knots, at a perturbed linear guess."""
    if constraint == "com":
        scene = mb.Scene().add_cylinder("cylinder", 0.08, 1.5, (0.55, 0.4, 0.75))
    else:
        scene = _distance_scene()
    ocp = tracking_ocp("iiwa", Q0, IIWA_TARGET, scene, N=4)
    add_obstacle_constraint(ocp, constraint, between_knots=True)
    nlp = GeneralizedNLP(ocp)
    z = nlp.initial_guess(initial_path(ocp, "linear"))
    return nlp, z + 0.1 * np.random.default_rng(6).standard_normal(nlp.n)


def _intervals(nlp: GeneralizedNLP) -> SecantRows:
    (block,) = [b for b in nlp.own if isinstance(b, SecantRows)]
    return block


def test_generalized_rows_sit_on_the_interval_motion_with_exact_derivatives() -> None:
    """Eq. (62) between knots: the secant through the rows at ``q_k + sΔt v_k + ½s²Δt(v_{k+1} -
    v_k)``, ``s = ½ ∓ δ``, at ``σ = 0, 1`` and the row at ``s = ½``; Jacobian and Hessian against
    central differences of the whole NLP."""
    nlp, z = _nlp("com")
    block = _intervals(nlp)
    q, v, _ = nlp.unpack(z)
    samples, weights = secant()
    Q = block.sample_configurations(q, v)
    for j, s in enumerate(samples):
        expected = q[2] + s * nlp.dt * v[2] + 0.5 * s * s * nlp.dt * (v[3] - v[2])
        np.testing.assert_allclose(Q[j, 2], expected, rtol=1e-14)
    assert samples[1] == 0.5 and samples[2] - 0.5 == 0.5 - samples[0] > 0
    r = np.stack([block.form.values(Q[j]) for j in range(3)])  # (sample, interval, P)
    line = r[0] + (SECANT_ENDS[:, None, None] - samples[0]) * (r[2] - r[0]) / (
        samples[2] - samples[0]
    )
    expected = np.concatenate([line, r[1:2]])  # (row, interval, P)
    assert INTERVAL_ROWS == len(expected)
    np.testing.assert_allclose(block.values(q, v), np.swapaxes(expected, 0, 1).ravel(), atol=1e-14)
    assert np.allclose(weights.sum(axis=1), 1.0)
    lam = np.random.default_rng(4).standard_normal(nlp.m)
    check_generalized_derivatives(nlp, z, lam)


def test_generalized_distance_rows_have_the_witness_point_derivatives() -> None:
    """Coal distances between knots: the Jacobian against central differences of the NLP, the
    Hessian that of the fixed-witness-point model (as at the knots) through the interval map."""
    nlp, z = _nlp("distance")
    block = _intervals(nlp)
    J = nlp.jacobian(z).toarray()[block.row0 : block.row0 + block.size]

    def rows(x: np.ndarray) -> np.ndarray:
        return nlp.constraints(x)[block.row0 : block.row0 + block.size]

    h = 1e-6
    fd = np.column_stack([(rows(z + h * e) - rows(z - h * e)) / (2 * h) for e in np.eye(nlp.n)])
    np.testing.assert_allclose(J, fd, atol=2e-5 * np.abs(J).max())

    ocp = nlp.ocp
    q, v, _ = nlp.unpack(z)
    _, weights = secant()
    joints = block.form.pairs.joint
    witness = []  # per sample: the witness points (link frames) and normals, fixed
    for Q in block.sample_configurations(q, v):
        _, _, kin, contacts, _ = distance_values(ocp.robot, ocp.scene, block.form.residual, Q, 1)
        R, t = kin.rotation[:, joints], kin.translation[:, joints]
        witness.append((np.einsum("kpji,kpj->kpi", R, contacts.robot_point - t), contacts.normal))
    shape = (block.size // (INTERVAL_ROWS * block.P), INTERVAL_ROWS, block.P)
    lam_rows = np.random.default_rng(7).uniform(0.5, 2.0, shape)
    lam = np.zeros(nlp.m)
    lam[block.row0 : block.row0 + block.size] = lam_rows.ravel()
    data = ocp.robot.model.createData()

    def model(x: np.ndarray) -> float:
        """``Σ λ_σ Σ_j w_σj nⱼᵀ p₁ⱼ`` with the witness points and normals fixed."""
        total = 0.0
        for j, Q in enumerate(block.sample_configurations(*nlp.unpack(x)[:2])):
            chain = chain_kinematics(ocp.robot.model, data, Q)
            local, normal = witness[j]
            points = chain.translation[:, joints] + np.einsum(
                "kpij,kpj->kpi", chain.rotation[:, joints], local
            )
            mu = np.einsum("ksp,s->kp", lam_rows, weights[:, j])
            total += float(np.sum(mu[..., None] * normal * points))
        return total

    U = nlp.lagrangian_hessian(z, 0.0, lam).toarray()
    H = U + U.T - np.diag(np.diag(U))
    cols = np.unique(block.hess_cols)
    h, eye = 1e-4, np.eye(nlp.n)
    for a in cols:
        for b in cols[cols >= a]:
            fd = (
                model(z + h * (eye[a] + eye[b]))
                - model(z + h * (eye[a] - eye[b]))
                - model(z - h * (eye[a] - eye[b]))
                + model(z - h * (eye[a] + eye[b]))
            ) / (4 * h * h)
            assert H[a, b] == pytest.approx(fd, abs=1e-6 * max(1.0, np.abs(H).max()))


def _maximal_interval() -> tuple:
    """The iiwa's bodies at a knot and the LGVI step ``(F, v)`` to a nearby configuration."""
    desc = load("iiwa")
    mm = maximal_model(desc)
    R0, p0 = body_poses(mm, Q0)
    step = np.random.default_rng(0).uniform(-0.15, 0.15, Q0.size)
    R1, p1 = body_poses(mm, Q0 + step)
    dt = 0.05
    return desc, mm, R0, p0, np.swapaxes(R0, 1, 2) @ R1, (p1 - p0) / dt, dt


def _pose(xyz, rotvec) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    pose[:3, 3] = xyz
    return pose


def test_maximal_distance_between_knots_has_witness_point_derivatives_on_the_retraction() -> None:
    """Coal distances at ``(R exp(t log F), p + tΔt v)`` for ``t = s ∓ δ`` as two secant rows
    ``margin - ℓ(σ)``, ``σ = 0, 1``, ``ℓ`` the line through the two distances, and the row at
    ``t = s``: the values are coal's, the Jacobian matches central differences along the
    retraction of ``(R, p, F, v)`` and the Hessian is that of the fixed-witness-point model
    ``Σ_j w_ij nⱼᵀ(p_t + R_t aⱼ)`` (four-point differences)."""
    desc, mm, R, p, F, v, dt = _maximal_interval()
    obstacles = [
        (coal.Sphere(0.1), _pose((0.35, 0.25, 0.6), (0.0, 0.0, 0.0))),
        (coal.Box(0.2, 0.15, 0.3), _pose((-0.35, 0.2, 0.5), (0.2, -0.5, 0.3))),
    ]
    pairs = collision_pairs(desc.collision_model, obstacles)
    b, P, s = pair_bodies(mm, pairs), pairs.size, 0.5
    f = interval_distance_function(mm, pairs)
    sites = {"R": R[b], "p": p[b], "F": F[b], "v": v[b]}
    params = {"pair": np.arange(P), "margin": 0.02, "s": s, "dt": dt}
    at_knot = distance_constraint_function(mm, pairs)
    samples = np.array([s - SECANT_HALF_WIDTH, s, s + SECANT_HALF_WIDTH])
    poses = [
        interval_pose(R[b], p[b], F[b], v[b], np.full(P, t), np.full(P, t * dt)) for t in samples
    ]
    d = np.stack(
        [
            0.02 - at_knot.value({"R": Rt, "p": pt}, {"pair": np.arange(P), "margin": 0.02})[:, 0]
            for Rt, pt in poses
        ],
        axis=1,
    )
    slope = (d[:, 2] - d[:, 0]) / (samples[2] - samples[0])
    line = d[:, :1] + (SECANT_ENDS[None] - samples[0]) * slope[:, None]
    rows = np.column_stack([line, d[:, 1]])
    np.testing.assert_allclose(f.value(sites, params), 0.02 - rows, atol=1e-12)
    assert np.abs(slope).max() > 1e-2  # the rows differ from the distances at the samples
    lam = np.random.default_rng(1).uniform(0.5, 2.0, (P, INTERVAL_ROWS))
    H = f.dense_hessian(f.hessian(sites, params, lam)[2])
    witness = []
    for Rt, pt in poses:
        geometry_R = Rt @ pairs.placement[:, :3, :3]
        geometry_t = pt + np.einsum(
            "pij,pj->pi", Rt, pairs.placement[:, :3, 3] - mm.com_in_joint[b]
        )
        contacts = signed_distances(pairs, np.arange(P), geometry_R, geometry_t)
        witness.append((np.einsum("pji,pj->pi", Rt, contacts.robot_point - pt), contacts.normal))
    weights = secant_weights(np.array([s]))[1][0]  # [row, sample]
    np.testing.assert_allclose(weights[:2, [0, 2]] @ samples[[0, 2]], SECANT_ENDS)
    h, eye = 1e-4, np.eye(f.n)
    for i in range(P):
        one = {n: x[i] for n, x in sites.items()}
        check = check_derivatives(f, one, params | {"pair": i}, step_jacobian=1e-5)
        # the distances' 2e-6 (curved shapes, witness points to ~sqrt(GJK tolerance)) times the
        # rows' weights (|w| ≤ 1.5, Σ|w| = 2 per row)
        assert check.jacobian_error < 8e-6, (pairs.names[i], check)

        def model(xi: np.ndarray, i: int = i, one: dict = one) -> float:
            x = f.retract({n: y[None] for n, y in one.items()}, xi[None])
            total = 0.0
            for j, t in enumerate(samples):
                Rx, px = interval_pose(
                    x["R"], x["p"], x["F"], x["v"], np.array([t]), np.array([t * dt])
                )
                a, n = witness[j][0][i], witness[j][1][i]
                total += (lam[i] @ weights[:, j]) * (n @ (px[0] + Rx[0] @ a))
            return float(total)

        fd = np.array(
            [
                [
                    (
                        model(h * (eye[r] + eye[c]))
                        - model(h * (eye[r] - eye[c]))
                        - model(h * (eye[c] - eye[r]))
                        + model(-h * (eye[r] + eye[c]))
                    )
                    / (4 * h * h)
                    for c in range(f.n)
                ]
                for r in range(f.n)
            ]
        )
        np.testing.assert_allclose(H[i], fd, atol=1e-6)


def test_maximal_com_between_knots_has_exact_derivatives() -> None:
    """Eq. (62) at ``p + tΔt v``, ``t = ½ ∓ δ``, as the secant's two ends, and at ``t = ½``:
    value, Jacobian and Hessian along the retraction."""
    _, _, _, p, _, v, dt = _maximal_interval()
    f = interval_cylinder_clearance_function(False)
    c = np.array([0.4, 0.2, 0.13])
    samples = 0.5 + SECANT_HALF_WIDTH * np.array([-1.0, 0.0, 1.0])
    for b in range(len(p)):
        params = {"c": c, "s": 0.5, "dt": dt}
        at = [c[2] ** 2 - np.sum((p[b] + t * dt * v[b] - c)[:2] ** 2) for t in samples]
        slope = (at[2] - at[0]) / (samples[2] - samples[0])
        expected = [*(at[0] + (SECANT_ENDS - samples[0]) * slope), at[1]]
        np.testing.assert_allclose(f.value({"p": p[b], "v": v[b]}, params)[0], expected, atol=1e-14)
        assert check_derivatives(f, {"p": p[b], "v": v[b]}, params).ok(1e-6)


def test_the_centre_row_catches_a_peak_the_secant_misses() -> None:
    """A point crossing a cylinder's edge between the secant's samples: eq. (62) is violated at
    ``s = ½`` (the row > 0) while both secant rows are satisfied; the centre row says so."""
    f = interval_cylinder_clearance_function(False)
    c, dt = np.array([0.0, 0.0, 0.1]), 0.1
    p, v = np.array([-0.2, 0.095, 0.5]), np.array([4.0, 0.0, 0.0])  # x = 0 at s = ½
    rows = f.value({"p": p, "v": v}, {"c": c, "s": 0.5, "dt": dt})[0]
    assert rows[0] <= 0 and rows[1] <= 0 and rows[2] > 0


# process-wide cache of test plans, result-neutral: a function of its arguments alone
@cache
def _plan(method: str, between_knots: bool) -> mb.PlanResult:
    """The wrist past a thin cylinder at N = 10 (tests/test_generalized.py), coal distances
    with a 3 cm margin, from the straight path through it; to ``tol`` 1e-5 (the secant rows'
    fixed-witness Hessian lacks the cylinder's curvature: the RIPM's last digits converge
    linearly and its line search can stall near 4e-6)."""
    ocp = small_cases(1, "distance", radius=0.05, between_knots=between_knots)[0]
    return mb.plan(ocp, method, warm_start="linear", tol=1e-5)


@pytest.mark.parametrize("method", ["ipopt", "ripm"])
def test_the_replayed_motion_keeps_the_margin_only_with_rows_between_knots(method: str) -> None:
    knots, between = _plan(method, False), _plan(method, True)
    assert knots.success and between.success
    residual = knots.ocp["clearance"].residual  # the margin is active at the knots
    rows = evaluate(knots.ocp.robot, knots.ocp.scene, residual, knots.q[1:], knots.v[1:], None)
    assert np.max(rows) > -1e-4
    margin = knots.ocp["clearance"].residual.margin
    check = mb.verify(knots)
    assert check.passed and np.isnan(check.margin_kept)  # knot-only: clear of the solid
    assert 0.0 <= check.clearances["clearance"] < MARGIN_KEPT * margin  # but inside the margin
    check = mb.verify(between)
    assert check.passed, check.reasons
    assert check.margin_kept == check.clearances["clearance"] / margin >= MARGIN_KEPT


def test_verify_fails_a_plan_that_keeps_too_little_of_its_margin_between_knots() -> None:
    plan = _plan("ipopt", False)
    strict = small_cases(1, "distance", radius=0.05, between_knots=True)[0]
    check = mb.verify(strict, plan)
    assert not check.passed and check.margin_kept < MARGIN_KEPT
    assert any("'clearance' keeps" in r and "between knots" in r for r in check.reasons)
    assert mb.verify(plan.ocp, plan).passed  # the knot-only rule: only entering fails


def test_knot_only_obstacles_add_no_rows_between_knots() -> None:
    """The paper's tasks constrain the knots only, with the transcriptions of before; the rows
    between knots are an addition to the knot rows."""
    paper = [iiwa_obstacle(), iiwa_obstacle(constraint="distance"), drone_docking()]
    assert all(
        not i.residual.between_knots
        for ocp in paper
        for i in ocp.constraints
        if i.residual.is_obstacle
    )
    knots, between = (small_cases(1, "distance", 0.05, b)[0] for b in (False, True))
    nlps = [GeneralizedNLP(ocp) for ocp in (knots, between)]
    assert [b.K for b in nlps[0].own] == [knots.N]
    assert [b.K for b in nlps[1].own] == [knots.N, knots.N * INTERVAL_ROWS]
    assert nlps[1].m == nlps[0].m + nlps[1].own[1].size
    z = nlps[0].initial_guess(initial_path(knots, "linear"))
    np.testing.assert_array_equal(nlps[1].constraints(z)[: nlps[0].m], nlps[0].constraints(z))
    names = [{t.name for t in MaximalNLP(ocp, jit=False).problem.terms} for ocp in (knots, between)]
    assert names[1] - names[0] == {"clearance/between_knots"}


def test_bad_between_knots_input_is_named_before_any_solve() -> None:
    ocp = tracking_ocp("iiwa", Q0, IIWA_TARGET, _distance_scene(), N=4)
    with pytest.raises(mb.InputError, match=r"Distance\.between_knots: expected true or false"):
        ocp.add_constraint("c", Distance(0.02, between_knots="yes"))
    with pytest.raises(mb.InputError, match=r"Distance\.interval_activation: must be"):
        ocp.add_constraint("c", Distance(0.02, interval_activation=0.0))
    cylinder = mb.Scene().add_cylinder("post", 0.1, 1.5, (0.4, 0.2, 0.75))
    with pytest.raises(mb.InputError, match=r"ComOutsideCylinder\.between_knots"):
        mb.OCP("iiwa", cylinder, N=4).add_constraint("c", ComOutsideCylinder("post", 0.0, 1))
    body = mb.OCP(drone_docking().robot, cylinder, N=4)
    with pytest.raises(
        mb.InputError, match=r"between_knots=True\) cannot be expressed in the free"
    ):
        body.add_constraint("c", ComOutsideCylinder("post", 0.02))
    ocp.add_constraint("clearance", Distance(0.02))
    for method in ("fddp", "csqp"):
        with pytest.raises(mb.InputError, match=r"cannot be expressed in shooting.*=False"):
            mb.plan(ocp, method)
    with pytest.raises(mb.InputError, match=r"between_knots.*expected true or false"):
        load_task(PANDA_TASK, {"constraints.between_knots": 1})


def test_a_saved_obstacle_without_the_option_is_knot_only() -> None:
    data = Distance(0.02).to_dict()
    assert Residual.from_dict(data).between_knots
    del data["between_knots"]
    assert not Residual.from_dict(data).between_knots
