"""The KKT factorized through the joint elimination plan (mbplan.solvers.kkt.reduced.system) against
the full LDLᵀ and the dense eigenvalues: same inertia (also wrong and singular), same steps,
the cases it leaves to the full factorization, and a RIPM solve with kkt_method="reduced"."""

import numpy as np
import pytest
import scipy.sparse as sp
from reference_problems import hs071

from mbplan.errors import InputError
from mbplan.formulations import maximal_layout
from mbplan.formulations.maximal_layout import JointEliminationPlans, joint_elimination_plan
from mbplan.solvers import RIPMOptions, solve_ripm
from mbplan.solvers.kkt.elimination import EliminationPlan
from mbplan.solvers.kkt.reduced.system import ReducedKKTSystem, kkt_system
from mbplan.solvers.kkt.system import Inertia, KKTSystem
from mbplan.tasks.paper import iiwa_obstacle, iiwa_obstacle_starts
from mbplan.tasks.speed import chain_task, maximal_ripm_problem
from mbplan.workspace import Workspace


def _kkt(problem, x0, seed):
    rng = np.random.default_rng(seed)
    z = rng.uniform(0.5, 2.0, problem.n_ineq)
    ev = problem.evaluate(x0, 1.0, rng.normal(size=problem.n_eq), z)
    blocks = (ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian)
    full = KKTSystem(problem.n, problem.n_eq, problem.n_ineq)
    full.set_matrices(*blocks)
    red = ReducedKKTSystem(
        problem.n, problem.n_eq, problem.n_ineq, problem.elimination_plan, strict=True
    )
    red.set_matrices(*blocks)
    return full, red, -rng.uniform(0.5, 2.0, problem.n_ineq) / z, rng


@pytest.fixture(
    scope="module",
    params=[
        "chain4",
        "chain8",
        "iiwa",
        "chain4+wrench",
        "iiwa+wrench",
        "chain8+3",
        "chain8+wrench+3",
    ],
)
def systems(request):
    task, *rest = request.param.split("+")
    wrench = "wrench" in rest
    segment = int(rest[-1]) if rest and rest[-1].isdigit() else None  # bodies per segment
    if task == "iiwa":
        ocp = iiwa_obstacle(iiwa_obstacle_starts(3, 0, "com")[1], N=6, constraint="com")
        problem, x0 = maximal_ripm_problem(ocp)
    else:
        problem, x0 = maximal_ripm_problem(chain_task(int(task[5:]), N=5), "linear")
    # the joints alone, or the joint wrenches eliminated too (inverse dynamics); in segments
    problem.elimination_plan = JointEliminationPlans(problem, forces=wrench, segment=segment)
    return problem, x0, *_kkt(problem, x0, 1)


def _diag(problem, primal, dual_eq, sigma):
    return np.concatenate(
        [np.broadcast_to(primal, (problem.n,)), np.full(problem.n_eq, dual_eq), sigma]
    )


@pytest.mark.parametrize("delta_w", [0.0, 1e-4, "varying", -3.0])
def test_reduced_inertia_and_step_equal_the_full_factorization(systems, delta_w):
    problem, _, full, red, sigma, rng = systems
    primal = rng.uniform(0.0, 1e-2, problem.n) if delta_w == "varying" else delta_w
    diag = _diag(problem, primal, 0.0, sigma)
    inertia, full_inertia = red.factorize(diag, 1e-9), full.factorize(diag, 1e-9)
    eig = np.linalg.eigvalsh(full.matrix().toarray())
    assert inertia == Inertia(int(np.sum(eig > 0)), int(np.sum(eig < 0)), 0)
    if np.abs(eig).min() > 1e-7:  # else ±1e-9 on the full matrix's pivots may flip a sign
        assert full_inertia == inertia
    assert red.reduction.nr + len(red.reduction.kept) < 0.6 * problem.n + problem.n_eq
    m = problem.n_eq + problem.n_ineq
    if delta_w == -3.0:  # wrong inertia: the correction rejects both
        assert inertia.negative > m
        return
    assert inertia.negative == m
    b = rng.normal(size=full.dim)
    x_full, (x_red, r_red) = full.solve(b)[0], red.solve(b)
    assert red.n_fallbacks == 0 and r_red <= 1e-10
    assert np.abs(x_red - x_full).max() <= 1e-6 * np.abs(x_full).max()  # both backward stable
    scale = np.abs(x_red).max() + np.abs(b).max()
    assert np.abs(full.matvec(x_red) - b).max() <= 1e-10 * scale


