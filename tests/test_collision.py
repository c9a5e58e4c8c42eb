"""Coal signed-distance constraints: derivatives in maximal coordinates and in joint space."""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation

from mbplan.engine import check_derivatives
from mbplan.errors import InfeasibleRequestError, InputError
from mbplan.lie import SO3
from mbplan.multibody import body_poses, maximal_model
from mbplan.multibody.collision import (
    chain_kinematics,
    collision_pairs,
    joint_placements,
    joint_space_contacts,
    placed_contacts,
    point_hessians,
    point_jacobians,
    signed_distances,
)
from mbplan.planning.solve import check_start
from mbplan.robots import load
from mbplan.transcription.distance import distance_constraint_function, pair_bodies

DESC = load("iiwa")
MM = maximal_model(DESC)
MODEL = DESC.model


def _pose(xyz, rotvec) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    pose[:3, 3] = xyz
    return pose


# tilted shapes near the arm: no parallel faces or axes (degenerate contacts) with the links
OBSTACLES = [
    (coal.Sphere(0.1), _pose((0.35, 0.25, 0.6), (0.0, 0.0, 0.0))),
    (coal.Capsule(0.05, 0.3), _pose((0.3, -0.3, 0.8), (0.4, 0.3, 0.1))),
    (coal.Box(0.2, 0.15, 0.3), _pose((-0.35, 0.2, 0.5), (0.2, -0.5, 0.3))),
    (coal.Cylinder(0.08, 0.4), _pose((0.0, 0.45, 1.0), (0.7, 0.2, -0.3))),
]
PAIRS = collision_pairs(DESC.collision_model, OBSTACLES)
Q = np.array([0.3, 0.5, -0.4, -1.2, 0.6, 0.8, -0.2])


def _contacts():
    kin = chain_kinematics(MODEL, MODEL.createData(), Q[None])
    contacts, J = joint_space_contacts(PAIRS, kin)
    return kin, contacts, J


def test_pairs_cover_moving_geometry_and_coal_agrees_with_pinocchio_placements() -> None:
    moving = [o for o in DESC.collision_model.geometryObjects if o.parentJoint > 0]
    assert PAIRS.size == len(moving) * len(OBSTACLES)
    _, contacts, _ = _contacts()
    gdata = DESC.collision_model.createData()
    pin.updateGeometryPlacements(MODEL, MODEL.createData(), DESC.collision_model, gdata, Q)
    for i in range(PAIRS.size):
        M = gdata.oMg[int(PAIRS.geometry[i])]
        shape, pose = OBSTACLES[PAIRS.obstacle[i]]
        d = coal.distance(
            PAIRS.robot_shapes[i],
            coal.Transform3s(M.rotation, M.translation),
            shape,
            coal.Transform3s(pose[:3, :3], pose[:3, 3]),
            coal.DistanceRequest(),
            coal.DistanceResult(),
        )
        assert contacts.distance[0, i] == pytest.approx(d, abs=1e-6)
    assert np.allclose(np.linalg.norm(contacts.normal, axis=-1), 1.0)
    # every pair is separated (EPA's penetration depth is only accurate to 1e-8): all are
    # checked by finite differences below
    assert contacts.distance.min() > 0.05


def test_joint_space_gradient_matches_finite_differences() -> None:
    """``∂d/∂q = -nᵀ J₁`` against central differences of coal's distance (step 1e-5 rad)."""
    _, contacts, J = _contacts()
    grad = -np.einsum("kpa,kpja->kpj", contacts.normal, J)[0]
    h = 1e-5
    for j in range(MODEL.nv):
        e = h * np.eye(MODEL.nv)[j]
        fd = (pair_distances_at(Q + e) - pair_distances_at(Q - e)) / (2 * h)
        np.testing.assert_allclose(grad[:, j], fd, atol=1e-6)


def pair_distances_at(q: np.ndarray) -> np.ndarray:
    return joint_space_contacts(PAIRS, chain_kinematics(MODEL, MODEL.createData(), q[None]))[
        0
    ].distance[0]


def test_point_hessians_match_differences_of_point_jacobians() -> None:
    rng = np.random.default_rng(0)
    local = rng.uniform(-0.1, 0.1, (PAIRS.size, 3))  # points fixed in the links

    def jacobians(q: np.ndarray) -> tuple[np.ndarray, np.ndarray, object]:
        kin = chain_kinematics(MODEL, MODEL.createData(), q[None])
        R, t = kin.rotation[0, PAIRS.joint], kin.translation[0, PAIRS.joint]
        points = t + np.einsum("pij,pj->pi", R, local)
        return point_jacobians(kin, PAIRS.joint, points[None])[0], points, kin

    J, _, kin = jacobians(Q)
    H = point_hessians(kin, PAIRS.joint, J[None])[0]
    h = 1e-6
    for j in range(MODEL.nv):
        e = h * np.eye(MODEL.nv)[j]
        fd = (jacobians(Q + e)[0] - jacobians(Q - e)[0]) / (2 * h)  # (P, nv, 3) d/dq_j
        np.testing.assert_allclose(H[:, j], fd, atol=1e-8)
        # and the Jacobian itself against differences of the points
        fd_points = (jacobians(Q + e)[1] - jacobians(Q - e)[1]) / (2 * h)
        np.testing.assert_allclose(J[:, j], fd_points, atol=1e-8)


