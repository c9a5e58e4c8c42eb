"""Replays rendered by headless Chromium (SwiftShader WebGL): the robots are on screen and move.

Skipped without /usr/bin/chromium; CI installs it (``apt-get install chromium``). A robot pixel
is one of a formulation's tint — clearly orange (generalized) or clearly blue (maximal) — which
the grey background and grid and the green goal are not. The scenes have no task, so no red
obstacles.
"""

from __future__ import annotations

import os
import signal
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from test_viz import make_results  # tests/ is on sys.path (pytest's rootdir import mode)

from mbplan.viz import MeshcatServer, draw_results, static_html

CHROMIUM = Path("/usr/bin/chromium")
pytestmark = pytest.mark.skipif(
    not CHROMIUM.exists(), reason="Chromium is not installed at /usr/bin/chromium"
)
WIDTH, HEIGHT = 960, 540
BELOW_LABELS = slice(HEIGHT // 5, HEIGHT)  # the scene's text labels sit at the top


def screenshot(url: str, png: Path, budget_ms: int = 5000, timeout_s: float = 45.0) -> np.ndarray:
    """Render ``url`` headless after ``budget_ms`` of virtual time; the RGB pixels."""
    with tempfile.TemporaryDirectory() as profile:
        proc = subprocess.Popen(
            [
                str(CHROMIUM),
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                f"--user-data-dir={profile}",
                f"--virtual-time-budget={budget_ms}",
                f"--screenshot={png}",
                f"--window-size={WIDTH},{HEIGHT}",
                url,
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            pytest.fail(f"Chromium did not finish rendering {url} in {timeout_s} s")
    assert png.exists(), f"Chromium wrote no screenshot of {url}"
    return np.asarray(Image.open(png).convert("RGB")).astype(int)


def robot_pixels(image: np.ndarray) -> np.ndarray:
    r, g, b = image[..., 0], image[..., 1], image[..., 2]
    return ((r > g + 30) & (r > b + 60)) | ((b > r + 60) & (b > g + 20))


def halves(mask: np.ndarray) -> tuple[int, int]:
    """Count of ``mask`` below the labels in the left and the right half of the image."""
    region = mask[BELOW_LABELS]
    return int(region[:, : WIDTH // 2].sum()), int(region[:, WIDTH // 2 :].sum())


def test_static_side_by_side_shows_both_robots_moving(tmp_path: Path) -> None:
    results = make_results()
    images = []
    for frame in (0, -1):
        page = static_html(results, tmp_path / f"frame{frame}.html", frame=frame)
        image = screenshot(page.resolve().as_uri(), tmp_path / f"frame{frame}.png")
        left, right = halves(robot_pixels(image))
        assert left > 500 and right > 500, f"robot pixels at frame {frame}: {left}, {right}"
        images.append(image)
    changed = np.abs(images[0] - images[1]).max(axis=2) > 40
    left, right = halves(changed)
    assert left > 300 and right > 300, (
        f"pixels changed between the first and last knot: {left}, {right}"
    )


def test_live_server_page_renders_the_robot(tmp_path: Path) -> None:
    """A live page streams its meshes over a websocket after loading, which can take longer than
    a static page on a busy machine: give it up to three increasing virtual-time budgets."""
    with MeshcatServer() as server:
        draw_results(server.viewer, make_results()[:1], frame=-1)
        for budget in (5000, 15000, 30000):
            image = screenshot(server.url, tmp_path / "live.png", budget_ms=budget, timeout_s=90.0)
            if robot_pixels(image)[BELOW_LABELS].sum() > 500:
                break
    mask = robot_pixels(image)[BELOW_LABELS]
    rows, cols = np.nonzero(mask)
    assert len(rows) > 500, f"{len(rows)} robot pixels"
    # one robot, framed: its pixels are around the middle of the picture
    assert WIDTH / 4 < cols.mean() < 3 * WIDTH / 4
