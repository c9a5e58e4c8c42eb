"""Meshes in replays (no browser): a mesh robot's visual meshes in maximal and generalized replays,
per-formulation tints and own materials, self-contained pages, scaled meshes, mesh obstacles,
primitive robots, and the camera's framing."""

from __future__ import annotations

import base64
import re
import struct
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import pytest
from test_viz import page_commands  # tests/ is on sys.path (pytest's rootdir import mode)

from mbplan.errors import InputError, RobotModelError
from mbplan.multibody import body_poses, maximal_model
from mbplan.ocp import OCP, Scene
from mbplan.results import PlanResult
from mbplan.robots import load_robot
from mbplan.viz import bounding_box, camera_offset, static_html
from mbplan.viz.camera import direction
from mbplan.viz.shapes import capsule_mesh, shape_of, vertex_normals
from mbplan.viz.styles import GENERALIZED_TINTS, MAXIMAL_TINTS

PANDA = load_robot("panda", lock=["panda_finger_joint1", "panda_finger_joint2"])


def results_for(ocp: OCP, knots: int = 4) -> list[PlanResult]:
    """A maximal and a generalized result moving every joint a little from ``ocp.q0``."""
    q = ocp.q0 + np.linspace(0.0, 0.3, knots)[:, None]
    mm = maximal_model(ocp.robot.model)
    poses = [body_poses(mm, qk) for qk in q]
    common = dict(
        status="Test", success=True, message="", iterations=1, solve_time_s=0.1,
        total_time_s=0.1, time_per_iter_s=0.1, q=q, v=np.zeros_like(q),
        tau=np.zeros((knots - 1, q.shape[1])), dt=ocp.dt, ocp=ocp,
    )  # fmt: skip
    maximal = PlanResult(
        method="ripm",
        R=np.array([R for R, _ in poses]),
        p=np.array([p for _, p in poses]),
        body_names=mm.body_names,
        **common,
    )
    return [maximal, PlanResult(method="ipopt", **common)]


def objects(path: Path) -> dict[str, dict]:
    """The ``set_object`` commands of a page by node path (``/meshcat/`` stripped)."""
    return {
        c["path"].removeprefix("/meshcat/"): c["object"]
        for c in page_commands(path)
        if c["type"] == "set_object"
    }


_TYPES = {"Int8Array": np.int8, "Uint16Array": np.uint16, "Uint32Array": np.uint32}


def decoded(attribute: dict) -> np.ndarray:
    """A three.js buffer attribute as floats ``(n, itemSize)`` (normalized ones scaled)."""
    dtype = np.dtype(_TYPES[attribute["type"]])
    a = np.frombuffer(attribute["array"].data, dtype).reshape(-1, attribute.get("itemSize", 1))
    if attribute.get("normalized"):
        return np.maximum(a / np.iinfo(dtype).max, -1.0)
    return a.astype(float)


