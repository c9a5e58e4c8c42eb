"""Replays and plots without a browser: geometry placements, static pages, the live server's
bindings, bad input, matplotlib figures."""

from __future__ import annotations

import base64
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import umsgpack

from mbplan.errors import InputError
from mbplan.multibody import body_poses, maximal_model
from mbplan.ocp import OCP, Scene
from mbplan.planning.initial_guess import initial_path
from mbplan.results import PlanResult, save_npz
from mbplan.robots import load_robot
from mbplan.tasks.paper import iiwa_obstacle
from mbplan.viz import (
    MeshcatServer,
    draw_results,
    drone_replay,
    generalized_geometry_placements,
    infer_robot,
    maximal_geometry_placements,
    plot_convergence,
    plot_sparsity,
    plot_trajectories,
    read_result,
    replay_main,
    static_html,
)

TASK = iiwa_obstacle(N=6)
DESC = load_robot("iiwa")
MM = maximal_model(DESC.model)


def make_results(task: OCP = TASK) -> tuple[PlanResult, PlanResult]:
    """A maximal and a generalized result along the joint-space interpolation of ``task``."""
    q = initial_path(task, "linear")
    poses = [body_poses(MM, qk) for qk in q]
    common = dict(
        status="Test",
        success=True,
        message="",
        iterations=2,
        solve_time_s=0.1,
        total_time_s=0.2,
        time_per_iter_s=0.05,
        q=q,
        v=np.zeros_like(q),
        tau=np.zeros((len(q) - 1, q.shape[1])),
        dt=task.dt,
        kkt_history=np.array([[1.0, 2.0], [1e-3, 1e-2], [1e-8, 1e-7]]),
    )
    maximal = PlanResult(
        method="ripm",
        R=np.array([R for R, _ in poses]),
        p=np.array([p for _, p in poses]),
        body_names=MM.body_names,
        **common,
    )
    return maximal, PlanResult(method="ipopt", **common)


def page_commands(path: Path) -> list[dict]:
    """The MeshCat commands inlined in a static page, decoded."""
    text = path.read_text()
    listing = re.search(r"for \(const command of \[(.*?)\]\)", text, re.S)
    assert listing is not None
    blobs = re.findall(r'"([A-Za-z0-9+/=]+)"', listing.group(1))
    return [umsgpack.unpackb(base64.b64decode(b)) for b in blobs]


def test_maximal_placements_equal_forward_kinematics_and_show_violations() -> None:
    visual = DESC.visual_model
    rng = np.random.default_rng(0)
    low, high = DESC.model.lowerPositionLimit, DESC.model.upperPositionLimit
    q = rng.uniform(low, high, size=(5, DESC.model.nq))
    R, p = (np.array(a) for a in zip(*(body_poses(MM, qk) for qk in q), strict=True))
    maximal = maximal_geometry_placements(MM, visual, R, p)
    generalized = generalized_geometry_placements(DESC.model, visual, q)
    assert maximal.shape == generalized.shape == (5, visual.ngeoms, 4, 4)
    np.testing.assert_allclose(maximal, generalized, atol=1e-12)
    # a body moved off its joint moves its own geometry only: the viewer shows the violation
    p_bad = p.copy()
    p_bad[:, 3] += [0.0, 0.0, 0.05]
    moved = maximal_geometry_placements(MM, visual, R, p_bad)[..., :3, 3] - maximal[..., :3, 3]
    on_body = np.array([obj.parentJoint == MM.pin_joint[3] for obj in visual.geometryObjects])
    np.testing.assert_allclose(
        moved[:, on_body], np.broadcast_to([0, 0, 0.05], moved[:, on_body].shape)
    )
    np.testing.assert_array_equal(moved[:, ~on_body], 0.0)
    with pytest.raises(InputError, match="expected R"):
        maximal_geometry_placements(MM, visual, R[:, :3], p)


def test_static_page_is_self_contained_and_animated(tmp_path: Path) -> None:
    maximal, generalized = make_results()
    path = static_html([maximal, generalized], tmp_path / "replay.html", TASK)
    assert path == tmp_path / "replay.html" and [f.name for f in tmp_path.iterdir()] == [
        "replay.html"
    ]
    text = path.read_text()
    assert "ripm (maximal)" in text and "ipopt (generalized)" in text
    # nothing to fetch: the viewer script is inline and the only URL is the XHTML namespace
    assert not re.search(r"<script[^>]*\ssrc=|<link|<img|@import", text)
    assert set(re.findall(r"https?://[^\s\"'<>)]+", text)) <= {"http://www.w3.org/1999/xhtml"}
    commands = page_commands(path)
    (animation,) = [c for c in commands if c["type"] == "set_animation"]
    assert animation["options"]["play"] is True
    clips = {a["path"]: a["clip"] for a in animation["animations"]}
    knots = TASK.N + 1
    for i in range(2):
        for obj in DESC.visual_model.geometryObjects:
            clip = clips[f"/meshcat/mbplan/robot{i}/visuals/{obj.name}"]
            assert clip["fps"] == pytest.approx(1 / TASK.dt)
            times = {t["name"]: [k["time"] for k in t["keys"]] for t in clip["tracks"]}
            assert times == {".position": list(range(knots)), ".quaternion": list(range(knots))}
    objects = {c["path"] for c in commands if c["type"] == "set_object"}
    assert {
        "/meshcat/mbplan/goal0/visuals/iiwa_link_7_0",
        "/meshcat/mbplan/obstacles1/visuals/cylinder",
    } <= objects