def test_new_values_without_inequality_rows_are_reduced_afresh(systems):
    """No inequality rows (``Σ`` empty): every new matrix of the same pattern gets its own
    ``Tᵀ H T``; steps and inertia follow the full factorization's matrix by matrix."""
    problem, x0, _, _, _, rng = systems
    full = KKTSystem(problem.n, problem.n_eq, 0)
    red = ReducedKKTSystem(problem.n, problem.n_eq, 0, problem.elimination_plan, strict=True)
    diag = np.concatenate([np.full(problem.n, 1e-3), np.zeros(problem.n_eq)])
    b = rng.normal(size=full.dim)
    for scale in (1.0, 3.0):
        ev = problem.evaluate(x0, scale, rng.normal(size=problem.n_eq), np.ones(problem.n_ineq))
        for kkt in (full, red):
            kkt.set_matrices(ev.hessian_lower, ev.eq_jacobian, None)
        assert red.factorize(diag, 1e-9) == full.factorize(diag, 1e-9)
        x_full, (x_red, ratio) = full.solve(b)[0], red.solve(b)
        assert red.n_fallbacks == 0 and ratio <= 1e-10
        assert np.abs(x_red - x_full).max() <= 1e-6 * np.abs(x_full).max()


def test_singular_matrix_is_rejected_by_both(systems):
    """``H = 0``, ``A_I = 0``: the matrix is singular on ``A_E``'s null space; each method either
    reports a wrong inertia or a solve whose residual refinement cannot reduce."""
    problem, x0 = systems[:2]
    full, red, sigma, rng = _kkt(problem, x0, 3)
    ev = problem.evaluate(x0, 0.0)
    for kkt in (full, red):
        kkt.set_matrices(ev.hessian_lower * 0.0, ev.eq_jacobian, ev.ineq_jacobian * 0.0)
    diag = _diag(problem, 0.0, 0.0, sigma)
    b = rng.normal(size=full.dim)
    m = problem.n_eq + problem.n_ineq
    for kkt in (full, red):
        inertia = kkt.factorize(diag, 1e-9)
        wrong = inertia is None or inertia.negative != m
        assert wrong or kkt.solve(b)[1] > 1e-5


def test_regularized_jacobian_block_goes_to_the_full_factorization(systems):
    problem, _, full, red, sigma, rng = systems
    diag = _diag(problem, 1e-4, -1e-8, sigma)  # δ_c > 0
    assert red.factorize(diag, 1e-9) == full.factorize(diag, 1e-9)
    b = rng.normal(size=full.dim)
    assert np.abs(red.solve(b)[0] - full.solve(b)[0]).max() == 0.0


def test_fallback_after_new_values_factorizes_the_current_matrices(systems):
    """The full system gets the matrices lazily (only on a fallback): after a reduced
    factorization of one matrix and new values of the same pattern, a ``δ_c > 0`` fallback
    factorizes the new matrix, bitwise as a full system given it directly."""
    problem, x0, _, _, sigma, rng = systems
    full_a, red, _, _ = _kkt(problem, x0, 5)
    red.factorize(_diag(problem, 1e-4, 0.0, sigma), 1e-9)  # reduced, first values
    z = rng.uniform(0.5, 2.0, problem.n_ineq)
    ev = problem.evaluate(x0, 2.0, rng.normal(size=problem.n_eq), z)
    blocks = (ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian)
    full = KKTSystem(problem.n, problem.n_eq, problem.n_ineq)
    for kkt in (full, red):
        kkt.set_matrices(*blocks)
    diag = _diag(problem, 1e-4, -1e-8, sigma)  # δ_c > 0: the full factorization
    assert red.factorize(diag, 1e-9) == full.factorize(diag, 1e-9)
    b = rng.normal(size=full.dim)
    x_red, x_full = red.solve(b)[0], full.solve(b)[0]
    assert np.abs(x_red - x_full).max() == 0.0
    full_a.factorize(diag, 1e-9)
    assert np.abs(full_a.solve(b)[0] - x_full).max() > 0.0  # the first values' step differs


