"""The identity check: ``benchmarks/ripm_fingerprint.py``'s fingerprints of the RIPM tests'
small problems, iiwa-com 0-9, drone 0-9, drone-limits 0-9, chain4 and finger_edu, for the tree
in the working directory (``diff`` two trees' outputs).

    PYTHONPATH=. python <this tree>/benchmarks/results/distls/fingerprint_cases.py > out.txt
"""

import sys
import warnings
from pathlib import Path

sys.path.insert(0, str(Path.cwd()))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # benchmarks/
import ripm_fingerprint as fp

from mbplan.solvers import solve_ripm
from mbplan.tasks.speed import TASKS


def main() -> None:
    warnings.simplefilter("ignore")
    for name, problem, x0, opts in fp._test_cases():
        print(name, fp.fingerprint(solve_ripm(problem, x0, **opts)), flush=True)
    tasks = [(t, i) for t in ("iiwa-com", "drone", "drone-limits") for i in range(10)]
    for task, i in [*tasks, ("chain4", 0)]:
        problem, x0, options = TASKS[task](i)
        print(f"{task}/{i}", fp.fingerprint(solve_ripm(problem, x0, options)), flush=True)
    for kind, result in fp._finger_edu().items():
        print(f"finger_edu/{kind}", result, flush=True)


if __name__ == "__main__":
    main()