def test_frame_shows_that_knot_with_the_animation_paused(tmp_path: Path) -> None:
    maximal, _ = make_results()
    path = static_html([maximal], tmp_path / "frame.html", frame=3)
    commands = page_commands(path)
    (animation,) = [c for c in commands if c["type"] == "set_animation"]
    assert animation["options"]["play"] is False
    node = "/meshcat/mbplan/robot0/visuals/iiwa_link_4_0"
    (last,) = [c for c in commands if c["type"] == "set_transform" and c["path"] == node][-1:]
    expected = maximal_geometry_placements(MM, DESC.visual_model, maximal.R[3], maximal.p[3])
    placed = np.array(last["matrix"]).reshape(4, 4).T  # column-major
    np.testing.assert_allclose(placed, expected[DESC.visual_model.getGeometryId("iiwa_link_4_0")])
    with pytest.raises(InputError, match="frame"):
        static_html([maximal], tmp_path / "bad.html", frame=TASK.N + 1)


def test_drone_page(tmp_path: Path) -> None:
    t = np.linspace(0.0, 1.0, 11)
    R = np.array([[[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]] for a in t])
    p = np.stack([t - 1.0, 0.5 * t, 0.2 * t], axis=1)
    path = drone_replay(R, p, [(-0.5, 0.5, 0.1)], tmp_path / "drone.html", open_browser=False)
    commands = page_commands(Path(path))
    (animation,) = [c for c in commands if c["type"] == "set_animation"]
    assert all(len(a["clip"]["tracks"][0]["keys"]) == 11 for a in animation["animations"])
    assert any(c["path"] == "/meshcat/mbplan/obstacles/visuals/obstacle0" for c in commands)
    with pytest.raises(InputError, match="expected R"):
        drone_replay(R, p[:-1], html=tmp_path / "x.html", open_browser=False)


def test_replay_main_writes_a_page_from_npz_files(tmp_path: Path, capsys) -> None:
    paths = [save_npz(r, tmp_path / f"{r.method}.npz") for r in make_results()]
    assert replay_main(paths, tmp_path / "out.html", no_browser=True) == 0
    assert "wrote" in capsys.readouterr().out
    assert "ripm (maximal)" in (tmp_path / "out.html").read_text()


def test_replay_draws_the_scene_the_plan_was_made_with(tmp_path: Path) -> None:
    """A result carrying its OCP is replayed with that OCP's robot and scene (here a custom box
    and sphere, and the UR5): no robot argument, nothing guessed."""
    scene = Scene().add_box("crate_4711", (0.2, 0.2, 0.2), (0.6, 0.0, 0.1))
    scene.add_sphere("ball_0815", 0.1, (0.0, 0.5, 0.8))
    ocp = OCP("ur5", scene, N=4, dt=0.1)
    q = np.repeat(ocp.q0[None], 5, axis=0)
    result = PlanResult(
        method="ipopt",
        status="Test",
        success=True,
        message="",
        iterations=1,
        solve_time_s=0.1,
        total_time_s=0.1,
        time_per_iter_s=0.1,
        q=q,
        v=np.zeros_like(q),
        tau=np.zeros((4, 6)),
        dt=0.1,
        ocp=ocp,
    )
    path = save_npz(result, tmp_path / "ur5.npz")
    assert replay_main([path], tmp_path / "page.html", no_browser=True) == 0
    objects = {
        c["path"] for c in page_commands(tmp_path / "page.html") if c["type"] == "set_object"
    }
    assert {
        "/meshcat/mbplan/obstacles0/visuals/crate_4711",
        "/meshcat/mbplan/obstacles0/visuals/ball_0815",
    } <= objects
    assert not any("cylinder" in o for o in objects)
    assert any("robot0/visuals/wrist_3_link" in o for o in objects)  # the UR5, not the iiwa


