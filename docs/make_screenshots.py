"""Regenerate the replay screenshots in docs/ (headless Chromium, Debian's ``chromium``).

    python docs/make_screenshots.py            # every robot below
    python docs/make_screenshots.py panda ur5  # some of them

Each robot is planned by the RIPM (maximal coordinates) and IPOPT (generalized coordinates) on
the same task and shown side by side, tinted by formulation, at the middle knot, from a static
page (``mbplan.viz.static_html``): docs/iiwa_plan.png and docs/side_by_side.png (case 1 of
``mbplan.tasks.paper.iiwa_obstacle_cases(2, 0)``, primitives only), docs/meshes_<robot>.png for the arms
with visual meshes and docs/meshes_panda_materials.png (the IPOPT plan in the meshes' own
materials), and docs/drone.png (the RIPM's docking through clutter of
``examples/drone_cluttered.py``, halfway), docs/floating_solo12.png (``examples/tasks/solo12_tuck.toml``:
a floating base in free flight), docs/trot_solo12.png (the README's solo12 trot, mid-step) and
docs/walk_talos_legs.png (the nominal talos_legs walk of ``mbplan bench locomotion``, on two
flat soles, mid-way through its first step).
The pages are kept in out/screenshots/.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests"), str(ROOT / "examples")]

import panda_between_boxes  # noqa: E402
from test_browser import screenshot  # noqa: E402

import mbplan as mb  # noqa: E402
from mbplan.locomotion import quadruped_gait  # noqa: E402
from mbplan.taskfile import load_task  # noqa: E402
from mbplan.tasks.drone import cluttered_task  # noqa: E402
from mbplan.tasks.locomotion import gait_case  # noqa: E402
from mbplan.tasks.paper import drone_docking, iiwa_obstacle_cases, tracking_ocp  # noqa: E402
from mbplan.viz import drone_replay, static_html  # noqa: E402

OUT = ROOT / "out" / "screenshots"
DOCS = ROOT / "docs"


def point_to_point(robot: str) -> Callable[[], mb.OCP]:
    """A joint-space point-to-point task within the joint limits (examples/other_arm.py)."""

    def ocp() -> mb.OCP:
        model = mb.load_robot(robot).model
        lo = np.maximum(model.lowerPositionLimit, -np.pi)
        hi = np.minimum(model.upperPositionLimit, np.pi)
        mid = 0.5 * (lo + hi)
        return tracking_ocp(robot, mid + 0.15 * (hi - lo), mid - 0.15 * (hi - lo), N=30, dt=0.1)

    return ocp


TASKS: dict[str, Callable[[], mb.OCP]] = {
    "iiwa": lambda: iiwa_obstacle_cases(2, 0)[1],
    "panda": panda_between_boxes.task,
    "ur5": point_to_point("ur5"),
    "ur10": point_to_point("ur10"),
    "z1": point_to_point("z1"),
    "xarm7": point_to_point("xarm7"),
    "so100": point_to_point("so100"),
    "solo12": lambda: load_task(str(ROOT / "examples" / "tasks" / "solo12_tuck.toml")).ocp,
    "trot": lambda: quadruped_gait(
        "solo12",
        gait="trot",
        step_length=0.1,
        step_height=0.05,
        dt=0.02,
        step_knots=8,
        support_knots=2,
    ),
    "talos_walk": lambda: gait_case("talos_legs-walk", 0),
}


def shoot(
    results: list[mb.PlanResult], task: mb.OCP, name: str, frame: int | None = None, **kwargs: str
) -> None:
    frame = task.N // 2 if frame is None else frame
    page = static_html(results, OUT / f"{name}.html", task, frame=frame, **kwargs)
    png = screenshot(page.resolve().as_uri(), DOCS / f"{name}.png", budget_ms=10000, timeout_s=180)
    print(f"wrote {DOCS / name}.png ({png.shape[1]}x{png.shape[0]})", flush=True)


def drone() -> None:
    task = cluttered_task(with_input_limits=True)
    plan = mb.plan(drone_docking(task), "ripm", tol=1e-8, max_iter=200)
    page = drone_replay(
        plan.R[:, 0], plan.p[:, 0], task.obstacles, OUT / "drone.html", dt=task.dt, open_browser=False,
        frame=task.N // 2,
    )  # fmt: skip
    screenshot(Path(page).resolve().as_uri(), DOCS / "drone.png", budget_ms=10000, timeout_s=180)
    print(f"wrote {DOCS / 'drone.png'}", flush=True)


def main(robots: list[str]) -> None:
    for robot in robots:
        if robot == "drone":
            drone()
            continue
        task = TASKS[robot]()
        warm = "linear" if robot in ("iiwa", "solo12", "trot", "talos_walk") else "via"
        results = [mb.plan(task, method, warm_start=warm) for method in ("ripm", "ipopt")]
        for r in results:
            print(f"{robot} {r.method}: {r.status}, {r.iterations} iterations", flush=True)
        if robot == "iiwa":
            shoot(results[:1], task, "iiwa_plan")
            shoot(results, task, "side_by_side")
            continue
        if robot in ("solo12", "trot"):
            shoot(results, task, "floating_solo12" if robot == "solo12" else "trot_solo12")
            continue
        if robot == "talos_walk":  # mid-way through the first step
            shoot(results, task, "walk_talos_legs", frame=7)
            continue
        shoot(results, task, f"meshes_{robot}")
        if robot == "panda":
            shoot(results[1:], task, "meshes_panda_materials", colors="materials")


if __name__ == "__main__":
    unknown = sorted(set(sys.argv[1:]) - {*TASKS, "drone"})
    if unknown:
        sys.exit(f"unknown robots {unknown}; choose from {', '.join(TASKS)}, drone")
    main(sys.argv[1:] or [*TASKS, "drone"])
