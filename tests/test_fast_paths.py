"""The per-iteration fast paths of the RIPM give what the general code gives, bit for bit."""

import numpy as np
import pytest
import scipy.sparse as sp

from mbplan.errors import InputError
from mbplan.lie import SO3, R
from mbplan.lie.group import check_orthogonal
from mbplan.solvers.ripm.iterate import transpose_times
from mbplan.transcription.sparse import SparsePattern, sparse_pattern
from mbplan.transcription.variables import Block, TrajectoryVariables
from mbplan.workspace import Workspace


@pytest.mark.parametrize("index", [np.int32, np.int64])
def test_transpose_times_is_scipys_product(index):
    rng = np.random.default_rng(0)
    a = sp.random(40, 60, density=0.1, format="csr", random_state=rng)
    a.indices, a.indptr = a.indices.astype(index), a.indptr.astype(index)
    x = rng.standard_normal(40)
    assert np.array_equal(transpose_times(a, x), a.T @ x)
    assert np.array_equal(transpose_times(a.tocsc(), x), a.T @ x)  # other formats: scipy's
    assert transpose_times(sp.csr_matrix((0, 5)), np.zeros(0)).shape == (5,)


def test_sparse_pattern_assembles_independent_matrices():
    pattern = SparsePattern(np.array([0, 1, 1, 0]), np.array([1, 0, 0, 1]), (2, 3))
    a = pattern.assemble(np.array([1.0, 2.0, 3.0, 4.0]))
    b = pattern.assemble(np.array([-1.0, 0.0, 0.0, 0.0]))
    assert np.array_equal(a.toarray(), [[0, 5, 0], [5, 0, 0]])
    assert np.array_equal(b.toarray(), [[0, -1, 0], [0, 0, 0]])
    assert a.has_canonical_format and a.shape == (2, 3)
    # the index arrays are shared by every matrix of the pattern (and, through a workspace, by
    # every problem of a task family): an in-place index operation must fail, not corrupt the others
    with pytest.raises(ValueError, match="read-only"):
        a.indices[0] = 2
    with pytest.raises(ValueError, match="read-only"):
        b.eliminate_zeros()
    assert np.array_equal(a.toarray(), [[0, 5, 0], [5, 0, 0]]) and a.T.shape == (3, 2)


def test_sparse_pattern_drops_entries_of_fixed_columns():
    pattern = SparsePattern(np.array([0, 1, 1, 0, 1]), np.array([1, -1, 0, 1, -1]), (2, 3))
    a = pattern.assemble(np.array([1.0, 7.0, 3.0, 4.0, 9.0]))
    assert pattern.nnz == 2
    assert np.array_equal(a.toarray(), [[0, 5, 0], [3, 0, 0]])
    assert a.data.shape == (2,) and a.has_canonical_format
    with pytest.raises(InputError, match="5 values expected"):
        pattern.assemble(np.ones(4))


def test_sparse_patterns_are_kept_in_a_workspace_by_their_index_arrays():
    """The same index arrays and shape: the workspace's pattern (its matrices stay
    independent); other entries, dtype or shape: another; no workspace: a new one."""
    ws = Workspace()
    rows, cols = np.array([0, 1, 1, 0]), np.array([1, 0, 0, 1])
    first = sparse_pattern(rows, cols, (2, 3), ws)
    assert sparse_pattern(rows.copy(), cols.copy(), (2, 3), ws) is first
    assert sparse_pattern(rows, cols, (2, 3)) is not first
    a, b = first.assemble(np.ones(4)), first.assemble(np.zeros(4))
    assert np.array_equal(a.toarray(), [[0, 2, 0], [2, 0, 0]]) and not b.toarray().any()
    for other in (
        sparse_pattern(rows, np.array([1, 0, 2, 1]), (2, 3), ws),
        sparse_pattern(rows.astype(np.int32), cols, (2, 3), ws),
        sparse_pattern(rows, cols, (2, 4), ws),
    ):
        assert other is not first
    assert sparse_pattern(rows, cols, (2, 4), ws).shape == (2, 4)


def test_sparse_pattern_key_sample_is_checked_against_every_entry():
    """The workspace key samples the index arrays; arrays equal on the sample but not
    elsewhere get their own pattern (and the kept one stays correct)."""
    ws = Workspace()
    rng = np.random.default_rng(0)
    rows, cols = rng.integers(0, 50, 5000), rng.integers(0, 50, 5000)
    first = sparse_pattern(rows, cols, (50, 50), ws)
    other_cols = cols.copy()
    other_cols[1] = (cols[1] + 1) % 50  # index 1 is not in the sample (every 4th entry)
    other = sparse_pattern(rows, other_cols, (50, 50), ws)
    assert other is not first
    values = rng.standard_normal(5000)
    for pattern, c in (
        (first, cols),
        (other, other_cols),
        (sparse_pattern(rows, cols, (50, 50), ws), cols),
    ):
        expected = np.zeros((50, 50))
        np.add.at(expected, (rows, c), values)
        np.testing.assert_allclose(pattern.assemble(values).toarray(), expected, atol=1e-12)
    assert not first.entries[1].flags.writeable