def test_nonnegative_inequality_diagonal_goes_to_the_full_factorization(systems):
    """The inequality rows are folded into ``K_r`` only for ``D_I < 0`` (the RIPM's ``-Σ⁻¹``)."""
    problem, _, full, red, sigma, rng = systems
    diag = _diag(problem, 1e-4, 0.0, -sigma)
    reduced = red.n_reduced
    assert red.factorize(diag, 1e-9) == full.factorize(diag, 1e-9)
    assert red.n_reduced == reduced
    b = rng.normal(size=full.dim)
    assert np.abs(red.solve(b)[0] - full.solve(b)[0]).max() == 0.0


@pytest.mark.parametrize("method", ["full", "reduced"])
def test_least_squares_y0_through_the_newton_system_is_the_least_squares_solution(method):
    """The start's ``y₀`` (kept: ``constr_mult_init_max`` large), solved with the Newton step's
    own system (``H``, ``A_I`` with zero values), minimizes ``‖∇f + A_Iᵀz₀ + A_Eᵀy‖`` as a
    dense least-squares solve does, with the full and with the reduced factorization: the same
    minimum, the normal equations met to the refinement's residual ratio (``A_E`` has condition
    ~4e4 here: ``y`` itself agrees to ~1e-5 relative)."""
    problem, x0 = maximal_ripm_problem(chain_task(4, N=5), "linear")
    opts = RIPMOptions(max_iter=0, constr_mult_init_max=1e12, kkt_method=method)
    y0 = solve_ripm(problem, x0, opts).y
    ev = problem.evaluate(x0, 1.0)
    rhs = -(ev.gradient + ev.ineq_jacobian.T @ np.full(problem.n_ineq, opts.bound_mult_init_val))
    a = ev.eq_jacobian.toarray()
    expected = np.linalg.lstsq(a.T, rhs, rcond=None)[0]
    r0, r = rhs - a.T @ y0, rhs - a.T @ expected
    assert np.linalg.norm(r0) <= (1 + 1e-10) * np.linalg.norm(r)
    assert np.abs(a @ r0).max() <= 1e-8 * np.abs(expected).max()
    assert np.abs(y0 - expected).max() <= 1e-4 * np.abs(expected).max()


def test_least_squares_y0_goes_through_the_reduction():
    """With ``kkt_method="reduced"`` the start's least-squares system is factorized through the
    reduction, not by the full fallback (which would also pass the test above)."""
    from mbplan.solvers.ripm.driver import _main_phase

    problem, x0 = maximal_ripm_problem(chain_task(4, N=5), "linear")
    opts = RIPMOptions(max_iter=0, constr_mult_init_max=1e12, kkt_method="reduced")
    ripm = _main_phase(problem, opts)
    ripm.run(x0, None, None, None)
    kkt = ripm.sh.kkt
    assert kkt.n_reduced == 1 and kkt.n_fallbacks == 0
    assert kkt.full.n_factorizations == 0


def test_min_refinement_reaches_the_reduced_and_the_full_solves(monkeypatch):
    """``ReducedKKTSystem.solve(min_refinement=)`` is what the reduced system's solves and the
    full factorization (reduction inactive) are called with."""
    problem, x0 = maximal_ripm_problem(chain_task(4, N=5), "linear")
    _, red, sigma, rng = _kkt(problem, x0, 3)
    seen = []
    solve = KKTSystem.solve

    def spy(self, rhs, max_refinement=10, ratio_max=1e-10, min_refinement=1):
        seen.append((self is red.full, min_refinement))
        return solve(self, rhs, max_refinement, ratio_max, min_refinement)

    monkeypatch.setattr(KKTSystem, "solve", spy)
    assert red.factorize(_diag(problem, 1e-4, 0.0, sigma), 1e-9) is not None
    b = rng.normal(size=red.dim)
    for minimum in (0, 1):
        seen.clear()
        red.solve(b, 10, 1e-8, min_refinement=minimum)
        assert seen and all(not full and m == minimum for full, m in seen)
    red._active = False  # as after a breakdown of the reduction: the full factorization
    red._full().factorize(_diag(problem, 1e-4, 0.0, sigma), 1e-9)
    seen.clear()
    red.solve(b, 10, 1e-8, min_refinement=0)
    assert seen == [(True, 0)]


