"""The assembled trajectory NLP: Riemannian derivatives of the whole problem against finite
differences along the retraction, fixed sparsity, additive rows and input validation."""

import casadi as cs
import numpy as np
import pytest
from fd import check_problem_derivatives

from mbplan.engine import RiemannianFunction
from mbplan.engine.jit import jit_available
from mbplan.engine.site_table import CallsInOrder, SiteTable
from mbplan.errors import InputError
from mbplan.formulations.free_body import FreeBodyNLP
from mbplan.lie import SO3, R
from mbplan.planning.initial_guess import initial_path
from mbplan.tasks import paper
from mbplan.tasks.drone import cluttered_task
from mbplan.transcription import Block, Term, TrajectoryProblem, TrajectoryVariables
from mbplan.workspace import Workspace


def _drone_problem(with_input_limits: bool):
    """The free-body maximal NLP of the cluttered docking task and its geodesic start."""
    nlp = FreeBodyNLP(paper.drone_docking(cluttered_task(with_input_limits)), jit=False)
    return nlp.problem, nlp.initial_point(initial_path(nlp.ocp, "linear"))


def _input_cost():
    """``½ w ‖u - u_ref‖²`` of ``u ∈ R⁴``: a scalar residual."""
    return RiemannianFunction(
        "input_cost",
        [("u", R(4))],
        lambda u, u_ref, w: 0.5 * w * cs.sumsqr(u - u_ref),
        [("u_ref", 4), ("w", 1)],
    )


def test_free_body_problem_derivatives_match_finite_differences():
    prob, x = _drone_problem(with_input_limits=True)
    N = 40
    assert (prob.n, prob.n_eq) == (16 * N, 12 * N)
    check_problem_derivatives(prob, x, np.random.default_rng(0))


def test_additive_rows_sum_contributions():
    f = _input_cost()  # scalar residual of u ∈ R⁴
    variables = TrajectoryVariables([Block("u", f.variables[0].group, 3)])
    params = {"u_ref": np.zeros(4), "w": 2.0}
    terms = [
        Term("a", "eq", f, {"u": ("u", [0, 1])}, params, rows=np.array([[0], [0]])),
        Term("b", "eq", f, {"u": ("u", [2])}, params, rows=np.array([[1]])),
    ]
    prob = TrajectoryProblem(variables, terms)
    u = np.arange(12.0).reshape(3, 4)
    _, h, _ = prob.values({"u": u})
    np.testing.assert_allclose(h, [np.sum(u[0] ** 2) + np.sum(u[1] ** 2), np.sum(u[2] ** 2)])
    J = prob.evaluate({"u": u}).eq_jacobian.toarray()
    np.testing.assert_allclose(J[0], np.concatenate([2 * u[0], 2 * u[1], np.zeros(4)]))


def test_a_term_at_no_knots_contributes_nothing():
    """Terms bound to no knots (e.g. a constraint list that came out empty) build and
    evaluate: the problem equals the one without them."""
    f = _input_cost()
    variables = TrajectoryVariables([Block("u", f.variables[0].group, 3)])
    params = {"u_ref": np.ones(4), "w": 2.0}
    terms = [
        Term("a", "eq", f, {"u": ("u", [0, 2])}, params),
        Term("c", "cost", f, {"u": ("u", [1])}, params),
    ]
    empty = [
        Term("no_eq", "eq", f, {"u": ("u", [])}, params, rows=np.zeros((0, 1), np.int64)),
        Term("no_cost", "cost", f, {"u": ("u", [])}, params),
    ]
    u = {"u": np.arange(12.0).reshape(3, 4)}
    y = np.array([0.5, -2.0])
    base, with_empty = (TrajectoryProblem(variables, t) for t in (terms, terms + empty))
    for got, want in zip(with_empty.values(u), base.values(u), strict=True):
        np.testing.assert_array_equal(got, want)
    got, want = (p.evaluate(u, 1.0, y, np.zeros(0)) for p in (with_empty, base))
    np.testing.assert_array_equal(got.gradient, want.gradient)
    for name in ("eq_jacobian", "hessian_lower"):
        np.testing.assert_array_equal(getattr(got, name).toarray(), getattr(want, name).toarray())


def test_bad_points_and_bindings_are_named():
    prob, x = _drone_problem(with_input_limits=False)
    with pytest.raises(InputError, match="block 'p'"):
        prob.check_point({**x, "p": x["p"][:-1]})
    bad = dict(x)
    bad["v"] = x["v"].copy()
    bad["v"][3, 1] = np.nan
    with pytest.raises(InputError, match="NaN"):
        prob.check_point(bad)
    bad = dict(x)
    bad["R"] = x["R"].copy()
    bad["R"][2] *= 1.1
    with pytest.raises(InputError, match="orthogonal"):
        prob.check_point(bad)
    f = _input_cost()
    variables = TrajectoryVariables([Block("u", f.variables[0].group, 3)])
    with pytest.raises(InputError, match="outside block"):
        TrajectoryProblem(
            variables, [Term("t", "cost", f, {"u": ("u", [3])}, {"u_ref": np.zeros(4), "w": 1.0})]
        )
    with pytest.raises(InputError, match="bind"):
        Term("t", "cost", f, {"x": ("u", [0])})