def test_bad_input_raises_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such result file"):
        read_result(tmp_path / "missing.npz")
    np.savez(tmp_path / "partial.npz", q=np.zeros((3, 7)), v=np.zeros((3, 7)))
    with pytest.raises(InputError, match="lacks the fields"):
        read_result(tmp_path / "partial.npz")
    (tmp_path / "text.npz").write_text("not a zip file")
    with pytest.raises(InputError, match="not a PlanResult"):
        read_result(tmp_path / "text.npz")
    with pytest.raises(InputError, match="no such result file"):
        replay_main([tmp_path / "missing.npz"], None, no_browser=True)
    maximal, _ = make_results()
    with pytest.raises(InputError, match=r"\.html"):
        static_html([maximal], tmp_path / "page.txt")
    with pytest.raises(InputError, match="fit robot 'ur5'"):
        static_html([maximal], tmp_path / "page.html", robot="ur5")


def _fake(robot: str, maximal: bool = True) -> PlanResult:
    """A two-knot result shaped for ``robot``."""
    mm = maximal_model(robot)
    q = np.zeros((2, mm.nq))
    arrays = {"R": np.broadcast_to(np.eye(3), (2, mm.nb, 3, 3)), "p": np.zeros((2, mm.nb, 3))}
    return PlanResult(
        "ripm" if maximal else "ipopt", "Test", True, "", 1, 0.0, 0.0, 0.0, q, q, q[:1], 0.1,
        **(arrays | {"body_names": mm.body_names} if maximal else {}),
    )  # fmt: skip


def test_infer_robot() -> None:
    assert infer_robot(make_results()) == "iiwa"
    assert infer_robot([_fake("panda")]) == "panda"
    with pytest.raises(InputError, match="all match"):  # the UR arms share their link names
        infer_robot([_fake("ur5")])
    with pytest.raises(InputError, match="no available robot"):
        infer_robot([_fake("ur5", maximal=False)])


def _listening(port: int) -> list[str]:
    """Local addresses of the listening TCP sockets on ``port`` (hex, from /proc/net)."""
    found = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            local, state = line.split()[1], line.split()[3]
            if state == "0A" and int(local.rsplit(":", 1)[1], 16) == port:
                found.append(local.rsplit(":", 1)[0])
    return found


@pytest.mark.skipif(not Path("/proc/net/tcp").exists(), reason="needs Linux /proc/net/tcp")
def test_live_server_listens_on_loopback_only() -> None:
    maximal, generalized = make_results()
    with MeshcatServer() as server:
        draw_results(server.viewer, [maximal, generalized], TASK)
        web_port = int(re.search(r":(\d+)/", server.url).group(1))
        zmq_port = int(server.viewer.window.zmq_url.rsplit(":", 1)[1])
        assert server.url.startswith("http://127.0.0.1:")
        for port in (web_port, zmq_port):
            assert _listening(port) == ["0100007F"]  # 127.0.0.1, IPv4 only
        pid = server.pid
    assert not Path(f"/proc/{pid}").exists()


@pytest.mark.skipif(not Path("/proc/net/tcp").exists(), reason="needs Linux /proc/net/tcp")
def test_replay_main_serves_on_loopback_until_interrupted(tmp_path: Path) -> None:
    paths = [str(save_npz(r, tmp_path / f"{r.method}.npz")) for r in make_results()]
    code = f"import sys; from mbplan.viz import replay_main; sys.exit(replay_main({paths}, None, True))"
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        url = re.search(r"http://127\.0\.0\.1:(\d+)/static/", line)
        assert url is not None, line
        assert _listening(int(url.group(1))) == ["0100007F"]
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=20) == 0
    finally:
        proc.kill()
        proc.wait()
    assert _listening(int(url.group(1))) == []


def test_plots(tmp_path: Path) -> None:
    maximal, generalized = make_results()
    png = plot_convergence([maximal, generalized], tmp_path / "conv.png")
    assert png.read_bytes().startswith(b"\x89PNG")
    svg = plot_trajectories([maximal, generalized], tmp_path / "traj.svg")
    assert "<svg" in svg.read_text()
    kkt = sp.random(60, 60, density=0.05, random_state=0, format="csc")
    path = plot_sparsity({"KKT matrix": kkt + kkt.T, "Hessian": sp.eye(30)}, tmp_path / "sp.png")
    assert path.stat().st_size > 1000
    assert sorted(f.name for f in tmp_path.iterdir()) == ["conv.png", "sp.png", "traj.svg"]
    with pytest.raises(InputError, match="must end in"):
        plot_convergence([maximal], tmp_path / "conv.jpg")
    with pytest.raises(InputError, match="not sparse"):
        plot_sparsity({"dense": np.eye(3)}, tmp_path / "sp.png")
    with pytest.raises(InputError, match="no results"):
        plot_convergence([], tmp_path / "conv.png")
