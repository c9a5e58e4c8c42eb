"""A live MeshCat server bound to 127.0.0.1 only, and showing a scene live or as a page.

The server runs meshcat's ZMQ–websocket bridge in a subprocess whose HTTP and websocket server
listen on 127.0.0.1 (its ZMQ socket already does); it exits when its parent does.
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import io
import os
import subprocess
import sys
import threading
import webbrowser

import meshcat

from mbplan.errors import MbplanError
from mbplan.viz.page import write_page
from mbplan.viz.scene import Scene

HOST = "127.0.0.1"  # the only interface the live server listens on


class MeshcatServer:
    """A MeshCat server in a subprocess listening on 127.0.0.1 only (HTTP, websocket, ZMQ).

    ``viewer`` (a ``meshcat.Visualizer``) sends to it; ``url`` is the page to open. Close it or
    use it as a context manager; it is killed when Python exits anyway.
    """

    def __init__(self) -> None:
        self._proc = subprocess.Popen(
            [sys.executable, "-u", "-c", "from mbplan.viz.server import _serve; _serve()"],
            stdin=subprocess.PIPE,  # the server exits when this pipe closes (we exit or die)
            stdout=subprocess.PIPE,
            start_new_session=True,  # Ctrl-C at an interactive prompt does not stop it
        )
        atexit.register(self.close)
        try:
            zmq_url = self._read("zmq_url=")
            self.url = self._read("web_url=")
            with contextlib.redirect_stdout(io.StringIO()):  # meshcat prints the URL
                self.viewer = meshcat.Visualizer(zmq_url=zmq_url)
        except BaseException:
            self.close()
            raise

    def _read(self, prefix: str) -> str:
        assert self._proc.stdout is not None
        line = self._proc.stdout.readline().decode("utf-8").strip()
        if not line.startswith(prefix):
            self._proc.kill()
            raise MbplanError(
                f"the MeshCat server did not start (exit code {self._proc.wait()}, output {line!r})"
            )
        return line[len(prefix) :]

    @property
    def pid(self) -> int:
        """Process id of the server."""
        return self._proc.pid

    def wait(self) -> int:
        """Block until the server exits; return its exit code."""
        return self._proc.wait()

    def close(self) -> None:
        """Stop the server (idempotent)."""
        atexit.unregister(self.close)
        if self._proc.poll() is None:
            self._proc.kill()
            self._proc.wait()
        for pipe in (self._proc.stdin, self._proc.stdout):
            if pipe is not None:
                pipe.close()

    def __enter__(self) -> MeshcatServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


LIVE: list[MeshcatServer] = []  # servers of replay()/drone_replay(), alive until exit


def show(scene: Scene, html: str | os.PathLike[str] | None, open_browser: bool) -> str:
    """Write ``scene``'s static page to ``html`` or serve it live; return the path or URL."""
    if html is not None:
        path = write_page(scene, html)
        location, url = str(path), path.resolve().as_uri()
    else:
        server = MeshcatServer()
        LIVE.append(server)
        scene(server.viewer)
        location = url = server.url
    if open_browser:
        webbrowser.open(url)
    return location


def serve_until_interrupted(scene: Scene, open_browser: bool) -> None:
    """Serve ``scene`` live until Ctrl-C, printing its URL once it is loaded."""
    # Ctrl-C from the moment the URL can be printed ends serving quietly.
    with MeshcatServer() as server, contextlib.suppress(KeyboardInterrupt):
        scene(server.viewer)
        print(f"MeshCat viewer at {server.url} (Ctrl-C stops the server)", flush=True)
        if open_browser:
            webbrowser.open(server.url)
        server.wait()


def _serve() -> None:
    """Entry point of the :class:`MeshcatServer` subprocess: meshcat's bridge with the HTTP and
    websocket server bound to 127.0.0.1 (its ZMQ socket already is). It exits when its stdin
    closes, i.e. when the parent exits, even if the parent is killed."""
    import tornado.web
    from meshcat.servers.zmqserver import ZMQWebSocketBridge

    def exit_on_eof() -> None:
        sys.stdin.buffer.read()
        os._exit(0)

    threading.Thread(target=exit_on_eof, daemon=True).start()

    class LocalBridge(ZMQWebSocketBridge):
        def make_app(self) -> tornado.web.Application:
            app = super().make_app()
            app.listen = functools.partial(app.listen, address=HOST)
            return app

    bridge = LocalBridge(host=HOST)
    print(f"zmq_url={bridge.zmq_url}", flush=True)
    print(f"web_url={bridge.web_url}", flush=True)
    bridge.run()