def test_joint_layout_rejects_joint_rows_that_are_empty_or_span_knots():
    """A joint constraint row group without entries, or with an entry on another knot's body,
    is not a joint of one knot: :func:`maximal_layout` says so instead of writing a wrong
    layout."""
    problem, x0 = maximal_ripm_problem(chain_task(2, N=4), "linear")
    jac = problem.evaluate(x0, 1.0).eq_jacobian.tolil()
    rows = next(r for name, r in problem.term_rows("eq").items() if "joint_constraints" in name)
    empty = jac.copy()
    for row in rows[0]:
        empty[row, :] = 0.0
    with pytest.raises(InputError, match="without entries"):
        maximal_layout.maximal_layout(problem, empty.tocsr())
    spanning = jac.copy()
    other_knot = jac.rows[rows[-1][0]][0]  # a column of the last knot's joint rows
    spanning[rows[0][0], other_knot] = 1.0
    with pytest.raises(InputError, match="outside one knot"):
        maximal_layout.maximal_layout(problem, spanning.tocsr())


def test_elimination_plans_are_kept_in_a_workspace_per_layout():
    """Two problems of one family and workspace share the layout and the plan; other options,
    another plan; another pattern, another layout; no workspace, a problem's own."""
    ws = Workspace()
    plans, layouts = [], []
    for _ in range(2):
        problem, x0 = maximal_ripm_problem(chain_task(4, N=5), "linear")
        jac = problem.evaluate(x0, 1.0).eq_jacobian
        plans.append(joint_elimination_plan(problem, jac, workspace=ws))
        layouts.append(maximal_layout.maximal_layout(problem, jac, ws))
    assert plans[0] is plans[1] and layouts[0] is layouts[1]
    assert joint_elimination_plan(problem, jac) is not plans[0]
    fresh = maximal_layout._layout(problem, jac)
    assert fresh.key() == layouts[0].key()
    coo = jac.tocoo()
    col = np.setdiff1d(np.arange(jac.shape[1]), jac.indices[jac.indptr[0] : jac.indptr[1]])[-1]
    extra = sp.csr_matrix(
        (np.r_[coo.data, 1.0], (np.r_[coo.row, 0], np.r_[coo.col, col])), shape=jac.shape
    )
    assert extra.nnz == jac.nnz + 1  # another pattern: built anew
    assert maximal_layout.maximal_layout(problem, extra, ws) is not layouts[0]
    other = joint_elimination_plan(problem, jac, segment=2, workspace=ws)
    assert other is not plans[0] and other.n_groups < plans[0].n_groups


@pytest.mark.parametrize(("wrench", "segment"), [(False, None), (True, None), (False, 2)])
def test_ripm_reduced_solve_equals_full(wrench, segment):
    problem, x0 = maximal_ripm_problem(chain_task(4, N=8), "linear")
    opts = RIPMOptions(tol=1e-6, max_iter=100)
    full = solve_ripm(problem, x0, opts)
    problem.elimination_plan = JointEliminationPlans(problem, forces=wrench, segment=segment)
    red = solve_ripm(problem, x0, opts.replace(kkt_method="reduced"))
    assert full.status.name == red.status.name == "CONVERGED"
    assert abs(full.iterations - red.iterations) <= 1
    assert abs(full.objective - red.objective) <= 1e-6 * max(1.0, abs(full.objective))


def test_default_plan_eliminates_the_wrenches_of_shallow_trees(monkeypatch):
    problem, x0 = maximal_ripm_problem(chain_task(4, N=5), "linear")
    jac = problem.evaluate(x0, 1.0).eq_jacobian
    blocks = joint_elimination_plan(problem, jac, forces=False).n_blocks
    assert blocks == 4 * 5  # a state block per body and knot
    assert joint_elimination_plan(problem, jac).n_blocks == 2 * blocks  # and a wrench block
    monkeypatch.setattr(maximal_layout, "WRENCH_MAX_DEPTH", 3)
    assert joint_elimination_plan(problem, jac).n_blocks == blocks


