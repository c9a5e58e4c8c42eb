"""A new process's first plan: compilation reported apart from the solve
(:mod:`mbplan.engine.compile_clock`), per-process work kept on disk
(:mod:`mbplan.engine.disk_cache`) without changing a result by a bit and never failing on a
damaged entry, ``mbplan warmup``'s command line and the speed benchmark's cold section."""

from __future__ import annotations

import ctypes
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from reference_problems import HS071_X0, hs071
from test_determinism import fingerprint

from mbplan.cli.main import main
from mbplan.engine import disk_cache
from mbplan.engine.compile_clock import CompileClock, compiling
from mbplan.results import load_npz, save_npz
from mbplan.solvers import solve_ripm
from mbplan.tasks.speed import TASKS

ROOT = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------------ compile clock
def test_clock_leaves_out_this_threads_compilation_only():
    def other_thread() -> None:
        with compiling():
            time.sleep(0.05)

    with CompileClock() as clock:
        with compiling():
            time.sleep(0.05)
        with compiling():  # nested: counted once
            with compiling():
                time.sleep(0.02)
        other = threading.Thread(target=other_thread)
        other.start()
        other.join()
    assert 0.07 <= clock.compile_s < clock.wall() - 0.04  # not the other thread's 0.05 s
    assert clock.elapsed() == pytest.approx(clock.wall() - clock.compile_s)
    frozen = (clock.wall(), clock.elapsed(), clock.compile_s)
    with compiling():  # stopped: no longer listening
        time.sleep(0.01)
    assert (clock.wall(), clock.elapsed(), clock.compile_s) == frozen


def test_a_solve_reports_compilation_apart_from_its_time(monkeypatch):
    """A kernel compiled during the solve (here: a pretend one in the first gradient) is in
    ``compile_time_s`` and not in ``wall_time_s`` nor in the per-iteration times."""
    problem = hs071()
    gradient, calls = problem._grad, []

    def compiling_gradient(x):
        if not calls:
            with compiling():
                time.sleep(0.3)
        calls.append(1)
        return gradient(x)

    monkeypatch.setattr(problem, "_grad", compiling_gradient)
    start = time.perf_counter()
    res = solve_ripm(problem, HS071_X0)
    outside = time.perf_counter() - start
    assert res.success
    assert res.compile_time_s >= 0.3
    assert res.wall_time_s <= outside - 0.3
    assert res.history.time_s[-1] <= res.wall_time_s
    assert res.history.time_s[0] <= outside - 0.3


def test_plan_results_carry_their_compile_time_through_the_file(tmp_path):
    from mbplan.planning.solve import plan
    from mbplan.tasks.speed import chain_task

    ocp = chain_task(2, N=8)
    result = plan(ocp, "ripm", warm_start="linear")
    assert result.compile_time_s >= 0.0
    assert result.total_time_s >= result.solve_time_s + result.compile_time_s
    loaded = load_npz(save_npz(result, tmp_path / "r.npz"))
    assert loaded.compile_time_s == result.compile_time_s


# ------------------------------------------------------------------------ disk cache
@pytest.fixture
def store(tmp_path, monkeypatch) -> Path:
    """An empty store of its own (the compiled kernels stay where they are), storing what is
    quick to build too."""
    monkeypatch.setattr(disk_cache, "store_dir", lambda: tmp_path / "store")
    monkeypatch.setattr(disk_cache, "MIN_BUILD_S", 0.0)
    monkeypatch.delenv("MBPLAN_DISK_CACHE", raising=False)
    return tmp_path / "store"