def mesh_of(drawn: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices (in the geometry object's frame), triangles and unit normals of a drawn mesh."""
    (geometry,) = drawn["geometries"]
    assert geometry["type"] == "BufferGeometry"
    assert drawn["object"]["frustumCulled"] is False  # quantized: bounds the viewer gets wrong
    M = np.array(drawn["object"]["matrix"]).reshape(4, 4).T  # column-major
    attributes = geometry["data"]["attributes"]
    vertices = decoded(attributes["position"]) @ M[:3, :3].T + M[:3, 3]
    normals = decoded(attributes["normal"]) @ np.linalg.inv(M[:3, :3])  # inverse transpose
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    faces = decoded(geometry["data"]["index"]).astype(int).reshape(-1, 3)
    return vertices, faces, normals


def color_of(obj: dict) -> tuple[float, float, float]:
    (material,) = obj["materials"]
    c = material["color"]
    return ((c >> 16) & 255) / 255, ((c >> 8) & 255) / 255, (c & 255) / 255


def assert_self_contained(path: Path) -> None:
    text = path.read_text()
    assert not re.search(r"<script[^>]*\ssrc=|<link|<img|@import|file://", text)
    assert set(re.findall(r"https?://[^\s\"'<>)]+", text)) <= {"http://www.w3.org/1999/xhtml"}
    for command in page_commands(path):  # nor does any embedded mesh or texture refer out
        blob = repr(command)
        assert "file://" not in blob and "package://" not in blob


def test_mesh_robot_in_maximal_and_generalized_replays_is_drawn_tinted(tmp_path: Path) -> None:
    scene = Scene().add_box("box", (0.1, 0.1, 0.1), (0.5, 0.3, 0.05))
    ocp = OCP(PANDA, scene, N=3, dt=0.1)
    page = static_html(results_for(ocp), tmp_path / "panda.html")
    assert_self_contained(page)
    drawn = objects(page)
    visual = PANDA.visual_model
    for i, tint in ((0, MAXIMAL_TINTS[0]), (1, GENERALIZED_TINTS[0])):
        for obj in visual.geometryObjects:
            assert obj.meshPath.endswith(".dae")
            drawn_obj = drawn[f"mbplan/robot{i}/visuals/{obj.name}"]
            vertices, faces, normals = mesh_of(drawn_obj)
            np.testing.assert_allclose(vertices, obj.geometry.vertices(), atol=1e-5)
            assert len(faces) == obj.geometry.num_tris and faces.max() < len(vertices)
            np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-6)
            np.testing.assert_allclose(color_of(drawn_obj), tint, atol=1 / 255)
    assert "mbplan/obstacles0/visuals/box" in drawn


def test_materials_keep_collada_files_and_urdf_colours(tmp_path: Path) -> None:
    ocp = OCP(PANDA, N=3, dt=0.1)
    page = static_html(results_for(ocp)[1:], tmp_path / "own.html", colors="materials")
    assert_self_contained(page)
    obj = PANDA.visual_model.geometryObjects[0]
    embedded = objects(page)[f"mbplan/robot0/visuals/{obj.name}"]["object"]
    assert embedded["type"] == "_meshfile_object" and embedded["format"] == "dae"
    assert embedded["data"] == Path(obj.meshPath).read_text()
    # an STL arm whose URDF gives colours: drawn as triangles in those colours
    xarm = OCP("xarm7", N=3, dt=0.1)
    page = static_html(results_for(xarm)[:1], tmp_path / "xarm.html", colors="materials")
    drawn = objects(page)
    for obj in xarm.robot.visual_model.geometryObjects:
        np.testing.assert_allclose(
            color_of(drawn[f"mbplan/robot0/visuals/{obj.name}"]), obj.meshColor[:3], atol=1 / 255
        )
    with pytest.raises(InputError, match="colors"):
        static_html(results_for(xarm), tmp_path / "bad.html", colors="rainbow")
    assert not (tmp_path / "bad.html").exists()


def test_primitive_robot_stays_primitives(tmp_path: Path) -> None:
    ocp = OCP("iiwa", N=3, dt=0.1)
    drawn = objects(static_html(results_for(ocp), tmp_path / "iiwa.html"))
    robot = {k: v for k, v in drawn.items() if k.startswith("mbplan/robot")}
    assert len(robot) == 2 * ocp.robot.visual_model.ngeoms
    for obj in ocp.robot.visual_model.geometryObjects:
        (geometry,) = drawn[f"mbplan/robot1/visuals/{obj.name}"]["geometries"]
        if isinstance(obj.geometry, coal.Cylinder):
            assert geometry["type"] == "CylinderGeometry"
            assert geometry["height"] == pytest.approx(2 * obj.geometry.halfLength)
            assert geometry["radiusTop"] == pytest.approx(obj.geometry.radius)
        else:
            assert isinstance(obj.geometry, coal.Sphere)
            assert geometry["type"] == "SphereGeometry"
            assert geometry["radius"] == pytest.approx(obj.geometry.radius)


def _tetrahedron_stl(path: Path, edge: float) -> None:
    corners = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) * edge
    faces = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]  # outward
    with path.open("wb") as f:
        f.write(b"\0" * 80 + struct.pack("<I", len(faces)))
        for face in faces:
            f.write(struct.pack("<12fH", 0, 0, 0, *corners[list(face)].ravel(), 0))


def test_scaled_meshes_and_mesh_obstacles(tmp_path: Path) -> None:
    _tetrahedron_stl(tmp_path / "tet.stl", 0.1)
    (tmp_path / "r.urdf").write_text(
        '<robot name="r"><link name="base"/><link name="l1"><inertial><mass value="1"/>'
        '<inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>'
        '<visual><geometry><mesh filename="tet.stl" scale="2 3 4"/></geometry></visual></link>'
        '<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>'
        '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>'
    )
    robot = load_robot(tmp_path / "r.urdf", package_dirs=[tmp_path])
    shape = shape_of(robot.visual_model.geometryObjects[0])
    np.testing.assert_allclose(shape.hi, [0.2, 0.3, 0.4], rtol=1e-6)  # scaled once
    scene = Scene().add_mesh("rock", tmp_path / "tet.stl", (2, 2, 2), (0.4, 0.0, 0.1))
    ocp = OCP(robot, scene, N=2, dt=0.1)
    drawn = objects(static_html(results_for(ocp, 3), tmp_path / "rock.html"))
    tet = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) * 0.1
    for node, scale in (("robot0/visuals/l1_0", [2, 3, 4]), ("obstacles0/visuals/rock", 2)):
        vertices, faces, normals = mesh_of(drawn[f"mbplan/{node}"])
        assert faces.shape == (4, 3)
        np.testing.assert_allclose(
            np.sort(vertices, axis=0), np.sort(tet * scale, axis=0), atol=1e-6
        )
        centre = vertices.mean(axis=0)
        assert np.all(np.sum(normals * (vertices - centre), axis=1) > 0)  # outward