def test_so3_batched_retraction_equals_one_by_one():
    """One call on a batch mixing tiny (Taylor branch) and large angles gives each element's
    own result exactly (the line search retracts all knots of all SO(3) blocks at once)."""
    rng = np.random.default_rng(1)
    X = SO3.exp(rng.standard_normal((12, 3)))
    xi = rng.standard_normal((12, 3)) * np.array([1e-5, 1e-1, 2.0] * 4)[:, None]
    batch = SO3.retract(X, xi)
    for k in range(12):
        assert np.array_equal(batch[k], SO3.retract(X[k], xi[k]))
        assert np.array_equal(SO3.exp(xi[k : k + 1])[0], SO3.exp(xi[k]))


def test_rotation_check_rejects_batches():
    X = SO3.exp(np.random.default_rng(2).standard_normal((5, 3)))
    check_orthogonal(X, "SO(3)", "element")
    with pytest.raises(InputError, match="not orthogonal"):
        check_orthogonal(X * (1 + 1e-5), "SO(3)", "element")
    bad = X.copy()
    bad[3] = -bad[3]
    with pytest.raises(InputError, match="reflection"):
        check_orthogonal(bad, "SO(3)", "element")
    with pytest.raises(InputError, match="not orthogonal"):
        SO3.retract(np.eye(3) * 2, np.zeros(3))


@pytest.mark.parametrize("fixed", [(0,), (0, 2)])
def test_grouped_retraction_equals_per_block(fixed):
    """R and F (one SO(3) group) retract in one call, fixed knots stay; a fixed knot inside
    the horizon (a non-contiguous free set) takes the masked path."""
    rng = np.random.default_rng(3)
    blocks = [Block("R", SO3, 5, fixed=fixed), Block("p", R(3), 5), Block("F", SO3, 5, fixed)]
    variables = TrajectoryVariables(blocks)
    point = {
        "R": SO3.exp(rng.standard_normal((5, 3))),
        "p": rng.standard_normal((5, 3)),
        "F": SO3.exp(rng.standard_normal((5, 3))),
    }
    dx = rng.standard_normal(variables.n)
    out = variables.retract(point, dx)
    for name in ("R", "p", "F"):
        idx = variables.tangent_index(name)
        free = idx[:, 0] >= 0
        b = variables.blocks[name]
        expected = point[name].copy()
        expected[free] = b.group.retract(point[name][free], dx[idx[free]])
        assert np.array_equal(out[name], expected)
        assert np.array_equal(out[name][~free], point[name][~free])
    with pytest.raises(InputError, match="not orthogonal"):
        variables.retract({**point, "F": 2 * point["F"]}, dx)


def _bits(a: np.ndarray) -> np.ndarray:
    """The bit patterns (signed zeros told apart)."""
    return np.ascontiguousarray(a, dtype=np.float64).view(np.int64)


def test_so3_products_round_in_their_documented_order():
    """Every entry of a 3 x 3 product is ``fma(a₂, b₂, fma(a₁, b₁, fma(a₀, b₀, 0)))``: checked
    against exact rational arithmetic rounded at the same three places; and within a few ulps
    of NumPy's product."""
    from fractions import Fraction

    from mbplan.lie.so3_kernels import product_batch

    def fma(a: float, b: float, c: float) -> float:
        return float(Fraction(a) * Fraction(b) + Fraction(c))

    rng = np.random.default_rng(4)
    a, b = rng.standard_normal((50, 3, 3)), rng.standard_normal((50, 3, 3))
    a[:5] = np.where(rng.random((5, 3, 3)) < 0.5, -0.0, a[:5])  # signed zeros
    out = product_batch(a, b)
    for k, i, j in np.ndindex(10, 3, 3):
        want = fma(
            a[k, i, 2], b[k, 2, j], fma(a[k, i, 1], b[k, 1, j], fma(a[k, i, 0], b[k, 0, j], 0.0))
        )
        assert _bits(out[k, i, j]) == _bits(np.float64(want))
    np.testing.assert_allclose(out, a @ b, rtol=0, atol=1e-14)


