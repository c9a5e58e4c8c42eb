"""The per-iteration fast paths of the RIPM give what the general code gives, bit for bit."""

import numpy as np
import pytest
import scipy.sparse as sp

from mbplan.errors import InputError
from mbplan.lie import SO3, R
from mbplan.lie.group import check_orthogonal
from mbplan.solvers.iterate import transpose_times
from mbplan.transcription.sparse import SparsePattern
from mbplan.transcription.variables import Block, TrajectoryVariables


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


def test_sparse_pattern_drops_entries_of_fixed_columns():
    pattern = SparsePattern(np.array([0, 1, 1, 0, 1]), np.array([1, -1, 0, 1, -1]), (2, 3))
    a = pattern.assemble(np.array([1.0, 7.0, 3.0, 4.0, 9.0]))
    assert pattern.nnz == 2
    assert np.array_equal(a.toarray(), [[0, 5, 0], [3, 0, 0]])
    assert a.data.shape == (2,) and a.has_canonical_format
    with pytest.raises(InputError, match="5 values expected"):
        pattern.assemble(np.ones(4))


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
