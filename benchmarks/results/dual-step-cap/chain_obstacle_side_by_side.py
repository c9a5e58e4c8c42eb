"""RIPM vs generalized IPOPT on the chain reach around a cylinder (16, 32, 64 links), one JSON
line per solve: ``python chain_obstacle_side_by_side.py > chain-obstacle.jsonl``."""

import json

from mbplan.tasks.speed import chain_case

KEYS = ("status", "iterations", "total_time_s", "solve_time_s", "time_per_iter_s", "verified")

for links in (16, 32, 64):
    for method in ("ripm", "ipopt"):
        row = chain_case(method, links, obstacle=True)
        print(json.dumps({"links": links, "method": method, **{k: row[k] for k in KEYS}}))
