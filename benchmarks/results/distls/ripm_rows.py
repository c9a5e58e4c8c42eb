"""The RIPM rows of the speed benchmark's iiwa-distance section
(:func:`mbplan.benchmarks.iiwa_obstacle.solve_case`, cases 0..n-1 in order in one process, as
``mbplan bench speed`` runs them; the IPOPT rows between them do not touch the RIPM's state) as
JSON lines: status, iterations, success, verification.

    PYTHONPATH=. python benchmarks/results/distls/ripm_rows.py 100 > rows.jsonl  # tree's root
"""

import json
import os
import sys
import warnings

sys.path.insert(0, os.getcwd())
from mbplan.benchmarks.iiwa_obstacle import solve_case

KEYS = ("status", "iterations", "success", "verified", "solve_time_s", "verification_reasons")


def main() -> None:
    warnings.simplefilter("ignore")
    n = int(sys.argv[1])
    for i in range(n):
        row = solve_case("ripm", n, 0, i, 40, 1e-6, 500, "via", "distance")
        print(json.dumps({"case": i, **{k: row[k] for k in KEYS}}), flush=True)


if __name__ == "__main__":
    main()
