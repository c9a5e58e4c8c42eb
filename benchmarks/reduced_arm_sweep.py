"""The arm sweep of ``tests/test_sweep.py`` (every arm, joint and frame goal, N = 6, rest warm
start) planned by the RIPM with each ``kkt_method`` given: success, iterations and time per task,
one JSON object on the last line. Run it in two checkouts to compare them.

    python benchmarks/reduced_arm_sweep.py full,reduced > arm-sweep.json
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

from test_sweep import _robot, _tasks  # noqa: E402

import mbplan as mb  # noqa: E402
from mbplan.robots import available_robots  # noqa: E402


def main() -> None:
    methods = sys.argv[1].split(",") if len(sys.argv) > 1 else ["full", "reduced"]
    out = {}
    for name in available_robots():
        robot = _robot(name)
        for kind, ocp in _tasks(robot, seed=len(name)).items():
            for m in methods:
                rest = np.repeat(ocp.q0[None], ocp.N + 1, axis=0)
                t0 = time.perf_counter()
                res = mb.plan(ocp, "ripm", warm_start=rest, max_iter=200, options={"kkt_method": m})
                out[f"{name}/{kind}/{m}"] = {
                    "success": bool(res.success),
                    "iterations": int(res.iterations),
                    "ms": 1e3 * (time.perf_counter() - t0),
                }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