def _maximal_sites():
    R, p = body_poses(MM, Q)
    bodies = pair_bodies(MM, PAIRS)
    f = distance_constraint_function(MM, PAIRS)
    return f, R[bodies], p[bodies]


def test_maximal_jacobian_matches_finite_differences_along_the_retraction() -> None:
    f, R, p = _maximal_sites()
    c = f.value({"R": R, "p": p}, {"pair": np.arange(PAIRS.size), "margin": 0.02})[:, 0]
    _, contacts, _ = _contacts()
    np.testing.assert_allclose(c, 0.02 - contacts.distance[0], atol=1e-9)
    for i in range(PAIRS.size):
        check = check_derivatives(
            f, {"R": R[i], "p": p[i]}, {"pair": i, "margin": 0.02}, step_jacobian=1e-5
        )
        assert check.jacobian_error < 2e-6, (PAIRS.names[i], check)


def test_maximal_hessian_is_the_fixed_witness_point_model() -> None:
    """The Hessian is that of ``margin - nᵀ(p₂ - p - δp - R exp(ω) a)`` with the witness point
    ``a`` (body frame) and the normal held fixed (documented in mbplan.multibody.collision):
    compare with four-point differences of that model along the exact retraction."""
    f, R, p = _maximal_sites()
    bodies = pair_bodies(MM, PAIRS)
    rng = np.random.default_rng(1)
    lam = rng.uniform(0.5, 2.0, (PAIRS.size, 1))
    params = {"pair": np.arange(PAIRS.size), "margin": 0.0}
    _, _, hnz = f.hessian({"R": R, "p": p}, params, lam)
    H = f.dense_hessian(hnz)
    Rb, pb = body_poses(MM, Q)
    geometry_R = Rb[bodies] @ PAIRS.placement[:, :3, :3]
    geometry_t = pb[bodies] + np.einsum(
        "pij,pj->pi", Rb[bodies], PAIRS.placement[:, :3, 3] - MM.com_in_joint[bodies]
    )
    contacts = signed_distances(PAIRS, np.arange(PAIRS.size), geometry_R, geometry_t)
    a = np.einsum("pji,pj->pi", R, contacts.robot_point - p)
    h = 1e-4
    eye = np.eye(6)
    for i in range(PAIRS.size):

        def model(xi: np.ndarray, i: int = i) -> float:
            point = p[i] + xi[3:] + SO3.retract(R[i], xi[:3]) @ a[i]
            return float(lam[i, 0] * contacts.normal[i] @ point)

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
                    for c in range(6)
                ]
                for r in range(6)
            ]
        )
        np.testing.assert_allclose(H[i], fd, atol=1e-6)


def test_distance_task_validation_names_the_geometry() -> None:
    import mbplan as mb
    from mbplan.residuals import Distance
    from mbplan.tasks.paper import IIWA_START, IIWA_TARGET, iiwa_obstacle

    with pytest.raises(InputError, match="constraint"):
        iiwa_obstacle(constraint="mesh")
    q0 = np.array(IIWA_START)
    kin = chain_kinematics(MODEL, MODEL.createData(), q0[None])
    wrist = kin.translation[0, 6]
    scene = mb.Scene().add_sphere("ball", 0.05, wrist + np.array([0.0, 0.0, 0.12]))
    blocked = mb.OCP("iiwa", scene, q0=q0).add_constraint("clearance", Distance(0.03))
    with pytest.raises(
        InfeasibleRequestError,
        match=r"q0 violates.*geometry 'iiwa_link_\d_0' and scene object 'ball'",
    ):
        mb.plan(blocked, "ripm")
    task = iiwa_obstacle(constraint="distance")
    check_start(task)
    from mbplan.formulations.joint_space import evaluate

    r = task["clearance"].residual
    both = np.vstack([task.q0, IIWA_TARGET])
    assert evaluate(task.robot, task.scene, r, both, both, None).max() <= 0.0  # d >= margin


