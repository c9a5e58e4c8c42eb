"""Run cases 0..n-1 of iiwa-distance in order (one process, like the benchmark), log per case."""
import sys, warnings, json, io, contextlib, os
warnings.simplefilter("ignore")
sys.path.insert(0, ".")
from mbplan.benchmarks.speed_tasks import TASKS
from mbplan.solvers import solve_ripm
n = int(sys.argv[1]); outdir = sys.argv[2]; os.makedirs(outdir, exist_ok=True)
task = sys.argv[3] if len(sys.argv) > 3 else "iiwa-distance"
res = {}
for i in range(n):
    p, x0, o = TASKS[task](i)
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        r = solve_ripm(p, x0, o, print_level=1)
    open(f"{outdir}/{task}-{i}.log", "w").write(buf.getvalue())
    res[i] = (r.status.name, int(r.iterations), float(r.objective), float(r.kkt_error), r.message)
json.dump(res, open(f"{outdir}/{task}-status.json", "w"), indent=0)
