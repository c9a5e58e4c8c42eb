"""Jumps of the coal distance rows near a solution: iiwa-distance cases 0..k-1 solved in order,
case k stopped at iteration ``it``; ``|g(R(x, t dx)) - g(x) - t J dx|`` along 5 random unit
(max-norm) directions for t = 1e-8 and 1e-7 (a smooth g gives ~t²).

    PYTHONPATH=. python benchmarks/results/distls/distance_jumps.py 22 13  # tree's root
"""

import os
import sys
import warnings

import numpy as np

sys.path.insert(0, os.getcwd())
from mbplan.solvers import solve_ripm
from mbplan.tasks.speed import TASKS


def main() -> None:
    warnings.simplefilter("ignore")
    k, it = int(sys.argv[1]), int(sys.argv[2])
    for i in range(k):
        solve_ripm(*TASKS["iiwa-distance"](i))
    p, x0, o = TASKS["iiwa-distance"](k)
    r = solve_ripm(p, x0, o, max_iter=it)
    print(f"case {k} iterate {r.iterations}: inf_pr {r.inf_pr:.2e}, inf_du {r.inf_du:.2e}")
    jac = p.evaluate(r.x, 1.0, r.y, r.z).ineq_jacobian
    dirs = [d / np.abs(d).max() for d in np.random.default_rng(1).standard_normal((5, p.n))]
    _, _, g = p.values(r.x)
    for t in (1e-8, 1e-7):
        jumps = [np.abs(p.values(p.retract(r.x, t * d))[2] - g - t * (jac @ d)) for d in dirs]
        j = np.max(jumps, axis=0)
        active = int(np.sum((j > 1e-9) & (r.z > 1e-3)))
        print(
            f"t = {t:.0e}: rows jumping > 1e-9: {int(np.sum(j > 1e-9))}, > 1e-7: "
            f"{int(np.sum(j > 1e-7))}, max {j.max():.2e}; of them active (z > 1e-3): {active}"
        )


if __name__ == "__main__":
    main()
