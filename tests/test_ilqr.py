"""Lie-group SS-/MS-iLQR: derivatives vs finite differences along x ⊕ tδx, exact LQR on a
linear–quadratic problem, MS with zero defects = SS, divergence and bad-input handling, and the
thesis scenarios A and C end to end."""

from __future__ import annotations

import json

import casadi as cs
import numpy as np
import pytest

from mbplan.cli.main import main
from mbplan.errors import InputError
from mbplan.lie import SE3, R, RnGroup
from mbplan.shooting import DiscreteDynamics, ShootingProblem, StateSpace, TrackingCost
from mbplan.solvers.ilqr import ILQROptions, ILQRStatus, solve_ilqr, solve_ilqr_bounded
from mbplan.tasks.ilqr import build


def _retract(space: StateSpace, q: np.ndarray, dx: np.ndarray) -> np.ndarray:
    parts = space.unpack(q)
    out = []
    for i, (g, X) in enumerate(zip(space.groups, parts, strict=True)):
        d = dx[space.tangent_slice(i)]
        out.append(X + d if isinstance(g, RnGroup) else X @ g.exp(d))
    return space.pack(out)


def _local(space: StateSpace, q: np.ndarray, y: np.ndarray) -> np.ndarray:
    out = []
    for g, X, Y in zip(space.groups, space.unpack(q), space.unpack(y), strict=True):
        out.append(Y - X if isinstance(g, RnGroup) else g.log(np.linalg.inv(X) @ Y))
    return np.concatenate(out)


@pytest.fixture(scope="module")
def scenarios():
    return {
        (name, integ): build(name, integ)
        for name, integ in [
            ("so3-tracking", "euler"),
            ("pendulum", "euler"),
            ("pendulum", "lgvi"),
            ("drone", "euler"),
            ("drone", "lgvi"),
        ]
    }


def _random_state(space, rng, center):
    return _retract(space, center, 0.3 * rng.standard_normal(space.nx))


@pytest.mark.parametrize(
    "key",
    [
        ("so3-tracking", "euler"),
        ("pendulum", "euler"),
        ("drone", "euler"),
        ("pendulum", "lgvi"),
        ("drone", "lgvi"),  # SO(3) × R³ × R³ × R³
    ],
)
def test_dynamics_jacobians_match_finite_differences(scenarios, key):
    sc = scenarios[key]
    dyn, space = sc.problem.dynamics, sc.problem.space
    rng = np.random.default_rng(3)
    X = np.stack([_random_state(space, rng, sc.problem.x_ref[k]) for k in range(4)])
    U = rng.standard_normal((3, dyn.nu))
    _, A, B = dyn.linearize(X, U)
    h = 1e-6
    for k in range(3):
        f0 = dyn.step(X[k], U[k])
        for _ in range(3):
            dx, du = rng.standard_normal(space.nx), rng.standard_normal(dyn.nu)
            fp = dyn.step(_retract(space, X[k], h * dx), U[k] + h * du)
            fm = dyn.step(_retract(space, X[k], -h * dx), U[k] - h * du)
            fd = (_local(space, f0, fp) - _local(space, f0, fm)) / (2 * h)
            assert np.allclose(fd, A[k] @ dx + B[k] @ du, atol=1e-6 * (1 + np.abs(fd).max()))


@pytest.mark.parametrize("key", ["so3-tracking", "drone"])
def test_cost_derivatives_match_finite_differences(scenarios, key):
    sc = scenarios[key, "euler"]
    cost, space = sc.problem.cost, sc.problem.space
    rng = np.random.default_rng(4)
    ref = sc.problem.x_ref[:1]
    q = _random_state(space, rng, ref[0])[None]
    u = rng.standard_normal((1, cost.nu))
    wq = rng.uniform(0.5, 2, (1, space.nx))
    wu = rng.uniform(0.5, 2, (1, cost.nu))
    uref = np.zeros((1, cost.nu))
    _, lx, lxx, lu, luu = cost.derivatives(q, u, ref, uref, wq, wu)

    def value(dx, du):
        return cost.values(_retract(space, q[0], dx)[None], u + du, ref, uref, wq, wu)[0]

    h = 1e-5
    eye = np.eye(space.nx)
    g = np.array([(value(h * e, 0) - value(-h * e, 0)) / (2 * h) for e in eye])
    assert np.allclose(g, lx[0], atol=1e-6 * (1 + np.abs(g).max()))
    gu = np.array(
        [(value(0 * eye[0], h * e) - value(0 * eye[0], -h * e)) / (2 * h) for e in np.eye(cost.nu)]
    )
    assert np.allclose(gu, lu[0], atol=1e-6)
    assert np.allclose(luu[0], 2 * np.diag(wu[0]))
    # Exact Hessian of the pullback ξ ↦ l(x ⊕ ξ) (second-order retraction ⇒ symmetric).
    H = np.zeros((space.nx, space.nx))
    h = 1e-4
    for i in range(space.nx):
        for j in range(space.nx):
            ei, ej = h * eye[i], h * eye[j]
            H[i, j] = (
                value(ei + ej, 0) - value(ei - ej, 0) - value(ej - ei, 0) + value(-ei - ej, 0)
            ) / (4 * h * h)
    assert np.allclose(H, lxx[0], atol=1e-4 * (1 + np.abs(H).max()))