def test_verification_measures_coal_distances_of_distance_tasks() -> None:
    """For a "distance" task the verifier's clearance is the coal distance to every obstacle
    (the cylinder as a finite solid), here negative along the straight path of case 0."""
    from mbplan.planning.initial_guess import initial_path
    from mbplan.tasks.paper import iiwa_obstacle_cases
    from mbplan.verification.multibody import _clearance

    ocp = iiwa_obstacle_cases(1, 0, constraint="distance")[0]
    path = initial_path(ocp, "linear")
    clearance = _clearance(ocp, ocp["clearance"], path)
    assert clearance < 0.0
    # (penetration depths from EPA agree to its tolerance)
    from mbplan.formulations.joint_space import evaluate

    r = ocp["clearance"].residual
    d = r.margin - evaluate(ocp.robot, ocp.scene, r, path, path, None)
    assert clearance == pytest.approx(d.min(), abs=1e-12)


def test_a_wrong_tight_gjk_distance_is_caught_by_the_default_request():
    """At this iiwa configuration (knot 31 of a distance-task plan) coal's GJK at the tight
    tolerance stops at 0.021 m from the obstacle where the distance is 0.085 m (1e-9 rad away
    too); the default request cross-checks it and its result is used."""
    import mbplan.multibody.collision as collision
    from mbplan.residuals.distance import distance_values
    from mbplan.tasks.paper import iiwa_obstacle

    q = np.array([1.003111497864807, 0.3706807128646723, 0.001580589416948418,
                  -1.2336641508135646, 0.004269912837888549, 1.001412071015906,
                  0.0049814865702810145])  # fmt: skip
    ocp = iiwa_obstacle(q, N=4, constraint="distance")
    residual = ocp["clearance"].residual
    nearby = q + 1e-9 * np.random.default_rng(1).standard_normal(7)
    value = distance_values(ocp.robot, ocp.scene, residual, np.stack([q, nearby]))[0]
    np.testing.assert_allclose(value[0], value[1], atol=1e-6)
    assert value[0, 3] == pytest.approx(0.03 - 0.0854, abs=1e-3)
    saved = collision._CROSS_CHECK
    try:  # without the cross-check the wrong distance shows (so this test can fail)
        collision._CROSS_CHECK = np.inf
        wrong = distance_values(ocp.robot, ocp.scene, residual, q[None])[0]
        assert wrong[0, 3] > value[0, 3] + 0.05
    finally:
        collision._CROSS_CHECK = saved


def test_lower_bounds_and_the_cap_leave_distances_below_it_exact() -> None:
    """Bounding-volume lower bounds never exceed coal's distance; with a cap, distances above it
    are the cap with a zero normal (zero derivatives), and those below it are unchanged."""
    from mbplan.multibody.collision import lower_bounds

    rng = np.random.default_rng(2)
    q = Q + 0.5 * rng.standard_normal((6, MODEL.nv))
    kin = chain_kinematics(MODEL, MODEL.createData(), q)
    exact, _ = joint_space_contacts(PAIRS, kin)
    capped, _ = joint_space_contacts(PAIRS, kin, 0.2)
    R = kin.rotation[:, PAIRS.joint] @ PAIRS.placement[:, :3, :3]
    t = kin.translation[:, PAIRS.joint] + np.einsum(
        "kpij,pj->kpi", kin.rotation[:, PAIRS.joint], PAIRS.placement[:, :3, 3]
    )
    pair = np.tile(np.arange(PAIRS.size), len(q))
    bound = lower_bounds(PAIRS, pair, R.reshape(-1, 3, 3), t.reshape(-1, 3))
    assert np.all(bound <= exact.distance.ravel() + 1e-12)
    assert np.any(bound > 0.2)  # some pairs are pruned
    np.testing.assert_array_equal(capped.distance, np.minimum(exact.distance, 0.2))
    far = exact.distance > 0.2
    assert far.any() and (~far).any()
    assert np.all(capped.normal[far] == 0.0)
    np.testing.assert_array_equal(capped.normal[~far], exact.normal[~far])


def test_meshes_become_cached_convex_hulls_with_one_request_per_pair(tmp_path, monkeypatch):
    """A UR5 mesh's hull contains it (its distances are lower bounds), is written to the hull
    cache and read back identical; polytope pairs skip the cross-check, curved ones keep it."""
    from mbplan.multibody import convex

    monkeypatch.setenv("MBPLAN_CACHE_DIR", str(tmp_path / "jit"))
    ur5 = load("ur5")
    box = (coal.Box(0.3, 0.02, 0.5), _pose((0.5, 0.1, 0.3), (0.1, 0.2, 0.3)))
    hulls = collision_pairs(ur5.collision_model, [box, OBSTACLES[0]])
    meshes = collision_pairs(ur5.collision_model, [box, OBSTACLES[0]], geometry="mesh")
    assert len(list((tmp_path / "hulls").iterdir())) == 6  # the moving links' 6 meshes
    again = collision_pairs(ur5.collision_model, [box, OBSTACLES[0]])
    assert all(s.getNodeType() == coal.NODE_TYPE.GEOM_CONVEX for s in hulls.robot_shapes[:-2])
    np.testing.assert_array_equal(hulls.checked, hulls.obstacle == 1)  # the sphere is curved
    assert meshes.checked[:-2].all()  # but ee_link's box with the box: two polytopes
    model = ur5.model
    q = np.array([-1.0, -1.2, 1.7, -2.1, -1.6, -2.6])
    kin = chain_kinematics(model, model.createData(), q[None])
    d_hull, d_again, d_mesh = (
        joint_space_contacts(p, kin)[0].distance for p in (hulls, again, meshes)
    )
    np.testing.assert_array_equal(d_hull, d_again)
    assert np.all(d_hull <= d_mesh + 1e-9)
    assert convex.hull_cache_dir() == tmp_path / "hulls"