def test_so3_exp_is_rodrigues_formula():
    from mbplan.lie.so3 import _coefficients, _hat_numeric

    rng = np.random.default_rng(5)
    xi = rng.standard_normal((40, 3)) * np.repeat([1e-5, 1e-2, 1.0, 3.0], 10)[:, None]
    a, b, _ = _coefficients(xi)
    K = _hat_numeric(xi)
    want = np.eye(3) + a[:, None, None] * K + b[:, None, None] * (K @ K)
    np.testing.assert_allclose(SO3.exp(xi), want, rtol=0, atol=1e-15)


def _trajectory(fixed=(0,), knots=6):
    rng = np.random.default_rng(6)
    blocks = [
        Block("R", SO3, knots, fixed=fixed, count=2),
        Block("p", R(3), knots, fixed=fixed, count=2),
        Block("u", R(2), knots - 1),
    ]
    variables = TrajectoryVariables(blocks)
    point = {
        "R": SO3.exp(rng.standard_normal((knots, 2, 3))),
        "p": rng.standard_normal((knots, 2, 3)),
        "u": rng.standard_normal((knots - 1, 2)),
    }
    point["R"][1, 0] = np.eye(3)  # exact zeros in X
    dx = rng.standard_normal(variables.n) * 0.3
    dx[variables.tangent_index("R")[2]] = [0.0, -0.0, 1e-9]  # zero and Taylor-branch steps
    return variables, point, dx


@pytest.mark.parametrize("fixed", [(0,), (0, 3)])
def test_packed_retraction_is_the_groups_retraction_bit_for_bit(fixed):
    """One compiled pass over the packed point gives the blocks' own retraction exactly, signed
    zeros included, from a plain point and from a packed one; the arrays are views of the
    packed vector, which evaluation then uses without a copy."""
    from mbplan.transcription.packed import PackedPoint

    variables, point, dx = _trajectory(fixed)
    assert variables.layout.retractable
    moved = variables.retract(point, dx)
    assert type(moved) is PackedPoint
    want = variables._retract_blocks(point, dx)
    again, want_again = variables.retract(moved, -dx), variables._retract_blocks(want, -dx)
    for name in variables.blocks:
        assert np.array_equal(_bits(moved[name]), _bits(want[name]))
        assert np.array_equal(_bits(again[name]), _bits(want_again[name]))
        assert np.shares_memory(moved[name], moved.packed)
    assert variables.packed(moved) is moved.packed
    assert np.array_equal(variables.packed(dict(moved)), moved.packed)


def test_packed_point_copies_are_plain_and_replaced_blocks_are_seen():
    import copy
    import pickle

    variables, point, dx = _trajectory()
    moved = variables.retract(point, dx)
    for clone in (copy.copy(moved), pickle.loads(pickle.dumps(moved))):
        assert type(clone) is dict and clone.keys() == moved.keys()
        assert all(np.array_equal(clone[k], moved[k]) for k in moved)
    replaced = variables.retract(point, dx)
    replaced["p"] = replaced["p"] + 1.0  # no longer a view: the packed vector is rebuilt
    assert not replaced.packed_by(variables.layout)
    assert np.array_equal(
        variables.packed(replaced)[: replaced.packed.size], variables.packed(dict(replaced))
    )
    moved["u"][0, 0] = np.nan  # written into the packed vector
    with pytest.raises(InputError, match="block 'u' contains NaN"):
        variables.packed(moved)


def test_packed_retraction_falls_back_to_the_groups_errors():
    variables, point, dx = _trajectory()
    with pytest.raises(InputError, match="not orthogonal"):
        variables.retract({**point, "R": 2 * point["R"]}, dx)
    bad = dx.copy()
    bad[variables.tangent_index("R")[3, 0]] = np.nan
    with pytest.raises(InputError, match="tangent vector: contains NaN"):
        variables.retract(point, bad)
    overflow = {**point, "p": np.full_like(point["p"], 1.7e308)}
    big = dx.copy()
    big[variables.tangent_index("p")] = 1e308
    with np.errstate(over="ignore"):
        out = variables.retract(overflow, big)  # as Rⁿ's retract: inf, no error
    assert type(out) is dict and np.isinf(out["p"][1:]).all()


def test_finite_vector_tells_nan_and_infinity_from_large_entries():
    from mbplan.finite import finite_vector

    v = np.linspace(-1.0, 1.0, 9)
    assert finite_vector(v) and finite_vector(np.zeros(0))
    assert finite_vector(np.array([1e200, -1e300, 2.0]))  # v·v overflows: entrywise test
    for bad in (np.nan, np.inf, -np.inf):
        w = v.copy()
        w[4] = bad
        assert not finite_vector(w)
        w[0] = 1e200
        assert not finite_vector(w)
    long = np.zeros(20_000)  # past the dot test's length: entrywise
    assert finite_vector(long)
    long[-1] = np.nan
    assert not finite_vector(long)