def test_packed_point_feeds_each_term_as_its_own_evaluation_would():
    """The one-gather packing of a whole point (matrices column-major, blocks with several
    elements per knot) gives every term the inputs ``SiteFunction.value`` packs itself."""
    import casadi as cs

    from mbplan.engine import RiemannianFunction
    from mbplan.lie import SO3, R

    A = np.arange(9.0).reshape(3, 3) + np.eye(3)  # not symmetric: a transpose would show
    f = RiemannianFunction(
        "mixed",
        [("Ra", SO3), ("Rb", SO3), ("p", R(3))],
        lambda Ra, Rb, p, w: cs.vertcat(cs.vec(cs.mtimes([Ra, A, Rb.T])), w * p),
        [("w", 1)],
    )
    variables = TrajectoryVariables([Block("R", SO3, 4, fixed=(0,), count=2), Block("p", R(3), 4)])
    term = Term(
        "t",
        "eq",
        f,
        {"Ra": ("R", [2, 4, 6]), "Rb": ("R", [3, 5, 7]), "p": ("p", [1, 2, 3])},
        {"w": 2.0},
    )
    prob = TrajectoryProblem(variables, [term])
    rng = np.random.default_rng(1)
    x = {"R": SO3.exp(rng.standard_normal((4, 2, 3))), "p": rng.standard_normal((4, 3))}
    flat = {"R": x["R"].reshape(8, 3, 3), "p": x["p"]}
    direct = f.value(term.gather(flat), {"w": 2.0}).ravel()
    _, h, _ = prob.values(x)
    np.testing.assert_allclose(h, direct, atol=1e-14)
    k, Ra, Rb = 1, flat["R"][4], flat["R"][5]
    np.testing.assert_allclose(h[12 * k : 12 * k + 9], (Ra @ A @ Rb.T).ravel(order="F"))
    np.testing.assert_allclose(prob.evaluate(x).eq, direct, atol=1e-14)
    with pytest.raises(InputError, match="block 'p' contains NaN"):
        prob.values({**x, "p": np.full((4, 3), np.nan)})
    with pytest.raises(InputError, match="block 'R' must have shape"):
        prob.evaluate({"p": x["p"]})


def test_problems_of_one_structure_share_patterns_not_parameters_or_buffers():
    """Two problems of one workspace whose terms differ only in parameters share the index maps
    and sparsity patterns, yet each evaluates with its own parameters (as a fresh build would)
    and its own buffers; another binding gives another structure, no workspace a problem's
    own."""
    f = _input_cost()
    ws = Workspace()
    variables = TrajectoryVariables([Block("u", R(4), 3, fixed=(0,))])

    def problem(u_ref: float, sites=(1, 2)) -> TrajectoryProblem:
        term = Term(
            "c", "cost", f, {"u": ("u", list(sites))}, {"u_ref": np.full(4, u_ref), "w": 2.0}
        )
        return TrajectoryProblem(TrajectoryVariables(list(variables.blocks.values())), [term], ws)

    a, b = problem(0.0), problem(1.0)
    assert a._structure is b._structure and a._layouts["cost"][0].index is (
        b._layouts["cost"][0].index
    )
    own = TrajectoryProblem(variables, a.terms)
    assert own._structure is not a._structure
    u = {"u": np.arange(12.0).reshape(3, 4)}
    ev_a, ev_b = a.evaluate(u), b.evaluate(u)
    assert ev_a.objective == pytest.approx(np.sum(u["u"][1:] ** 2))
    assert ev_b.objective == pytest.approx(np.sum((u["u"][1:] - 1.0) ** 2))
    np.testing.assert_allclose(ev_a.gradient, 2 * u["u"][1:].ravel())
    assert a.evaluate(u).objective == ev_a.objective  # b's evaluation did not touch a's buffers
    other = problem(0.0, sites=(2, 1))
    assert other._layouts["cost"][0].index is not a._layouts["cost"][0].index
    np.testing.assert_allclose(other.evaluate(u).gradient, ev_a.gradient)
    with pytest.raises(ValueError, match="read-only"):  # shared: nobody may write into them
        a.term_rows("cost")["c"][0, 0] = 1
    # another function object of the same layout (e.g. one closing over another scene's
    # geometry), knots fixed by a list: the same structure
    f2 = _input_cost()
    listed = TrajectoryVariables([Block("u", R(4), 3, fixed=[0])])
    assert listed.blocks["u"] == variables.blocks["u"]
    term = Term("c", "cost", f2, {"u": ("u", [1, 2])}, {"u_ref": np.zeros(4), "w": 2.0})
    same = TrajectoryProblem(listed, [term], ws)
    assert same._layouts["cost"][0].index is a._layouts["cost"][0].index
    assert same.evaluate(u).objective == ev_a.objective


