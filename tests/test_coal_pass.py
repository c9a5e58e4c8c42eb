"""The compiled coal pass gives coal's Python answers bit for bit, and the pair-by-pair path
takes over wherever it cannot."""

from __future__ import annotations

import dataclasses

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


def _both_paths(monkeypatch, pairs, pair, R, t, cap):
    """signed_distances through the compiled pass and pair by pair from Python."""
    compiled = C.signed_distances(pairs, pair, R, t, cap)
    with monkeypatch.context() as m:
        m.setattr(coal_pass, "library", lambda: None)
        python = C.signed_distances(pairs, pair, R, t, cap)
    return compiled, python


@pytest.mark.skipif(coal_pass.library() is None, reason="no C++ compiler or coal headers")
@pytest.mark.parametrize(
    ("robot", "geometry"), [("ur5", "convex"), ("ur5", "mesh"), ("iiwa", "convex")]
)
@pytest.mark.parametrize("cap", [np.inf, 0.1])
def test_compiled_distances_equal_the_python_loop_bit_for_bit(monkeypatch, robot, geometry, cap):
    """Hull/box, hull/curved (cross-checked), BVH mesh and primitive pairs, separated and
    penetrating, uncapped and capped (pruned by the lower bound): the same distances, normals
    and witness points to the last bit."""
    pairs = C.collision_pairs(load(robot).collision_model, OBSTACLES, geometry)
    pair, R, t = _sites(pairs, 120 if geometry == "mesh" else 400)
    caps = np.full(len(pair), cap)
    compiled, python = _both_paths(monkeypatch, pairs, pair, R, t, caps)
    assert (python.distance < 0).any() and (python.distance > 0).any()
    assert (python.distance == cap).any() == np.isfinite(cap)
    for field in ("distance", "normal", "robot_point"):
        np.testing.assert_array_equal(getattr(compiled, field), getattr(python, field))


@pytest.mark.skipif(coal_pass.library() is None, reason="no C++ compiler or coal headers")
def test_the_pass_sends_only_pairs_within_their_cap_and_a_wrong_shape_type_falls_back():
    """Pairs whose lower bound exceeds the cap are not sent to coal; a node type that does not
    match the shape at the address gives no answer (the caller then asks coal pair by pair)."""
    pairs = C.collision_pairs(load("iiwa").collision_model, OBSTACLES)
    pair, R, t = _sites(pairs, 300)
    shapes, tolerances = C._pass_shapes(pairs), C._tolerances()
    cap = np.full(len(pair), 0.05)
    found = coal_pass.site_distances(shapes, pair, R, t, cap, tolerances)
    bound = C.lower_bounds(pairs, pair, R, t)
    assert found is not None and found[3] == np.sum(bound <= cap) < len(pair)
    wrong = shapes.robot[1].copy()
    wrong[pair[0]] = int(coal.NODE_TYPE.GEOM_OCTREE)
    bad = dataclasses.replace(shapes, robot=(shapes.robot[0], wrong))
    assert coal_pass.site_distances(bad, pair, R, t, np.full(len(pair), np.inf), tolerances) is None


def test_without_the_library_distances_come_pair_by_pair_and_agree(monkeypatch) -> None:
    pairs = C.collision_pairs(load("ur5").collision_model, OBSTACLES)
    pair, R, t = _sites(pairs, 60, seed=3)
    compiled, python = _both_paths(monkeypatch, pairs, pair, R, t, np.full(len(pair), 0.3))
    for field in ("distance", "normal", "robot_point"):
        np.testing.assert_array_equal(getattr(compiled, field), getattr(python, field))


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
