"""Regenerate docs/iiwa_plan.png and docs/side_by_side.png (headless Chromium, Debian package).

    python docs/make_screenshots.py

Case 1 of ``mbplan.paper.iiwa_obstacle_cases(n, seed=0)``, planned by the RIPM (maximal) and IPOPT
(generalized), shown at knot 20. docs/drone.png comes from ``examples/drone_docking.py``'s page.
"""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from test_browser import screenshot  # noqa: E402

from mbplan.paper import iiwa_obstacle_cases  # noqa: E402
from mbplan.planning.solve import plan  # noqa: E402
from mbplan.viz import static_html  # noqa: E402

if __name__ == "__main__":
    task = iiwa_obstacle_cases(2, 0)[1]
    maximal, generalized = (
        plan(task, "ripm", warm_start="linear"),
        plan(task, "ipopt", warm_start="linear"),
    )
    out = ROOT / "out"
    single = static_html([maximal], out / "iiwa_plan.html", task, frame=20)
    both = static_html([maximal, generalized], out / "side_by_side.html", task, frame=20)
    screenshot(f"file://{single}", ROOT / "docs" / "iiwa_plan.png")
    screenshot(f"file://{both}", ROOT / "docs" / "side_by_side.png")
