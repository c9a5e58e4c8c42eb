"""A replay as one self-contained HTML page: the viewer's JavaScript and the scene inlined.

The scene is drawn into a recorder instead of a live viewer; the page replays the recorded
commands (msgpack, base64) into meshcat's viewer. Meshes are embedded in their commands
(:mod:`mbplan.viz.shapes`): the page needs no network and no file beside it.
"""

from __future__ import annotations

import base64
import html as html_lib
import os
from pathlib import Path
from typing import Any

import meshcat
import umsgpack

from mbplan.validation import output_file
from mbplan.viz.plots import write_atomic
from mbplan.viz.scene import Scene

_VIEWER_JS = Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js"


class Recorder:
    """A meshcat window that records the commands (for a static page) instead of sending them."""

    def __init__(self) -> None:
        self.commands: list[bytes] = []

    def send(self, command: Any) -> None:
        self.commands.append(umsgpack.packb(command.lower()))


PAGE = """<!DOCTYPE html>
<html>
<head>
<meta charset="utf-8">
<title>{title}</title>
<style>
body {{ margin: 0; }}
#meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}
#legend {{ position: absolute; bottom: 8px; left: 8px; padding: 6px 10px; font: 14px sans-serif;
  background: rgba(255, 255, 255, 0.8); border-radius: 4px; }}
#legend span {{ display: inline-block; width: 12px; height: 12px; margin-right: 6px; }}
</style>
</head>
<body>
<div id="meshcat-pane"></div>
<div id="legend">{legend}</div>
<script>
{viewer_js}
</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
for (const command of [{commands}]) {{
  viewer.handle_command_bytearray(Uint8Array.from(atob(command), (c) => c.charCodeAt(0)));
}}
</script>
</body>
</html>
"""


def write_page(scene: Scene, path: str | os.PathLike[str]) -> Path:
    """Draw ``scene`` into a recorder and write the static page atomically."""
    path = output_file(path, (".html", ".htm"), "static page")
    recorder = Recorder()
    scene(meshcat.Visualizer(window=recorder))
    legend = "<br>".join(
        f'<span style="background: rgb({", ".join(str(round(255 * c)) for c in label.rgb)})">'
        f"</span>{html_lib.escape(label.text)}"
        for label in scene.labels
    )
    page = PAGE.format(
        title=html_lib.escape(scene.title),
        legend=legend,
        viewer_js=_VIEWER_JS.read_text(encoding="utf-8"),
        commands=",".join(f'"{base64.b64encode(c).decode("ascii")}"' for c in recorder.commands),
    )
    return write_atomic(path, page.encode("utf-8"))