def test_a_value_comes_back_as_it_was(store):
    base = np.arange(12.0).reshape(3, 4)
    frozen = np.arange(5)
    frozen.flags.writeable = False
    value = {
        "a": base,
        "same": base.view(),  # the same memory: stays one memory
        "frozen": frozen,
        "fortran": np.asfortranarray(base),
        "empty": np.zeros((0, 3)),
        "tuple": (base, 3, "x"),
    }
    builds = []
    for _ in range(2):
        got = disk_cache.cached("probe", lambda: ("key", 1), lambda: builds.append(1) or value)
    assert builds == [1]  # built once, then loaded
    assert got is not value and got["tuple"][0] is got["a"]
    assert np.shares_memory(got["a"], got["same"])
    assert not got["frozen"].flags.writeable and got["a"].flags.writeable
    assert got["fortran"].flags.f_contiguous and not got["fortran"].flags.c_contiguous
    for name in ("a", "same", "frozen", "fortran", "empty"):
        assert got[name].dtype == value[name].dtype
        np.testing.assert_array_equal(got[name], value[name])


def _partial_view():
    a = np.arange(10.0)
    return {"a": a, "b": a[2:5]}  # part of another array's memory


@pytest.mark.parametrize(
    "make",
    [_partial_view, lambda: {"s": np.arange(10.0)[::2]}, lambda: {"p": ctypes.c_void_p(1)}],
    ids=["partial-view", "strided-view", "ctypes-pointer"],
)
def test_a_value_that_would_not_come_back_as_it_is_is_not_stored(store, make):
    value, builds = make(), []
    for _ in range(2):
        got = disk_cache.cached("probe", lambda: "key", lambda: builds.append(1) or value)
        assert got is value
    assert builds == [1, 1]
    assert not list(store.rglob("*.pkl"))


def test_a_key_that_cannot_be_pickled_is_built_every_time(store):
    builds = []
    for _ in range(2):
        disk_cache.cached("probe", lambda: (lambda: 0,), lambda: builds.append(1) or [1])
    assert builds == [1, 1] and not store.exists()


def test_a_damaged_entry_is_rebuilt_and_replaced(store):
    disk_cache.cached("probe", lambda: "other", lambda: np.arange(4.0))
    disk_cache.cached("probe", lambda: "key", lambda: np.arange(4.0))
    other, entry = (
        store / "probe" / f"{disk_cache.digest_of('probe', k)}.pkl" for k in ("other", "key")
    )
    good = entry.read_bytes()
    middle = len(good) // 2
    damaged = {
        "truncated": good[:middle],
        "empty": b"",
        "garbage": b"garbage",
        "corrupt payload": good[:middle] + bytes(b ^ 0xFF for b in good[middle:]),
        "another key's entry": other.read_bytes(),
    }
    for what, data in damaged.items():
        entry.write_bytes(data)
        got = disk_cache.cached("probe", lambda: "key", lambda: np.arange(4.0) + 1)
        np.testing.assert_array_equal(got, np.arange(4.0) + 1, err_msg=what)
        assert entry.read_bytes() != data, what  # written again
    assert not list(store.rglob("*.tmp"))


def test_a_value_quick_to_build_is_not_stored(store, monkeypatch):
    monkeypatch.setattr(disk_cache, "MIN_BUILD_S", 0.05)
    disk_cache.cached("probe", lambda: "quick", lambda: np.zeros(3))
    assert not list(store.rglob("*.pkl"))
    disk_cache.cached("probe", lambda: "slow", lambda: time.sleep(0.05) or np.zeros(3))
    assert len(list(store.rglob("*.pkl"))) == 1


def test_the_cache_is_off_on_request_and_its_size_is_bounded(store, monkeypatch):
    monkeypatch.setenv("MBPLAN_DISK_CACHE", "off")
    disk_cache.cached("probe", lambda: "off", lambda: np.zeros(3))
    assert not store.exists()
    monkeypatch.delenv("MBPLAN_DISK_CACHE")
    monkeypatch.setattr(disk_cache, "MAX_BYTES", 3000)
    for i in range(4):  # ~1 kB each
        disk_cache.cached("probe", lambda i=i: i, lambda: np.zeros(128))
        time.sleep(0.01)
    kept = sorted(store.rglob("*.pkl"))
    assert 1 <= len(kept) < 4
    assert sum(p.stat().st_size for p in kept) <= 3000


