import sys, warnings, types
warnings.simplefilter("ignore")
from pathlib import Path
sys.path.insert(0, str(Path.cwd()))
import numpy as np, coal
from mbplan.multibody import collision
from mbplan.benchmarks.speed_tasks import TASKS
from mbplan.solvers import solve_ripm
k, it = int(sys.argv[1]), int(sys.argv[2])
for i in range(k):
    p, x0, o = TASKS["iiwa-distance"](i); solve_ripm(p, x0, o)
p, x0, o = TASKS["iiwa-distance"](k)
r = solve_ripm(p, x0, o, max_iter=it)
J = p.evaluate(r.x, 1.0, r.y, r.z).ineq_jacobian
rng = np.random.default_rng(1)
dirs = [d / np.abs(d).max() for d in rng.standard_normal((5, p.n))]
def run(label, **attrs):
    proxy = types.SimpleNamespace(**{a: getattr(coal, a) for a in dir(coal) if not a.startswith("__")})
    def req():
        q = coal.DistanceRequest()
        for a, v in attrs.items(): setattr(q, a, v)
        return q
    proxy.DistanceRequest = req
    collision.coal = proxy
    _, _, g = p.values(r.x)
    jumps = []
    for dx in dirs:
        for t in (1e-8, 1e-7):
            _, _, g2 = p.values(p.retract(r.x, t * dx))
            jumps.append(np.abs(g2 - g - t * (J @ dx)))
    j8, j7 = np.max(jumps[0::2], axis=0), np.max(jumps[1::2], axis=0)
    print(f"{label}: t=1e-8: >1e-9 {int(np.sum(j8 > 1e-9))}, >1e-7 {int(np.sum(j8 > 1e-7))}, max {j8.max():.2e}; t=1e-7: >1e-8 {int(np.sum(j7 > 1e-8))}, >1e-7 {int(np.sum(j7 > 1e-7))}, max {j7.max():.2e}")
    jm = np.max(jumps, axis=0)
    print(f"{label}: rows with jump > 1e-9: {int(np.sum(jm > 1e-9))}, > 1e-8: {int(np.sum(jm > 1e-8))}, > 1e-7: {int(np.sum(jm > 1e-7))}, max {jm.max():.2e}", flush=True)
run("as shipped")
#run("dualitygap absolute", gjk_max_iterations=1000, gjk_convergence_criterion=coal.GJKConvergenceCriterion.DualityGap, gjk_convergence_criterion_type=coal.GJKConvergenceCriterionType.Absolute)
