"""RIPM rows of the speed benchmark's iiwa-distance section (mbplan.benchmarks.iiwa_obstacle.solve_case,
cases 0..99 in order in one process, as `mbplan bench speed` runs them) -> JSON lines."""
import sys, warnings, json
warnings.simplefilter("ignore")
from pathlib import Path
sys.path.insert(0, str(Path.cwd()))
from mbplan.benchmarks.iiwa_obstacle import solve_case
n = int(sys.argv[1])
for i in range(n):
    row = solve_case("ripm", n, 0, i, 40, 1e-6, 500, "via", "distance")
    print(json.dumps({"case": i, **{k: row[k] for k in ("status", "iterations", "success", "verified", "solve_time_s", "verification_reasons")}}), flush=True)
