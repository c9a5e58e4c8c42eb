"""chain{n}-obstacle rows as `mbplan bench speed` makes them (speed_tasks.chain_case: a cold solve,
then a warm solve from the linear warm start, verified), with the planned and replayed goal errors.

PYTHONPATH=$PWD python benchmarks/results/chainobs/run.py 4 8 16 32 > benchmarks/results/chainobs/chain-obstacle.jsonl
"""

import json
import sys
import time

import numpy as np

from mbplan.benchmarks.common import plan_row
from mbplan.planning.solve import plan
from mbplan.tasks.speed import chain_target, chain_task

for links in map(int, sys.argv[1:]):
    for method in ("ripm", "ipopt"):
        ocp = chain_task(links, obstacle=True)
        t0 = time.perf_counter()
        plan(ocp, method, warm_start="linear")
        cold = time.perf_counter() - t0
        row, result, check = plan_row(ocp, method, warm_start="linear", tol=1e-6, max_iter=500)
        row = {"links": links, "method": method, "cold_total_time_s": cold, **row}
        row["planned_goal_error"] = float(np.max(np.abs(result.q[-1] - chain_target(links, True))))
        row["replayed_goal_error"] = check.final_goal_error_rad
        row["deviation_ratios"] = [check.joint_deviation_ratio, check.velocity_deviation_ratio]
        row["min_obstacle_distance_m"] = check.min_obstacle_distance_m
        print(json.dumps(row), flush=True)