def test_default_plan_of_deep_trees_is_joints_only_in_segments():
    """Deeper than ``WRENCH_MAX_DEPTH``: no wrench blocks; every ``SEGMENT_DEPTH``-th body of a
    path keeps its maximal coordinates (a state block without local rows, no row group)."""
    problem, x0 = maximal_ripm_problem(chain_task(9, N=4), "linear")
    jac = problem.evaluate(x0, 1.0).eq_jacobian
    plan = joint_elimination_plan(problem, jac)
    assert maximal_layout.WRENCH_MAX_DEPTH == maximal_layout.SEGMENT_DEPTH == 8
    assert plan.n_blocks == 9 * 4  # state blocks only
    local = (plan.block_rows >= 0).sum(axis=1).reshape(4, 9)
    assert np.all(local[:, 8] == 0) and np.all(local[:, :8] > 0)  # body 8 at depth 9 is cut
    assert plan.n_groups == 8 * 3  # steps 1…N-1, uncut bodies
    one = joint_elimination_plan(problem, jac, segment=9)
    assert one.n_blocks == 9 * 4 and np.all((one.block_rows >= 0).sum(axis=1) > 0)
    with pytest.raises(InputError, match="segment"):
        joint_elimination_plan(problem, jac, segment=0)


def test_segments_keep_the_cut_bodies_coordinates_in_the_reduced_matrix():
    """A cut body's twelve state coordinates stay in ``K_r`` at every knot; its joint
    constraints and kinematics rows stay among ``K_r``'s rows."""
    problem, x0 = maximal_ripm_problem(chain_task(4, N=5), "linear")
    jac = problem.evaluate(x0, 1.0).eq_jacobian
    lay = maximal_layout.maximal_layout(problem, jac)
    problem.elimination_plan = JointEliminationPlans(problem, forces=False, segment=2)
    red = _kkt(problem, x0, 0)[1].reduction
    cut = 2  # depth 3
    assert np.isin(lay.s_cols[1:, cut], red.red_cols).all()
    assert np.isin(lay.con_rows[1:, cut], red.kept).all()
    assert np.isin(lay.kin_rows[:, cut], red.kept).all()
    # the others: 11 dependent coordinates at knot 1 (six kinematics rows, five constraints),
    # 10 at knots 2…N (five replaced kinematics rows, five constraints)
    assert np.isin(lay.s_cols[1:, [0, 1, 3]], red.dep).sum() == 3 * (11 + 10 * 4)


def test_wrench_blocks_leave_the_generalized_coordinates():
    """With the joint wrenches eliminated, ``K_r`` keeps per knot and joint its two free state
    coordinates and one kinematics row (and no inequality rows: folded in)."""
    problem, x0 = maximal_ripm_problem(chain_task(4, N=5), "linear")
    problem.elimination_plan = JointEliminationPlans(problem, forces=True)
    red = _kkt(problem, x0, 0)[1]
    joints = 4  # the chain's bodies
    assert red.reduction.nr == 2 * joints * 5 - joints  # knot 1: one free coordinate each
    assert len(red.reduction.kept) == joints * 5 - joints  # steps 1…N-1: one kinematics row


def test_kkt_method_choice_and_errors(systems):
    problem = systems[0]
    assert type(kkt_system(problem, "auto", "amd")) is ReducedKKTSystem
    assert type(kkt_system(problem, "full", "amd")) is KKTSystem
    with pytest.raises(InputError, match="kkt_method"):
        RIPMOptions(kkt_method="cholesky")
    nlp = hs071()
    assert type(kkt_system(nlp, "auto", "amd")) is KKTSystem
    with pytest.raises(InputError, match="no elimination_plan"):
        kkt_system(nlp, "reduced", "amd")
    one = np.zeros((1, 2), np.int64)
    with pytest.raises(InputError, match="more local rows than columns"):
        EliminationPlan(
            one[:0], one[:0], one[:0], one[:0], np.array([-1]), np.array([[0, 1, 2]]), one[:, :1]
        )
    with pytest.raises(InputError, match="1 of 1 groups in no block"):  # rows it replaces
        EliminationPlan(one, one, one[:, :1], one, np.array([-1]), one[:, :1], one)


def test_breakdown_and_invalid_plan_fall_back_to_the_full_factorization(systems):
    problem, x0 = systems[:2]
    full, red, sigma, rng = _kkt(problem, x0, 2)  # own systems: the fixture's stay as they are
    ev = problem.evaluate(x0, 1.0, rng.normal(size=problem.n_eq), np.ones(problem.n_ineq))
    dead = ev.eq_jacobian.copy()
    dead.data[:] = 0.0  # same pattern, every local row zero: the reduction breaks down
    diag = _diag(problem, 1.0, 0.0, sigma)
    for kkt in (full, red):
        kkt.set_matrices(ev.hessian_lower, dead, ev.ineq_jacobian)
    assert red.factorize(diag, 1e-9) == full.factorize(diag, 1e-9)
    assert not red._active and red.reduction is not None

    def invalid(_jac):
        raise InputError("no plan here")

    lenient = ReducedKKTSystem(problem.n, problem.n_eq, problem.n_ineq, invalid)
    lenient.set_matrices(ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian)
    full.set_matrices(ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian)
    assert lenient.reduction is None
    assert lenient.factorize(diag, 1e-9) == full.factorize(diag, 1e-9)
    strict = ReducedKKTSystem(problem.n, problem.n_eq, problem.n_ineq, invalid, strict=True)
    with pytest.raises(InputError, match="no plan here"):
        strict.set_matrices(ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian)