def _linear_problem(N=12, n=4, m=2, seed=0, scale=1.0):
    rng = np.random.default_rng(seed)
    Ad = scale * (np.eye(n) + 0.1 * rng.standard_normal((n, n)))
    Bd = rng.standard_normal((n, m))
    space = StateSpace([R(n)])
    dyn = DiscreteDynamics(
        f"lin{n}{m}_{seed}_{int(scale * 100)}",
        space,
        m,
        lambda parts, u: [cs.mtimes(cs.DM(Ad), parts[0]) + cs.mtimes(cs.DM(Bd), u)],
    )
    q, r = rng.uniform(0.5, 2, n), rng.uniform(0.1, 1, m)
    problem = ShootingProblem(
        dynamics=dyn,
        cost=TrackingCost(space, m),
        x0=rng.standard_normal(n),
        x_ref=rng.standard_normal((N + 1, n)),
        u_ref=rng.standard_normal((N, m)),
        state_weights=q,
        input_weights=r,
        terminal_weights=3 * q,
    )
    return problem, Ad, Bd, q, r


def test_backward_pass_on_lq_problem_is_exact_lqr():
    problem, Ad, Bd, q, r = _linear_problem()
    N, n, m = problem.N, 4, 2
    res = solve_ilqr(problem, ILQROptions(multiple_shooting=False, max_iter=1, tol=1e-300))
    # Independent solution: the equality-constrained QP in (x, u), solved by its KKT system.
    nz = (N + 1) * n + N * m
    H = np.zeros((nz, nz))
    c = np.zeros(nz)
    for k in range(N + 1):
        w = q if k < N else 3 * q
        sl = slice(k * n, (k + 1) * n)
        H[sl, sl] = 2 * np.diag(w)
        c[sl] = -2 * w * problem.x_ref[k]
    off = (N + 1) * n
    for k in range(N):
        sl = slice(off + k * m, off + (k + 1) * m)
        H[sl, sl] = 2 * np.diag(r)
        c[sl] = -2 * r * problem.u_ref[k]
    E = np.zeros(((N + 1) * n, nz))
    e = np.zeros((N + 1) * n)
    E[:n, :n] = np.eye(n)
    e[:n] = problem.x0
    for k in range(N):
        rows = slice((k + 1) * n, (k + 2) * n)
        E[rows, (k + 1) * n : (k + 2) * n] = np.eye(n)
        E[rows, k * n : (k + 1) * n] = -Ad
        E[rows, off + k * m : off + (k + 1) * m] = -Bd
    kkt = np.block([[H, E.T], [E, np.zeros((len(e), len(e)))]])
    sol = np.linalg.solve(kkt, np.concatenate([-c, e]))
    assert np.allclose(res.u, sol[off:nz].reshape(N, m), atol=1e-9)
    assert np.allclose(res.x, sol[:off].reshape(N + 1, n), atol=1e-9)
    # Feedback gains equal the finite-horizon discrete Riccati recursion.
    P = 2 * np.diag(3 * q)
    for k in range(N - 1, -1, -1):
        Kk = -np.linalg.solve(2 * np.diag(r) + Bd.T @ P @ Bd, Bd.T @ P @ Ad)
        assert np.allclose(res.K[k], Kk, atol=1e-9)
        P = 2 * np.diag(q) + Ad.T @ P @ (Ad + Bd @ Kk)
        P = 0.5 * (P + P.T)
    converged = solve_ilqr(problem, ILQROptions(multiple_shooting=True, max_iter=3))
    assert converged.success and converged.iterations == 1


def test_ms_with_zero_defects_takes_the_ss_step(scenarios):
    problem = scenarios["pendulum", "euler"].problem
    U0 = 0.1 * np.random.default_rng(1).standard_normal((problem.N, 3))
    X0 = problem.dynamics.simulate(problem.x0, U0)
    ss = solve_ilqr(problem, ILQROptions(multiple_shooting=False, max_iter=1), u_init=U0)
    ms = solve_ilqr(problem, ILQROptions(multiple_shooting=True, max_iter=1), x_init=X0, u_init=U0)
    assert ms.history.defect_norm[0] < 1e-12
    assert np.allclose(ms.K, ss.K, atol=1e-8) and np.allclose(ms.k, ss.k, atol=1e-8)
    assert np.allclose(ms.x, ss.x, atol=1e-10) and np.allclose(ms.u, ss.u, atol=1e-10)