def test_values_by_forward_kinematics_alone_equal_those_with_jacobians() -> None:
    """The distances' values (warm start, the generalized NLP's line search) take the joint
    placements without Jacobians: the same placements and distances, bit for bit."""
    q = Q + 0.5 * np.random.default_rng(3).standard_normal((5, MODEL.nv))
    kin = chain_kinematics(MODEL, MODEL.createData(), q)
    rotation, translation = joint_placements(MODEL, MODEL.createData(), q)
    np.testing.assert_array_equal(rotation, kin.rotation)
    np.testing.assert_array_equal(translation, kin.translation)
    values = placed_contacts(PAIRS, rotation, translation, 0.3)
    with_jacobians, _ = joint_space_contacts(PAIRS, kin, 0.3)
    np.testing.assert_array_equal(values.distance, with_jacobians.distance)
    np.testing.assert_array_equal(values.robot_point, with_jacobians.robot_point)


def test_polytope_pairs_start_gjk_from_the_bounding_boxes_at_the_same_answer() -> None:
    """Hull/box pairs start GJK from the boxes' centres: coal's answer from its default start
    direction, to round-off, on random UR5 configurations (both paths use the one request)."""
    from mbplan.multibody import collision

    ur5 = load("ur5")
    box = (coal.Box(0.3, 0.02, 0.5), _pose((0.5, 0.1, 0.3), (0.1, 0.2, 0.3)))
    pairs = collision_pairs(ur5.collision_model, [box])
    assert not pairs.checked.any()
    request = collision._POLYTOPE
    assert request.gjk_initial_guess == coal.GJKInitialGuess.BoundingVolumeGuess
    default = collision._request(collision.POLYTOPE_TOLERANCE)
    assert default.gjk_initial_guess == coal.GJKInitialGuess.DefaultGuess
    rng = np.random.default_rng(4)
    q = rng.uniform(-np.pi, np.pi, (40, ur5.model.nv))
    contacts = placed_contacts(pairs, *joint_placements(ur5.model, ur5.model.createData(), q))
    gaps = []
    for k in range(len(q)):
        gdata = ur5.collision_model.createData()
        pin.updateGeometryPlacements(
            ur5.model, ur5.model.createData(), ur5.collision_model, gdata, q[k]
        )
        for i in range(pairs.size):
            M = gdata.oMg[int(pairs.geometry[i])]
            placement = coal.Transform3s(M.rotation, M.translation)
            d = collision._distance(pairs, i, placement, default)[0]
            gaps.append(abs(d - contacts.distance[k, i]))
    assert max(gaps) <= 1e-12


@pytest.mark.parametrize(
    ("vertices", "problem"),
    [
        (np.zeros((0, 3)), "empty"),
        (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]]), "flat"),
    ],
)
def test_empty_or_flat_meshes_are_named_before_a_solve(vertices, problem) -> None:
    import mbplan as mb
    from mbplan.errors import RobotModelError
    from mbplan.residuals import Distance

    mesh = coal.BVHModelOBBRSS()
    mesh.beginModel(2, len(vertices))
    if len(vertices):
        mesh.addVertices(vertices)
        mesh.addTriangles(np.array([[0, 1, 2], [1, 3, 2]]))
    mesh.endModel()
    gm = DESC.collision_model.copy()
    gm.geometryObjects[3].geometry = mesh
    gm.geometryObjects[3].meshPath = "/meshes/link3.stl"
    robot = mb.load_robot(MODEL, collision_model=gm)
    ocp = mb.OCP(robot, mb.Scene().add_box("crate", (0.2, 0.2, 0.2), (0.5, 0.0, 0.5)), q0=Q)
    with pytest.raises(RobotModelError, match=rf"iiwa_link_3_0.*link3\.stl.*{problem}"):
        ocp.add_constraint("clearance", Distance(0.02))
    with pytest.raises(InputError, match="geometry must be one of"):
        mb.OCP("iiwa", ocp.scene, q0=Q).add_constraint("c", Distance(0.02, geometry="hull"))