def test_each_system_picks_rows_and_columns_on_its_own_first_matrix():
    """The replaced rows and dependent columns are picked on the values of a system's first
    matrix of the pattern, never on another problem's (even with a shared workspace), and
    picked again on a later matrix of the system that breaks them down (not the full
    factorization for the rest of its solve: the arm sweep's z1)."""
    problem, x0 = maximal_ripm_problem(chain_task(4, N=5), "linear")
    problem.elimination_plan = JointEliminationPlans(problem, forces=True)
    rng = np.random.default_rng(4)
    z = rng.uniform(0.5, 2.0, problem.n_ineq)
    ev = problem.evaluate(x0, 1.0, rng.normal(size=problem.n_eq), z)
    plan = problem.elimination_plan(ev.eq_jacobian)
    own = plan.block_cols[0][plan.block_cols[0] >= 0]
    probe = ReducedKKTSystem(problem.n, problem.n_eq, problem.n_ineq, lambda _: plan)
    probe.set_matrices(ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian)
    col = np.setdiff1d(own, probe.reduction.dep)[0]  # a free column of block 0

    def scaled(s):  # A_E with that column scaled: the plan's row spans hold for every s
        jac = ev.eq_jacobian.copy()
        jac.data[jac.indices == col] *= s
        return jac

    diag = _diag(problem, 1e-4, 0.0, -rng.uniform(0.5, 2.0, problem.n_ineq) / z)
    b = rng.normal(size=probe.dim)
    ws = Workspace()

    def system() -> ReducedKKTSystem:
        n, me, mi = problem.n, problem.n_eq, problem.n_ineq
        return ReducedKKTSystem(n, me, mi, lambda _: plan, workspace=ws)

    def choice(red: ReducedKKTSystem, s: float) -> tuple:
        """The choice ``red`` factorizes and solves ``A_E`` scaled by ``s`` with."""
        full = KKTSystem(problem.n, problem.n_eq, problem.n_ineq)
        reduced = red.n_reduced
        for kkt in (red, full):
            kkt.set_matrices(ev.hessian_lower, scaled(s), ev.ineq_jacobian)
        inertia, full_inertia = red.factorize(diag, 1e-9), full.factorize(diag, 1e-9)
        eig = np.linalg.eigvalsh(full.matrix().toarray())
        assert red.n_reduced == reduced + 1
        assert inertia == full_inertia == Inertia(int(np.sum(eig > 0)), int(np.sum(eig < 0)), 0)
        x_full, (x_red, ratio) = full.solve(b)[0], red.solve(b)
        assert red.n_fallbacks == 0 and ratio <= 1e-10
        assert np.abs(x_red - x_full).max() <= 1e-6 * np.abs(x_full).max()
        return red.reduction.dep_key

    red = system()
    first = choice(red, 1e6)
    assert col in red.reduction.dep  # picked on the scaled column
    again = choice(red, 0.0)  # broke down on the zeroed column: picked again on these values
    assert again != first
    assert choice(system(), 0.0) == again  # a new system picks on its own first values
    assert choice(system(), 1e6) == first  # whatever the workspace's systems picked before
    assert ws.count("reduction") == 2

    def referenced() -> ReducedKKTSystem:  # picks on the values of A_E scaled by 1e6
        n, me, mi = problem.n, problem.n_eq, problem.n_ineq
        ref = lambda _: scaled(1e6).data  # noqa: E731
        return ReducedKKTSystem(n, me, mi, lambda _: plan, reference_of=ref, workspace=ws)

    assert choice(referenced(), 1.0) == first  # the reference's pick, kept in the workspace
    assert choice(referenced(), 0.0) == again  # it breaks down: picked on the system's values
    assert ws.count("reduction") == 2
