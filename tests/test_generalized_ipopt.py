"""Generalized-coordinate IPOPT baseline (RIPM paper eq. 61, 62; Table III)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

import mbplan.baselines.generalized_ipopt as gi
from mbplan.baselines.generalized_ipopt import (
    GeneralizedTranscription,
    _restoration_iterations,
    solve_generalized_ipopt,
)
from mbplan.errors import InfeasibleRequestError, InputError
from mbplan.multibody.collision import chain_kinematics, joint_space_contacts, point_jacobians
from mbplan.tasks.obstacle import (
    IIWA_START,
    IIWA_TARGET,
    Cylinder,
    Obstacle,
    ObstacleTask,
    com_clearances,
    joint_interpolation,
    link_coms,
    pair_distances,
    robot_description,
)
from mbplan.verification import verify

MODEL = robot_description("iiwa").model


def small_cases(n: int = 3) -> list[ObstacleTask]:
    """N = 10 tasks whose straight path brushes a cylinder in the way of the wrist (links 6, 7
    pass at 0.60-0.62 m from the base axis; the cylinder's near side is at 0.60 m)."""
    rng = np.random.default_rng(0)
    cylinder = Cylinder((0.68 * np.cos(0.6), 0.68 * np.sin(0.6)), 0.08)
    target = np.array(IIWA_TARGET)
    return [
        ObstacleTask(
            N=10,
            dt=0.1,
            q0=target + np.concatenate([[-0.8], 0.1 * rng.uniform(-1.0, 1.0, 6)]),
            obstacles=(cylinder,),
        )
        for _ in range(n)
    ]


def _random_point(tr: GeneralizedTranscription, seed: int) -> np.ndarray:
    guess = tr.initial_guess()
    rng = np.random.default_rng(seed)
    return tr.pack(guess["q"], guess["v"], guess["tau"]) + 0.1 * rng.standard_normal(tr.n)


def _central_columns(fn, z: np.ndarray, h: float) -> np.ndarray:
    return np.column_stack([(fn(z + h * e) - fn(z - h * e)) / (2.0 * h) for e in np.eye(z.size)])


@pytest.fixture(scope="module")
def transcription() -> GeneralizedTranscription:
    cylinders = (Cylinder((0.4, 0.2), 0.1), Cylinder((-0.3, 0.4), 0.15))
    return GeneralizedTranscription(ObstacleTask(N=4, obstacles=cylinders))


def test_jacobian_matches_central_differences(transcription: GeneralizedTranscription) -> None:
    tr = transcription
    z = _random_point(tr, 0)
    J = tr.jacobian(z).toarray()
    assert J.shape == (tr.m, tr.n) == (2 * 4 * 7 + 4 * 7 * 2, 3 * 4 * 7)
    fd = _central_columns(tr.constraints, z, 1e-6)
    assert np.max(np.abs(J - fd)) <= 1e-7 * np.max(np.abs(J))
    assert np.max(np.abs(fd[J == 0.0])) < 1e-6  # nothing outside the sparsity pattern


def test_lagrangian_hessian_matches_central_differences(
    transcription: GeneralizedTranscription,
) -> None:
    tr = transcription
    z = _random_point(tr, 1)
    rng = np.random.default_rng(2)
    sigma, lam = 0.7, rng.standard_normal(tr.m)
    U = tr.lagrangian_hessian(z, sigma, lam).toarray()
    assert np.all(np.tril(U, -1) == 0.0)  # upper triangle, as CasADi's hess_lag
    H = U + U.T - np.diag(np.diag(U))

    def gradient(x: np.ndarray) -> np.ndarray:
        return sigma * tr.weights * (x - tr.reference) + tr.jacobian(x).T @ lam

    fd = _central_columns(gradient, z, 1e-6)
    assert np.max(np.abs(H - fd)) <= 1e-6 * np.max(np.abs(H))
    # the eq.-62 part alone is analytic: much tighter
    lam_obs = np.where(np.arange(tr.m) >= 2 * tr.N * tr.nv, lam, 0.0)
    U = tr.lagrangian_hessian(z, 0.0, lam_obs).toarray()
    fd = _central_columns(lambda x: tr.jacobian(x).T @ lam_obs, z, 1e-6)
    np.testing.assert_allclose(U + U.T - np.diag(np.diag(U)), fd, atol=1e-8)


def test_callbacks_agree_with_the_numpy_functions(transcription: GeneralizedTranscription) -> None:
    tr = transcription
    g, jac_g, hess_lag = tr.callbacks()
    z = _random_point(tr, 3)
    lam = np.random.default_rng(4).standard_normal(tr.m)
    np.testing.assert_allclose(np.asarray(g(z)).ravel(), tr.constraints(z))
    g_out, J = jac_g(z, np.zeros(0))
    np.testing.assert_allclose(np.asarray(g_out).ravel(), tr.constraints(z))
    np.testing.assert_allclose(np.asarray(J), tr.jacobian(z).toarray())
    np.testing.assert_allclose(
        np.asarray(hess_lag(z, np.zeros(0), 0.5, lam)),
        tr.lagrangian_hessian(z, 0.5, lam).toarray(),
    )


def test_initial_guess_satisfies_eq61() -> None:
    task = ObstacleTask(N=10)
    tr = GeneralizedTranscription(task)
    guess = tr.initial_guess()
    np.testing.assert_array_equal(guess["q"], joint_interpolation(task))
    assert not guess["v"][0].any() and not guess["v"][-1].any()
    g = tr.constraints(tr.pack(guess["q"], guess["v"], guess["tau"]))
    assert np.max(np.abs(g[: 2 * task.N * 7])) < 1e-9
    assert np.min(g[2 * task.N * 7 :]) < 0.0  # the straight path crosses the obstacle


def test_small_runs_converge_and_pass_verification() -> None:
    for task in small_cases(3):
        result = solve_generalized_ipopt(task)
        assert result.success, result.message
        assert result.status == "Solve_Succeeded" and result.method == "generalized_ipopt"
        assert 0 < result.iterations < 100 and result.entered_restoration is False
        assert result.kkt_history.shape == (result.iterations + 1, 2)
        assert result.kkt_history[-1].max() < 1e-6
        assert 0.0 < result.solve_time_s <= result.total_time_s
        assert result.time_per_iter_s == pytest.approx(result.solve_time_s / result.iterations)
        np.testing.assert_array_equal(result.q[0], task.q0)
        assert result.q.shape == result.v.shape == (11, 7) and result.tau.shape == (10, 7)
        # eq. 62 is active: the wrist touches the cylinder + margin at some knot
        clearance = com_clearances(
            task, np.array([link_coms(MODEL, MODEL.createData(), q) for q in result.q])
        )
        assert clearance.min() == pytest.approx(task.margin, abs=1e-6)
        assert np.all(np.abs(result.tau) <= task.torque_limit)
        assert np.all(np.abs(result.v) <= task.velocity_limit + 1e-9)
        check = verify(task, result)
        assert check.passed, check.reasons


def test_restoration_is_detected_and_can_be_disabled() -> None:
    task = small_cases(1)[0]
    forced = solve_generalized_ipopt(task, ipopt_options={"start_with_resto": "yes"})
    assert forced.entered_restoration is True and forced.extra["restoration_iterations"] > 0
    stopped = solve_generalized_ipopt(
        task, restoration=False, ipopt_options={"start_with_resto": "yes"}
    )
    assert stopped.entered_restoration is True and not stopped.success
    assert stopped.status == "Maximum_Iterations_Exceeded"
    assert "restoration" in stopped.message and stopped.iterations <= 2
    log = (
        "iter    objective    inf_pr   inf_du lg(mu)  ||d||  lg(rg) alpha_du alpha_pr  ls\n"
        "   0  2.0000000e-02 2.38e+00 2.00e-01  -1.0 0.00e+00    -  0.00e+00 0.00e+00   0\n"
        "  12r 1.0040046e+00 4.64e-02 9.99e+02  -1.3 0.00e+00    -  0.00e+00 3.73e-09R 29\n"
        "  13r 1.0028337e+00 7.97e-02 9.75e+02  -1.3 2.03e+00    -  5.48e-01 2.46e-02f  1\n"
        "  14  1.0028337e+00 7.97e-02 9.75e+02  -1.3 2.03e+00    -  5.48e-01 2.46e-02f  1\n"
        "Number of Iterations....: 14\n"
    )
    assert _restoration_iterations(log) == 2


def test_input_errors_before_solving(monkeypatch: pytest.MonkeyPatch) -> None:
    def no_solver(*args: object, **kwargs: object) -> None:
        raise AssertionError("nlpsol must not be reached")

    monkeypatch.setattr(gi.cs, "nlpsol", no_solver)
    task = small_cases(1)[0]
    guess = GeneralizedTranscription(task).initial_guess()
    guess["v"][3, 2] = np.nan
    with pytest.raises(InputError, match=r"initial_guess\['v'\]: contains NaN"):
        solve_generalized_ipopt(task, initial_guess=guess)
    with pytest.raises(InputError, match=r"initial_guess\['tau'\]: expected shape"):
        solve_generalized_ipopt(task, initial_guess={**guess, "v": guess["q"], "tau": guess["q"]})
    with pytest.raises(InputError, match="missing 'tau'"):
        solve_generalized_ipopt(task, initial_guess={"q": guess["q"], "v": guess["q"]})
    with pytest.raises(InputError, match="max_iter"):
        solve_generalized_ipopt(task, max_iter=-1)
    with pytest.raises(InputError, match="restoration"):
        solve_generalized_ipopt(task, ipopt_options={"output_file": "x.log"})
    with pytest.raises(InputError, match="tol"):
        solve_generalized_ipopt(task, tol=float("nan"))
    com = link_coms(MODEL, MODEL.createData(), np.array(IIWA_START))[4]
    blocked = ObstacleTask(obstacles=(Cylinder(tuple(com[:2]), 0.1),))
    with pytest.raises(InfeasibleRequestError, match=r"q0 overlaps.*'iiwa_link_5'"):
        solve_generalized_ipopt(blocked)
    pose = np.eye(4)
    pose[:3, 3] = (2.0, 0.0, 0.5)
    box = Obstacle("box", pose, (0.1, 0.1, 0.1))
    with pytest.raises(InputError, match="Cylinder obstacles"):
        solve_generalized_ipopt(ObstacleTask(obstacles=(box,)))


@pytest.fixture(scope="module")
def distance_transcription() -> GeneralizedTranscription:
    sphere, box = np.eye(4), np.eye(4)
    sphere[:3, 3] = (0.35, 0.25, 0.6)
    box[:3, 3] = (-0.35, 0.2, 0.5)
    box[:3, :3] = pin.rpy.rpyToMatrix(0.2, -0.5, 0.3)
    obstacles = (Obstacle("sphere", sphere, (0.1,)), Obstacle("box", box, (0.2, 0.15, 0.3)))
    task = ObstacleTask(N=4, obstacles=obstacles, obstacle_constraint="distance")
    return GeneralizedTranscription(task)


def test_distance_rows_jacobian_matches_central_differences(
    distance_transcription: GeneralizedTranscription,
) -> None:
    tr = distance_transcription
    z = _random_point(tr, 5)
    J = tr.jacobian(z).toarray()
    assert tr.m == 2 * 4 * 7 + 4 * tr.npairs and tr.npairs == 14
    fd = _central_columns(tr.constraints, z, 1e-6)
    assert np.max(np.abs(J - fd)) <= 1e-7 * np.max(np.abs(J))
    assert np.max(np.abs(fd[J == 0.0])) < 1e-6


def test_distance_rows_hessian_is_the_fixed_witness_point_model(
    distance_transcription: GeneralizedTranscription,
) -> None:
    """``∇²(μ d)`` with coal's witness point fixed in its link and the normal fixed
    (mbplan.multibody.collision), against central differences of that model's gradient."""
    tr = distance_transcription
    z = _random_point(tr, 6)
    rng = np.random.default_rng(7)
    mu = rng.uniform(0.5, 2.0, (tr.N, tr.npairs))
    lam = np.concatenate([np.zeros(2 * tr.N * tr.nv), mu.ravel()])
    U = tr.lagrangian_hessian(z, 0.0, lam).toarray()
    H = U + U.T - np.diag(np.diag(U))
    q, _, _ = tr.unpack(z)
    data = MODEL.createData()
    kin = chain_kinematics(MODEL, data, q[1:])
    contacts, _ = joint_space_contacts(tr.pairs, kin)
    joints = tr.pairs.joint
    for k in range(1, tr.N + 1):
        R, t = kin.rotation[k - 1, joints], kin.translation[k - 1, joints]
        local = np.einsum("pji,pj->pi", R, contacts.robot_point[k - 1] - t)

        def model_gradient(qk: np.ndarray, k: int = k, local: np.ndarray = local) -> np.ndarray:
            chain = chain_kinematics(MODEL, data, qk[None])
            points = chain.translation[0, joints] + np.einsum(
                "pij,pj->pi", chain.rotation[0, joints], local
            )
            J = point_jacobians(chain, joints, points[None])[0]
            return -np.einsum("p,pa,pja->j", mu[k - 1], contacts.normal[k - 1], J)

        fd = _central_columns(model_gradient, q[k], 1e-6)
        block = H[np.ix_(tr.iq(k), tr.iq(k))]
        np.testing.assert_allclose(block, fd, atol=1e-7)


def test_small_distance_runs_converge_and_pass_verification() -> None:
    """N = 10 with coal distances: the straight path of the small cases crosses a thinner
    cylinder with the links' geometry; IPOPT converges onto the margin and the replay keeps clear
    of the solid."""
    cylinder = Cylinder((0.68 * np.cos(0.6), 0.68 * np.sin(0.6)), 0.05)
    for task in small_cases(2):
        task = dataclasses.replace(task, obstacle_constraint="distance", obstacles=(cylinder,))
        assert pair_distances(task, joint_interpolation(task)).min() < 0.0
        result = solve_generalized_ipopt(task)
        assert result.success, result.message
        check = verify(task, result)
        assert check.passed, check.reasons
        d = pair_distances(task, result.q[1:]).min()
        assert d == pytest.approx(task.margin, abs=1e-6)  # active constraint