def test_a_riemannian_function_whose_library_is_gone_is_compiled_again(
    store, tmp_path, monkeypatch
):
    from mbplan.engine.jit import jit_available
    from mbplan.lie import SO3

    if not jit_available():
        pytest.skip("no C compiler")
    monkeypatch.setenv("MBPLAN_CACHE_DIR", str(tmp_path / "jit"))
    from mbplan.engine import RiemannianFunction

    def build():
        return RiemannianFunction("cold_probe", [("R", SO3)], lambda R: R[0, 1] * R[1, 0], jit=True)

    first = build()
    (entry,) = store.rglob("*.pkl")
    loaded = build()  # from the disk: no derivation, the same patterns and libraries
    R = SO3.exp(np.array([[0.1, 0.2, 0.3]]))
    for a, b in zip(
        first.hessian({"R": R}, None, np.ones((1, 1))),
        loaded.hessian({"R": R}, None, np.ones((1, 1))),
        strict=True,
    ):
        np.testing.assert_array_equal(a, b)
    for lib in (tmp_path / "jit").glob("cold_probe_hessian_*.so"):
        lib.unlink()
    again = build()
    np.testing.assert_array_equal(again.jac_rows, first.jac_rows)
    assert list((tmp_path / "jit").glob("cold_probe_hessian_*.so"))
    assert entry.exists()


# ------------------------------------------------------------------------ robots
def test_visual_meshes_are_read_when_first_drawn_as_they_were(monkeypatch):
    """A robot's visual geometry is read at the first ``visual_model`` (a plan never reads it),
    and is then what Pinocchio reads eagerly, also with locked joints."""
    import pinocchio as pin

    from mbplan.robots import IIWA_URDF, load, load_robot

    calls = []
    read = pin.buildGeomFromUrdf
    monkeypatch.setattr(pin, "buildGeomFromUrdf", lambda *a, **k: calls.append(1) or read(*a, **k))
    desc = load(IIWA_URDF)
    robot = load_robot(desc, lock=["iiwa_joint_7"])
    assert calls == []
    model, visual = pin.buildModelsFromUrdf(
        str(IIWA_URDF),
        package_dirs=[str(IIWA_URDF.parent)],
        geometry_types=[pin.GeometryType.VISUAL],
    )
    joint = model.getJointId("iiwa_joint_7")
    reduced = pin.buildReducedModel(model, [visual], [joint], pin.neutral(model))[1][0]
    for got, expected in ((desc.visual_model, visual), (robot.visual_model, reduced)):
        assert [(g.name, g.parentJoint, g.parentFrame) for g in got.geometryObjects] == [
            (g.name, g.parentJoint, g.parentFrame) for g in expected.geometryObjects
        ]
        for a, b in zip(got.geometryObjects, expected.geometryObjects, strict=True):
            np.testing.assert_array_equal(a.placement.homogeneous, b.placement.homogeneous)
    assert calls == [1] and robot.visual_model is robot.visual_model  # read once


# ------------------------------------------------------------------------ determinism
_CHILD = """
import pathlib, sys
from mbplan.engine import disk_cache
hits = []
load = disk_cache.load
def counting(*args):
    value = load(*args)
    hits.append(value is not disk_cache.MISSING)
    return value
disk_cache.load = counting
disk_cache.store_dir = lambda: pathlib.Path(sys.argv[1])
from test_determinism import fingerprint
from mbplan.solvers import solve_ripm
from mbplan.tasks.speed import TASKS
problem, x0, options = TASKS["iiwa-com"](0)
print(sum(hits), len(hits), fingerprint(solve_ripm(problem, x0, options)))
"""