def test_a_term_s_parameters_are_replaced_in_place_of_a_rebuild():
    """``set_parameters`` changes what the next evaluation reads, per site, as a problem built
    with those parameters evaluates; the structure stays; an unknown term is named."""
    f = _input_cost()
    variables = TrajectoryVariables([Block("u", R(4), 3, fixed=(0,))])

    def problem(u_ref: np.ndarray) -> TrajectoryProblem:
        term = Term("c", "cost", f, {"u": ("u", [1, 2])}, {"u_ref": u_ref, "w": 2.0})
        return TrajectoryProblem(variables, [term])

    u = {"u": np.arange(12.0).reshape(3, 4)}
    a = problem(np.zeros(4))
    before = a.evaluate(u).objective
    structure = a._structure
    per_site = np.array([np.ones(4), np.full(4, 3.0)])
    a.set_parameters("c", {"u_ref": per_site})
    fresh = problem(per_site).evaluate(u)
    assert a.evaluate(u).objective == pytest.approx(fresh.objective) != pytest.approx(before)
    np.testing.assert_allclose(a.evaluate(u).gradient, fresh.gradient)
    assert a._structure is structure
    with pytest.raises(InputError, match="no term named 'd'"):
        a.set_parameters("d", {"w": 1.0})


@pytest.mark.skipif(not jit_available(), reason="no C compiler")
def test_compiled_term_pass_equals_the_term_by_term_calls(monkeypatch):
    """A problem of compiled terms runs their site loops in one compiled pass; its values,
    derivatives and Hessian equal, bit for bit, those of the term-by-term calls."""
    import mbplan.transcription.trajectory as problem_module

    A = np.arange(9.0).reshape(3, 3) + np.eye(3)
    step = RiemannianFunction(
        "pass_probe_step",
        [("Ra", SO3), ("Rb", SO3), ("p", R(3))],
        lambda Ra, Rb, p, w: cs.vertcat(cs.vec(cs.mtimes([Ra, A, Rb.T])), w * p * cs.sumsqr(p)),
        [("w", 1)],
        jit=True,
    )
    cost = RiemannianFunction(
        "pass_probe_cost",
        [("p", R(3))],
        lambda p: cs.sumsqr(p) ** 2,
        jit=True,
    )
    variables = TrajectoryVariables([Block("R", SO3, 4, fixed=(0,)), Block("p", R(3), 4)])

    bind = {"Ra": ("R", [0, 1, 2]), "Rb": ("R", [1, 2, 3]), "p": ("p", [1, 2, 3])}

    def build() -> TrajectoryProblem:
        terms = [
            Term("c", "cost", cost, {"p": ("p", [1, 2, 3])}),
            Term("s", "eq", step, bind, {"w": 2.0}),
            Term("g", "ineq", cost, {"p": ("p", [0, 3])}),
        ]
        return TrajectoryProblem(variables, terms)

    rng = np.random.default_rng(3)
    x = {"R": SO3.exp(rng.standard_normal((4, 3))), "p": rng.standard_normal((4, 3))}
    compiled = build()
    y, z = rng.standard_normal(compiled.n_eq), rng.standard_normal(compiled.n_ineq)

    def evaluations(prob: TrajectoryProblem) -> tuple:
        return prob.evaluate(x, 0.5, y, z), prob.evaluate(x, hessian=False), prob.values(x)

    results = [evaluations(compiled)]
    kinds = ("value", "jacobian", "hessian")
    assert all(isinstance(compiled._bound[k], SiteTable) for k in kinds)
    # bound anew: a second table over the same buffers recomputes the last Hessian
    again = compiled.bind_calls("hessian")
    assert isinstance(again, SiteTable) and again is not compiled._bound["hessian"]
    hessians = compiled._hessians.copy()
    compiled._hessians[:] = np.nan
    again()
    np.testing.assert_array_equal(compiled._hessians, hessians)
    with pytest.raises(InputError, match="call kind: expected one of"):
        compiled.bind_calls("gradient")
    monkeypatch.setattr(problem_module, "bound_calls", CallsInOrder)
    by_term = build()
    results.append(evaluations(by_term))
    assert not any(isinstance(c, SiteTable) for c in by_term._bound["hessian"].calls)
    (ev_a, plain_a, val_a), (ev_b, plain_b, val_b) = results
    for a, b in ((ev_a, ev_b), (plain_a, plain_b)):
        assert a.objective == b.objective
        for name in ("gradient", "eq", "ineq"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        for name in ("eq_jacobian", "ineq_jacobian"):
            np.testing.assert_array_equal(getattr(a, name).toarray(), getattr(b, name).toarray())
    np.testing.assert_array_equal(ev_a.hessian_lower.toarray(), ev_b.hessian_lower.toarray())
    assert plain_a.hessian_lower is None
    assert val_a[0] == val_b[0]
    for a, b in zip(val_a[1:], val_b[1:], strict=True):
        np.testing.assert_array_equal(a, b)


def test_evaluation_passes_equal_per_term_gathers_and_bincounts():
    """The one-pass gather of inputs and multipliers and the one-pass sums give, bit for bit,
    per-term ``take`` and NumPy ``bincount`` over the structure's maps: kinds interleaved in
    the term list, rows shared and reversed (summed), with and without inequalities, a
    read-only ``y``, with and without the Hessian."""
    step = RiemannianFunction(
        "order_probe_step",
        [("Ra", SO3), ("p", R(3))],
        lambda Ra, p, w: cs.vertcat(cs.vec(Ra) * w, p * cs.sumsqr(p)),
        [("w", 1)],
    )
    cost = RiemannianFunction("order_probe_cost", [("p", R(3))], lambda p: cs.sumsqr(p) ** 2)
    variables = TrajectoryVariables([Block("R", SO3, 4, fixed=(0,)), Block("p", R(3), 4)])
    shared = np.arange(24)[::-1].reshape(2, 12)  # into the first term's rows, reversed

    def terms(with_ineq: bool) -> list[Term]:
        listed = [
            Term("s1", "eq", step, {"Ra": ("R", [0, 1, 2]), "p": ("p", [1, 2, 3])}, {"w": 2.0}),
            Term("c1", "cost", cost, {"p": ("p", [1, 3])}),
            Term("s2", "eq", step, {"Ra": ("R", [3, 2]), "p": ("p", [0, 1])}, {"w": -1.0}, shared),
            Term("c2", "cost", cost, {"p": ("p", [0])}),
        ]
        if with_ineq:
            listed.insert(1, Term("g", "ineq", cost, {"p": ("p", [0, 3])}))
        return listed

    def bincount(slot: np.ndarray, values: np.ndarray, size: int) -> np.ndarray:
        return np.bincount(slot, weights=values, minlength=size)

    rng = np.random.default_rng(4)
    x = {"R": SO3.exp(rng.standard_normal((4, 3))), "p": rng.standard_normal((4, 3))}
    for with_ineq in (True, False):
        prob = TrajectoryProblem(variables, terms(with_ineq))
        s = prob._structure
        assert (prob.n_eq, prob.n_ineq) == (36, 2 if with_ineq else 0)
        y, z = rng.standard_normal(prob.n_eq), rng.standard_normal(prob.n_ineq)
        y.setflags(write=False)
        for ev in (prob.evaluate(x, 0.7, y, z), prob.evaluate(x, hessian=False)):
            packed = variables.packed(x)
            for lay in prob._all_layouts:
                np.testing.assert_array_equal(lay.z, packed.take(lay.index.z_index))
                kind = lay.term.kind
                if ev.hessian_lower is not None:
                    lam = {"cost": np.full(prob.n_eq + prob.n_ineq, 0.7), "eq": y, "ineq": z}
                    np.testing.assert_array_equal(lay.lam, lam[kind].take(lay.index.rows))
            grad = bincount(s.grad_cols, prob._jacobians["cost"], prob.n + 1)[: prob.n]
            np.testing.assert_array_equal(ev.gradient, grad)
            for kind, size in (("eq", prob.n_eq), ("ineq", prob.n_ineq)):
                residual = bincount(s.rows[kind], prob._residuals[kind], size)
                np.testing.assert_array_equal(getattr(ev, kind), residual)
                pattern = s.jac_patterns[kind]
                data = bincount(pattern.slot, prob._jacobians[kind], pattern.nnz + 1)
                np.testing.assert_array_equal(getattr(ev, kind + "_jacobian").data, data[:-1])
            if ev.hessian_lower is not None:
                pattern = s.hess_pattern
                data = bincount(pattern.slot, prob._hessians, pattern.nnz + 1)
                np.testing.assert_array_equal(ev.hessian_lower.data, data[:-1])
        f, eq, ineq = prob.values(x)
        np.testing.assert_array_equal(eq, bincount(s.rows["eq"], prob._residuals["eq"], 36))
        assert f == pytest.approx(ev.objective, rel=1e-15) and ineq.shape == (prob.n_ineq,)
    with pytest.raises(InputError, match="rows must be non-negative"):
        Term("bad", "eq", step, {"Ra": ("R", [1]), "p": ("p", [1])}, {"w": 1.0}, -np.ones((1, 12)))