def test_vertex_normals_and_capsule_mesh() -> None:
    corners = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    normals = vertex_normals(corners, np.array([(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]))
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, rtol=1e-6)
    centroid = corners.mean(axis=0)
    assert np.all(np.sum(normals * (corners - centroid), axis=1) > 0)  # outward
    vertices, faces = capsule_mesh(0.1, 0.3)
    np.testing.assert_allclose(vertices.min(axis=0), [-0.1, -0.1, -0.4], atol=1e-3)
    np.testing.assert_allclose(vertices.max(axis=0), [0.1, 0.1, 0.4], atol=1e-3)
    assert faces.max() < len(vertices)
    n = vertex_normals(vertices, faces)
    radial = vertices - np.clip(vertices * [0, 0, 1], -0.3, 0.3)
    assert np.all(np.sum(n * radial, axis=1) > 0)  # outward everywhere
    obj = pin.GeometryObject("cap", 0, pin.SE3.Identity(), coal.Capsule(0.1, 0.6))
    np.testing.assert_allclose(shape_of(obj).hi, [0.1, 0.1, 0.4])
    hull = coal.ConvexBase.convexHull(list(corners * 0.1), False, "")  # no polygons: its hull
    shape = shape_of(pin.GeometryObject("hull", 0, pin.SE3.Identity(), hull))
    assert shape.geometry.faces.shape == (4, 3)
    np.testing.assert_allclose(shape.hi, [0.1, 0.1, 0.1])
    with pytest.raises(RobotModelError, match="cannot draw"):
        shape_of(pin.GeometryObject("plane", 0, pin.SE3.Identity(), coal.Plane()))


@pytest.mark.parametrize("elevation, azimuth", [(25.0, 10.0), (50.0, -120.0), (90.0, 0.0)])
def test_camera_frames_every_point_tightly(elevation: float, azimuth: float) -> None:
    rng = np.random.default_rng(1)
    points = rng.normal(size=(200, 3)) * [0.5, 1.5, 0.3] + [0.2, -0.1, 0.4]
    lo, hi = bounding_box(points)
    points = points - 0.5 * (lo + hi)  # what the scene does: its centre at the origin
    view = direction(elevation, azimuth)
    for fov, aspect in ((40.0, 16 / 9), (60.0, 1.0)):
        eye = camera_offset(points, view, fov, aspect)
        np.testing.assert_allclose(eye / np.linalg.norm(eye), view, atol=1e-12)
        forward = -view
        right = np.cross(forward, [0.0, 0.0, 1.0])
        right = right / np.linalg.norm(right) if np.linalg.norm(right) > 1e-9 else [1.0, 0, 0]
        up = np.cross(right, forward)
        rel = points - eye
        depth = rel @ forward
        assert np.all(depth > 0)
        tan_half = np.tan(np.radians(fov) / 2)
        reach = np.maximum(
            np.abs(rel @ up) / (depth * tan_half), np.abs(rel @ right) / (depth * tan_half * aspect)
        )
        assert reach.max() <= 1.0  # every point in view
        assert reach.max() > 0.85  # and the robot fills it (margin 1.1)
    with pytest.raises(InputError, match="no finite points"):
        bounding_box(np.full((2, 3), np.nan))


def test_page_embeds_collada_textures_as_data_uris(tmp_path: Path) -> None:
    png = base64.b64decode(
        "iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mP8z8BQDwAEhQGAhKmMIQAAAABJRU5ErkJggg=="
    )
    (tmp_path / "skin.png").write_bytes(png)
    (tmp_path / "m.dae").write_text(
        '<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">'
        '<library_images><image id="i"><init_from>skin.png</init_from></image></library_images>'
        "</COLLADA>"
    )
    from mbplan.viz.shapes import ColladaFile

    lowered = ColladaFile(tmp_path / "m.dae", np.ones(3)).lower()["object"]
    assert lowered["resources"] == {
        "skin.png": "data:image/png;base64," + base64.b64encode(png).decode()
    }
