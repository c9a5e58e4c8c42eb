"""``mbplan plan --viz`` serves the replay until Ctrl-C (it used to print a URL and exit)."""

import webbrowser

from mbplan.cli.main import main
from mbplan.viz import server as meshcat_server


def test_plan_viz_serves_until_ctrl_c(monkeypatch, capsys):
    served = []

    def wait(server):
        served.append((server.url, server._proc.poll()))  # printed, and the server is alive
        assert "MeshCat viewer at" in capsys.readouterr().out
        raise KeyboardInterrupt  # the user's Ctrl-C

    monkeypatch.setattr(meshcat_server.MeshcatServer, "wait", wait)
    monkeypatch.setattr(webbrowser, "open", lambda url: True)
    argv = ["plan", "--method", "ipopt", "--seed", "1", "--horizon", "10", "--viz"]
    code = main(argv)
    assert code in (0, 1)  # the plan's own status, not the interrupt's
    ((url, alive),) = served
    assert url.startswith("http://127.0.0.1:") and alive is None
    assert not meshcat_server.LIVE  # nothing left serving in the background