def _child(store: Path) -> tuple[int, int, str]:
    """(entries loaded, looked up, fingerprint) of the iiwa solved in a new process."""
    path = os.pathsep.join([str(ROOT / "tests"), str(ROOT), os.environ.get("PYTHONPATH", "")])
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, str(store)],
        capture_output=True,
        text=True,
        check=True,
        timeout=600,
        env={**os.environ, "PYTHONPATH": path},
    ).stdout.split()
    return int(out[-3]), int(out[-2]), out[-1]


@pytest.mark.slow
def test_results_are_the_same_bit_for_bit_without_with_a_cold_and_with_a_warm_disk_cache(
    store, monkeypatch
):
    """The iiwa solved with the disk cache off, in a new process with an empty one (everything
    built and written), in another new process (everything loaded: the compiled functions'
    entries and the structures) and here with it warm (the structures loaded): one
    fingerprint (iterates, multipliers, history)."""

    def solve() -> str:
        problem, x0, options = TASKS["iiwa-com"](0)
        return fingerprint(solve_ripm(problem, x0, options))

    monkeypatch.setenv("MBPLAN_DISK_CACHE", "off")
    without = solve()
    monkeypatch.delenv("MBPLAN_DISK_CACHE")
    hits, lookups, cold = _child(store)
    assert hits == 0 and lookups > 4
    assert {"riemannian", "reduction", "structure", "kkt_pattern", "analysis"} <= {
        p.parent.name for p in store.rglob("*.pkl")
    }
    hits, lookups, warm = _child(store)
    assert hits == lookups > 4
    assert without == cold == warm == solve()


# ------------------------------------------------------------------------ command line
def test_warmup_lists_its_plans_and_refuses_unknown_ones(capsys):
    assert main(["warmup", "--list"]) == 0
    listed = capsys.readouterr().out.split()
    assert {"iiwa-ripm", "iiwa-ipopt", "drone-ripm", "chain8-ripm"} <= set(listed)
    assert main(["warmup", "--only", "iiwa-ripm,chain8-ripm", "--list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == ["iiwa-ripm", "chain8-ripm"]
    assert main(["warmup", "--only", "iiwa-rpim"]) == 2
    assert "unknown plan 'iiwa-rpim'" in capsys.readouterr().err
    assert main(["warmup", "--only", "iiwa-ripm,iiwa-ripm"]) == 2


def test_speed_bench_renders_its_cold_section_alone_and_beside_the_rest(tmp_path, monkeypatch):
    from mbplan.benchmarks import speed

    numbers = {
        "process_s": 1.5, "startup_s": 0.9, "cold_plan_s": 0.4, "cold_compile_s": 0.3,
        "cold_solve_s": 0.1, "warm_plan_s": 0.2, "warm_solve_s": 0.1, "cold_iterations": 13,
        "warm_iterations": 13,
    }  # fmt: skip
    monkeypatch.setattr(speed, "cold_starts", lambda repeats: {"iiwa-com": {"ripm": numbers}})
    assert main(["bench", "speed", "--cold-only", "--out", str(tmp_path)]) == 0
    text = (tmp_path / "results.md").read_text()
    assert "| iiwa-com | ripm | 1.50 | 0.90 | 0.40 | 0.30 | 0.10 | 0.20 | 0.10 | 2.00 |" in text
    summary = __import__("json").loads((tmp_path / "summary.json").read_text())
    assert summary["cold"]["iiwa-com"]["ripm"] == numbers


def test_the_cold_start_child_reports_a_cold_and_a_warm_plan():
    from mbplan.benchmarks.cold_start import COLD_TASKS, measure

    assert {"iiwa-com", "drone", "chain8"} <= set(COLD_TASKS)
    numbers = measure("chain8", "ipopt")
    assert numbers["cold_iterations"] == numbers["warm_iterations"] > 0
    assert all(numbers[f"{w}_plan_s"] >= numbers[f"{w}_solve_s"] for w in ("cold", "warm"))
