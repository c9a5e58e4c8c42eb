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
