"""The joint-eliminated KKT (mbplan.benchmarks.reduced_kkt) against the full LDLᵀ: same step,
same inertia (also of an indefinite matrix), and the cases it refuses."""

import numpy as np
import pytest

from mbplan.benchmarks.reduced_kkt import ReducedKKT
from mbplan.errors import InputError
from mbplan.formulations.maximal_layout import maximal_layout
from mbplan.solvers.kkt.system import KKTSystem
from mbplan.tasks.speed import chain_task, maximal_ripm_problem


@pytest.fixture(scope="module")
def chain_kkt():
    problem, x0 = maximal_ripm_problem(chain_task(4, N=6), "linear")
    rng = np.random.default_rng(1)
    z = rng.uniform(0.5, 2.0, problem.n_ineq)
    ev = problem.evaluate(x0, 1.0, rng.normal(size=problem.n_eq), z)
    kkt = KKTSystem(problem.n, problem.n_eq, problem.n_ineq)
    kkt.set_matrices(ev.hessian_lower, ev.eq_jacobian, ev.ineq_jacobian)
    return problem, ev, kkt, -rng.uniform(0.5, 2.0, problem.n_ineq) / z


@pytest.mark.parametrize("forces", [False, True])
@pytest.mark.parametrize("delta_w", [0.0, 1e-4, -3.0])
def test_reduced_step_and_inertia_equal_the_full_factorization(chain_kkt, delta_w, forces):
    problem, ev, kkt, sigma = chain_kkt
    diag = np.concatenate([np.full(problem.n, delta_w), np.zeros(problem.n_eq), sigma])
    inertia = kkt.factorize(diag, 1e-9)
    red = ReducedKKT(maximal_layout(problem, ev.eq_jacobian), kkt.matrix(), forces=forces)
    assert red.reduced.shape[0] < kkt.dim / (4 if forces else 2)
    assert red.factorize() == inertia
    if delta_w < 0:  # wrong inertia (the correction would reject it): both see the same
        assert inertia.positive < problem.n
        return
    b = np.random.default_rng(2).normal(size=kkt.dim)
    x_full, x_red = kkt.solve(b)[0], red.solve(b)
    assert np.abs(x_red - x_full).max() <= 1e-8 * np.abs(x_full).max()
    assert np.abs(kkt.matvec(x_red) - b).max() <= 1e-9 * np.abs(b).max()
    assert red.elimination_flops > 0 and red.flops["reduced LDLT (AMD)"] > 0


def test_reduction_refuses_a_regularized_jacobian_block(chain_kkt):
    problem, ev, kkt, sigma = chain_kkt
    diag = np.concatenate([np.zeros(problem.n), np.full(problem.n_eq, -1e-8), sigma])
    kkt.factorize(diag, 1e-9)
    with pytest.raises(InputError, match="δ_c = 0"):
        ReducedKKT(maximal_layout(problem, ev.eq_jacobian), kkt.matrix())
