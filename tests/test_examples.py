"""Every script in examples/ runs (in the size CI affords) and produces what it promises."""

import subprocess
import sys
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def run_example(name: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(EXAMPLES / name), *args], capture_output=True, text=True, timeout=600
    )


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
    """Reduced size: 30 iterations per solver (the full comparison is the iiwa benchmark)."""
    proc = run_example(
        "compare_formulations.py", "--seed", "1", "--max-iter", "30", "--out", str(tmp_path)
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    for name in ("ripm.npz", "ipopt.npz", "side_by_side.html", "convergence.png"):
        assert (tmp_path / name).stat().st_size > 0, name
