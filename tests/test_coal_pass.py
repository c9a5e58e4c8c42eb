"""The compiled coal pass gives coal's Python answers bit for bit, and the pair-by-pair path
takes over wherever it cannot."""

from __future__ import annotations

import coal
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mbplan.multibody import coal_pass
from mbplan.multibody import collision as C
from mbplan.robots import load

OBSTACLES = [
    (coal.Box(0.3, 0.2, 0.4), np.eye(4)),
    (coal.Sphere(0.1), np.eye(4)),
    (coal.Capsule(0.05, 0.3), np.eye(4)),
    (coal.Cylinder(0.1, 0.2), np.eye(4)),
]


def _sites(pairs: C.CollisionPairs, S: int = 400, seed: int = 0):
    """Random placements within reach of the obstacles (a third or so penetrating: EPA)."""
    rng = np.random.default_rng(seed)
    pair = rng.integers(0, pairs.size, S)
    R = Rotation.random(S, random_state=seed).as_matrix()
    return pair, R, rng.uniform(-0.5, 0.5, (S, 3))


@pytest.mark.skipif(coal_pass.library() is None, reason="no C++ compiler or coal headers")
@pytest.mark.parametrize(
    ("robot", "geometry"), [("ur5", "convex"), ("ur5", "mesh"), ("iiwa", "convex")]
)
def test_compiled_distances_equal_the_python_loop_bit_for_bit(robot, geometry) -> None:
    """Hull/box, hull/curved (cross-checked), BVH mesh and primitive pairs, separated and
    penetrating: the same distances, normals and witness points to the last bit."""
    pairs = C.collision_pairs(load(robot).collision_model, OBSTACLES, geometry)
    pair, R, t = _sites(pairs, 120 if geometry == "mesh" else 400)
    compiled = C._compiled_distances(pairs, pair, R, t)
    python = C._python_distances(pairs, pair, R, t)
    assert compiled is not None
    assert (python[0] < 0).any() and (python[0] > 0).any()
    for a, b in zip(compiled, python, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.skipif(coal_pass.library() is None, reason="no C++ compiler or coal headers")
def test_a_site_whose_shape_is_not_what_python_says_falls_back() -> None:
    """A node type that does not match the shape at the address: no answer from the pass
    (the caller then asks coal pair by pair)."""
    pairs = C.collision_pairs(load("iiwa").collision_model, OBSTACLES)
    pair, R, t = _sites(pairs, 8)
    robot, obstacle = (coal_pass.addresses(s) for s in (pairs.robot_shapes, pairs.obstacle_shapes))
    args = [
        (robot[0][pair], robot[1][pair]),
        (obstacle[0][pair], obstacle[1][pair]),
        pairs.checked[pair],
        (R, t),
        (pairs.obstacle_rotation[pair], pairs.obstacle_translation[pair]),
        np.array([1e-10, 1e-13, 1e-11, 1e-8, 1e-8, 1e100]),
    ]
    assert coal_pass.site_distances(*args) is not None
    wrong = robot[1][pair].copy()
    wrong[3] = int(coal.NODE_TYPE.GEOM_OCTREE)
    args[0] = (robot[0][pair], wrong)
    assert coal_pass.site_distances(*args) is None


def test_without_the_library_distances_come_pair_by_pair_and_agree(monkeypatch) -> None:
    pairs = C.collision_pairs(load("ur5").collision_model, OBSTACLES)
    pair, R, t = _sites(pairs, 60, seed=3)
    cap = np.full(len(pair), 0.3)
    expected = C.signed_distances(pairs, pair, R, t, cap)
    monkeypatch.setattr(coal_pass, "library", lambda: None)
    python = C.signed_distances(pairs, pair, R, t, cap)
    for field in ("distance", "normal", "robot_point"):
        np.testing.assert_array_equal(getattr(expected, field), getattr(python, field))


def test_a_missing_compiler_or_the_switch_leaves_the_python_loop(monkeypatch, capsys) -> None:
    """``$MBPLAN_COAL_PASS=off`` and a missing ``$CXX`` give no library (the latter says why);
    the process's library is restored afterwards."""
    try:
        coal_pass.library.cache_clear()
        monkeypatch.setenv(coal_pass.DISABLE, "off")
        assert coal_pass.library() is None
        coal_pass.library.cache_clear()
        monkeypatch.delenv(coal_pass.DISABLE)
        monkeypatch.setenv("CXX", "no-such-compiler-mbplan")
        assert coal_pass.library() is None
        assert "pair by pair" in capsys.readouterr().err
    finally:
        coal_pass.library.cache_clear()
