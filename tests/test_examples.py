"""Every script in examples/ runs (in the size CI affords) and produces what it promises."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.slow  # each runs an example script end to end

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}


def run_example(name: str, *args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run an example with this checkout's ``mbplan`` first on the path."""
    return subprocess.run(
        [sys.executable, str(EXAMPLES / name), *args],
        capture_output=True,
        text=True,
        timeout=600,
        env=ENV,
        cwd=cwd,
    )


def readme_script(marker: str) -> str:
    """The Python block of README.md under the ``<!-- marker -->`` comment."""
    text = (ROOT / "README.md").read_text()
    block = text.split(f"<!-- {marker} -->", 1)[1].split("```python", 1)[1]
    return block.split("```", 1)[0]


def run_readme_script(marker: str, most_lines: int, cwd) -> subprocess.CompletedProcess:
    """Run README.md's block under ``marker`` (at most ``most_lines`` non-blank lines) in
    ``cwd``; it must exit 0."""
    script = readme_script(marker)
    assert len([line for line in script.strip().splitlines() if line.strip()]) <= most_lines
    (cwd / "script.py").write_text(script)
    proc = subprocess.run(
        [sys.executable, "script.py"], capture_output=True, text=True, timeout=600, env=ENV, cwd=cwd
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc


def test_readme_trot_script_plans_verifies_and_replays(tmp_path):
    """The README's trot: solo12 on Crocoddyl's trot schedule with hard contacts, planned by
    both methods, verified, both plans in one replay page."""
    proc = run_readme_script("trot-script", 15, tmp_path)
    assert proc.stdout.count("True True (21, 8, 3)") == 2, proc.stdout
    assert (tmp_path / "out" / "trot.html").stat().st_size > 10_000


def test_readme_panda_script_plans_verifies_and_saves(tmp_path):
    """The README's ≤ 12-line script: the panda's hand to a pose between two boxes in both
    formulations, verified, saved; the pose (a terminal constraint) is met within 1 mm and
    1e-3 rad by both."""
    proc = run_readme_script("panda-script", 12, tmp_path)
    assert proc.stdout.count("True True") == 2, proc.stdout
    import pinocchio as pin

    import mbplan as mb

    for method in ("ripm", "ipopt"):
        plan = mb.load_npz(tmp_path / "out" / f"panda_{method}.npz")
        assert plan.success and plan.ocp is not None and plan.ocp.scene.names == ["left", "right"]
        goal = plan.ocp["hand"].residual
        model = plan.ocp.robot.model
        data = model.createData()
        pin.framesForwardKinematics(model, data, plan.q[-1])
        M = data.oMf[model.getFrameId("panda_hand")]
        assert np.linalg.norm(M.translation - goal.translation) <= 1e-3
        assert np.linalg.norm(pin.log3(goal.rotation.T @ M.rotation)) <= 1e-3
        assert mb.verify(plan).passed


def test_drone_cluttered(tmp_path):
    out = tmp_path / "path.png"
    proc = run_example("drone_cluttered.py", "--out", str(out))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "CONVERGED" in proc.stdout
    assert out.stat().st_size > 10_000


def test_drone_docking_replay_page(tmp_path):
    proc = run_example("drone_docking.py", "--seed", "1", "--out", str(tmp_path))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "docking.html").stat().st_size > 10_000


def test_other_arm_both_formulations(tmp_path):
    proc = run_example("other_arm.py", "--robot", "ur5", "--horizon", "20", "--out", str(tmp_path))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "ur5_ripm.npz").exists() and (tmp_path / "ur5_ipopt.npz").exists()
    assert proc.stdout.count("verified:") == 2


def test_compare_formulations_reduced(tmp_path):
    """Reduced size: 60 iterations per solver (the full comparison is the iiwa benchmark)."""
    proc = run_example(
        "compare_formulations.py", "--seed", "1", "--max-iter", "60", "--out", str(tmp_path)
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    for name in ("ripm.npz", "ipopt.npz", "side_by_side.html", "convergence.png"):
        assert (tmp_path / name).stat().st_size > 0, name


def test_fourbar_example_plans_both_formulations_closed(tmp_path):
    """The four-bar script: both formulations solved, verified, at the rocker goal with the loop
    closed (its own exit status), the plans saved and the replay page written."""
    proc = run_example("fourbar_crank.py", "--out", str(tmp_path), "--horizon", "20")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    import mbplan as mb

    for method in ("ripm", "ipopt"):
        plan = mb.load_npz(tmp_path / f"fourbar_{method}.npz")
        check = mb.verify(plan)
        assert plan.success and check.passed and check.closure_residual <= 1e-9
    assert any(p.suffix == ".html" for p in tmp_path.iterdir())