def test_diverging_full_step_rollout_is_a_failure_without_nan():
    space = StateSpace([R(1)])
    dyn = DiscreteDynamics(
        "cubic_blowup", space, 1, lambda parts, u: [parts[0] + 0.3 * parts[0] ** 3 + 0.01 * u]
    )
    problem = ShootingProblem(
        dynamics=dyn,
        cost=TrackingCost(space, 1),
        x0=np.ones(1),
        x_ref=np.zeros((51, 1)),
        u_ref=np.zeros((50, 1)),
        state_weights=np.ones(1),
        input_weights=np.ones(1),
        terminal_weights=np.ones(1),
    )
    for opts in (ILQROptions(max_iter=20), ILQROptions(line_search=True, max_iter=20)):
        res = solve_ilqr(problem, opts)
        assert not res.success
        assert np.all(np.isfinite(res.x)) and np.all(np.isfinite(res.u))
        assert np.isfinite(res.objective)
    full = solve_ilqr(problem, ILQROptions(max_iter=20))
    assert full.status is ILQRStatus.NUMERICAL_ERROR and "diverged" in full.message
    # An unstable linear system whose adjoint overflows: non-finite gradient, not "converged".
    linear, *_ = _linear_problem(N=400, scale=3.0, seed=2)
    res = solve_ilqr(linear, ILQROptions(max_iter=20))
    assert res.status is ILQRStatus.NUMERICAL_ERROR
    assert np.all(np.isfinite(res.x)) and np.isfinite(res.objective)


