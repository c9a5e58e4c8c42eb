"""The arm sweep of ``tests/test_sweep.py`` (every arm, joint and frame goal, N = 6, rest warm
start) planned by the RIPM with each ``kkt_method`` given (``auto``: the default) in one process:
success, iterations and time per task, one JSON object on the last line. Run it in two checkouts
to compare them (from the root of each: it imports the working directory's ``mbplan``).

    python benchmarks/reduced_arm_sweep.py full,reduced,auto > arm-sweep.json
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path.cwd()))

from mbplan.benchmarks.arm_sweep import sweep_robot, sweep_tasks

import mbplan as mb
from mbplan.robots import available_robots


def main() -> None:
    methods = sys.argv[1].split(",") if len(sys.argv) > 1 else ["full", "reduced"]
    out = {}
    for name in available_robots():
        robot = sweep_robot(name)
        for kind, ocp in sweep_tasks(robot, seed=len(name)).items():
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