def test_bad_input_gives_clear_errors(scenarios):
    p = scenarios["so3-tracking", "euler"].problem
    kw = dict(
        dynamics=p.dynamics,
        cost=p.cost,
        x0=p.x0,
        x_ref=p.x_ref,
        u_ref=p.u_ref,
        state_weights=p.state_weights,
        input_weights=p.input_weights,
        terminal_weights=p.terminal_weights,
    )
    bad_x0 = p.x0.copy()
    bad_x0[0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        ShootingProblem(**{**kw, "x0": bad_x0})
    off = p.x0.copy()
    off[:9] = 2 * np.eye(3).ravel()
    with pytest.raises(InputError, match="orthogonal"):
        ShootingProblem(**{**kw, "x0": off})
    with pytest.raises(InputError, match="shape"):
        ShootingProblem(**{**kw, "x0": p.x0[:5]})
    with pytest.raises(InputError, match="input reference"):
        ShootingProblem(**{**kw, "u_ref": p.u_ref[:-1]})
    with pytest.raises(InputError, match="state weights"):
        ShootingProblem(**{**kw, "state_weights": np.ones(4)})
    ref = p.x_ref.copy()
    ref[3, -1] = np.inf
    with pytest.raises(InputError, match="state reference"):
        ShootingProblem(**{**kw, "x_ref": ref})
    with pytest.raises(InputError, match="u_init"):
        solve_ilqr(p, u_init=np.full((p.N, 3), np.nan))
    with pytest.raises(InputError):
        ILQROptions(tol=-1.0)
    with pytest.raises(InputError, match="SE"):
        StateSpace([SE3, R(6)]).check(np.zeros(22))


@pytest.mark.parametrize("key", ["so3-tracking", "pendulum"])
def test_thesis_scenarios_ms_converges_and_ss_is_trapped(scenarios, key):
    sc = scenarios[key, "euler"]
    ms = solve_ilqr(sc.problem, ILQROptions(max_iter=sc.max_iter))
    ss = solve_ilqr(sc.problem, ILQROptions(multiple_shooting=False, max_iter=sc.max_iter))
    assert ms.success, ms
    assert ms.grad_norm < 1e-8 and ms.defect_norm < 1e-8
    assert ms.group_violation <= 1e-12 and ss.group_violation <= 1e-12
    assert max(ms.history.group_violation) <= 1e-12
    # SS-iLQR from the zero-input rollout ends in a worse local solution (thesis §4-3, §4-5).
    assert ss.objective > 1.5 * ms.objective
    assert ms.iterations <= {"so3-tracking": 10, "pendulum": 19}[key]


def test_input_bounds_by_augmented_lagrangian(scenarios):
    problem = scenarios["pendulum", "euler"].problem
    free = solve_ilqr(problem, ILQROptions(max_iter=100))
    assert np.abs(free.u).max() > 10  # the bound below is active
    res = solve_ilqr_bounded(problem, -8.0, 8.0, ILQROptions(max_iter=100))
    assert res.success, res
    assert np.abs(res.u).max() <= 8.0 + 1e-6
    assert res.group_violation <= 1e-12
    assert res.objective >= free.objective
    with pytest.raises(InputError, match="lower <= upper"):
        solve_ilqr_bounded(problem, 1.0, -1.0)


def test_ddp_dynamics_second_derivatives_and_quadratic_convergence(scenarios):
    sc = scenarios["drone", "euler"]
    dyn, space = sc.problem.dynamics, sc.problem.space
    rng = np.random.default_rng(5)
    X = np.stack([_random_state(space, rng, sc.problem.x_ref[k]) for k in range(2)])
    U = rng.standard_normal((1, dyn.nu))
    H = dyn.second_derivatives(X, U)[0]
    nx, nz = space.nx, space.nx + dyn.nu
    f0 = dyn.step(X[0], U[0])

    def g(z):
        return _local(space, f0, dyn.step(_retract(space, X[0], z[:nx]), U[0] + z[nx:]))

    h, e = 1e-4, np.eye(nz)
    for i, j in [(0, 0), (3, 7), (5, 12), (13, 14), (2, 15)]:
        a, b = h * e[i], h * e[j]
        fd = (g(a + b) - g(a - b) - g(b - a) + g(-a - b)) / (4 * h * h)
        assert np.allclose(fd, H[:, i, j], atol=1e-6)
    a = scenarios["so3-tracking", "euler"]
    ilqr = solve_ilqr(a.problem, ILQROptions(max_iter=50))
    ddp = solve_ilqr(a.problem, ILQROptions(max_iter=50, second_order=True))
    assert ddp.success and ddp.method == "ms-ddp"
    assert ddp.iterations < ilqr.iterations
    assert abs(ddp.objective - ilqr.objective) < 1e-8 * ilqr.objective


def test_verbose_log_and_history(scenarios, capsys):
    problem = scenarios["pendulum", "euler"].problem
    seen = []
    res = solve_ilqr(
        problem, ILQROptions(max_iter=3), verbose=True, callback=lambda i, h: seen.append(i)
    )
    out = capsys.readouterr().out
    assert res.status is ILQRStatus.MAX_ITER and not res.success
    assert seen == [0, 1, 2, 3] and len(res.history) == 4
    assert out.count("\n") == 5 and out.startswith("iter")


def test_bench_ilqr_writes_the_issue_schema(tmp_path):
    out = tmp_path / "ilqr"
    rc = main(
        [
            "bench",
            "ilqr",
            "--scenario",
            "pendulum",
            "--methods",
            "ss-ilqr,ms-ilqr,ipopt-quaternion",
            "--repeats",
            "1",
            "--no-lgvi",
            "--out",
            str(out),
        ]
    )
    assert rc == 0
    summary = json.loads((out / "summary.json").read_text())
    rows = summary["scenarios"]["pendulum"]
    assert set(rows) == {"ss-ilqr", "ms-ilqr", "ipopt-quaternion"}
    keys = {
        "converged",
        "iterations",
        "time_s",
        "time_per_iter_s",
        "final_cost",
        "max_defect",
        "group_violation",
    }
    for row in rows.values():
        assert set(row) == keys
        assert isinstance(row["converged"], bool) and isinstance(row["iterations"], int)
    assert rows["ms-ilqr"]["converged"] and rows["ms-ilqr"]["group_violation"] <= 1e-12
    md = (out / "results.md").read_text()
    assert "| pendulum | ms-ilqr |" in md and "55.96" in md  # thesis' numbers beside ours
    assert (out / "pendulum-convergence.png").exists()
    assert (
        main(
            [
                "bench",
                "ilqr",
                "--scenario",
                "pendulum",
                "--methods",
                "nope",
                "--out",
                str(tmp_path / "x"),
            ]
        )
        == 2
    )


def test_fddp_baseline_on_so3_tracking(scenarios):
    from mbplan.benchmarks.ilqr.fddp import fddp_baseline

    sc = scenarios["so3-tracking", "euler"]
    run = fddp_baseline(sc)
    assert run.converged and run.iterations <= sc.max_iter
    assert run.x.shape == sc.problem.x_ref.shape and np.all(np.isfinite(run.u))
    # Crocoddyl's semi-implicit Euler solves a nearby problem: close to, not equal to, MS-iLQR's.
    ms = solve_ilqr(sc.problem, ILQROptions(max_iter=50))
    assert abs(sc.problem.cost_value(run.x, run.u) - ms.objective) < 0.2 * ms.objective
