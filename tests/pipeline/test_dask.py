"""Chunk tasks on a Dask cluster (pipeline/chunks.py, --scheduler): the same bytes as in this process.

References: the local build of the same command, byte for byte (every array's recorded sha256, the
EXR file); Dask's own fault handling (a killed worker's tasks rerun elsewhere); the artifact store's
contract (a failed command leaves the previous artifact, content hash and all, and no temporaries).
The demo's fabric (data/scenes/demo.toml) is the input: its realize, voxelize and a small fiberpath
render on a 2-worker cluster; the tiny tiling's svf on a LocalCluster the command starts itself.
The tests that start clusters are marked slow (their worker processes compile the kernels again on a
cold cache): ``make test-all`` runs them, ``make test`` the error cases and the local path.
"""
import json
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from tests.helpers import ROOT

DEMO = ROOT / "data" / "scenes" / "demo.toml"
LOOMLIGHT = [sys.executable, "-c", "import sys; from pipeline.cli import entry; sys.argv[0] = 'loomlight'; entry()"]


def _worker_env(**extra):
    env = {"NUMBA_NUM_THREADS": "1", "LOOMLIGHT_NUMBA_CACHE_ROOT": os.environ["LOOMLIGHT_NUMBA_CACHE_ROOT"],
           "PYTHONHASHSEED": "0", "MPLBACKEND": "Agg"}
    env.update(extra)
    return env


def _cluster(**env):
    import logging

    from distributed import LocalCluster

    return LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                        silence_logs=logging.CRITICAL, env=_worker_env(**env))


@pytest.fixture(scope="module")
def cluster():
    c = _cluster()
    yield c
    c.close()


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """The demo's yarns and tables (built here, in this process)."""
    from pipeline.cli import main

    d = tmp_path_factory.mktemp("dask_demo")
    assert main(["ingest", str(DEMO), "-o", str(d / "yarns.zarr")]) == 0
    assert main(["tables", str(d / "yarns.zarr"), "-o", str(d / "tables.zarr")]) == 0
    return d


def _arrays(path) -> dict:
    """name -> sha256 of every array of an artifact, as its writer recorded them."""
    meta = json.loads((Path(path) / "zarr.json").read_text())["attributes"]["loomlight"]
    return {k: v["sha256"] for k, v in meta["arrays"].items()}


def _content_hash(path) -> str:
    return json.loads((Path(path) / "zarr.json").read_text())["attributes"]["loomlight"]["content_hash"]


def _siblings(path):
    return sorted(p.name for p in Path(path).parent.iterdir() if p.name.startswith(f".{Path(path).name}."))


@pytest.mark.slow
def test_realize_and_voxelize_same_bytes_on_a_cluster(cli, demo, cluster):
    addr = cluster.scheduler_address
    for where, extra in (("local", []), ("dask", ["--scheduler", addr])):
        code, _, err = cli("realize", demo / "yarns.zarr", "-o", demo / f"fibers_{where}.zarr", *extra)
        assert code == 0, err
        code, _, err = cli("voxelize", demo / "tables.zarr", "-o", demo / f"grid_{where}.zarr", "--res", 24, 20, 40,
                           *extra)
        assert code == 0, err
    for kind in ("fibers", "grid"):
        local, dask = _arrays(demo / f"{kind}_local.zarr"), _arrays(demo / f"{kind}_dask.zarr")
        assert local == dask and len(local) >= 4


@pytest.mark.slow
def test_render_same_exr_on_a_cluster(cli, demo, cluster):
    """fiberpath with adaptive refinement (two passes of band tasks): the EXR and the image array."""
    code, _, err = cli("realize", demo / "yarns.zarr", "-o", demo / "fibers_local.zarr")
    assert code == 0, err
    args = [DEMO, "--method", "fiberpath", "--fibers", demo / "fibers_local.zarr", "--width", 40, "--height", 30,
            "--spp", 2, "--max-spp", 6]
    code, _, err = cli("render", *args, "-o", demo / "local.exr")
    assert code == 0, err
    code, _, err = cli("render", *args, "-o", demo / "dask.exr", "--scheduler", cluster.scheduler_address)
    assert code == 0, err
    assert (demo / "local.exr").read_bytes() == (demo / "dask.exr").read_bytes()
    assert _arrays(demo / "local.zarr") == _arrays(demo / "dask.zarr")
    assert not list(demo.glob(".dask.zarr.tmp-*"))  # the scratch film is gone


@pytest.mark.slow
@pytest.mark.parametrize("method", ["bysdf", "volpath"])
def test_the_room_renders_the_same_bytes_on_a_cluster(cli, cluster, tmp_path, method):
    """A tenth of the Sponza-class room (``loomlight room --scale 0.1``: eleven fabrics, meshes, area lights) by
    bysdf and procedural volpath: the EXR from a 2-worker cluster is the local one, byte for byte."""
    from pipeline.room import write_room

    scene = write_room(tmp_path / "room", scale=0.1).scene
    assert cli("ingest", scene, "-o", tmp_path / "yarns.zarr")[0] == 0
    inputs = (["--set", f"yarns={tmp_path / 'yarns.zarr'}"] if method == "bysdf" else
              ["--source", "procedural", "--tables", tmp_path / "tables.zarr"])
    if method == "volpath":
        assert cli("tables", tmp_path / "yarns.zarr", "-o", tmp_path / "tables.zarr")[0] == 0
    args = [scene, "--method", method, *inputs, "--width", 32, "--height", 18, "--spp", 2, "--max-depth", 4]
    for where, extra in (("local", []), ("dask", ["--scheduler", cluster.scheduler_address])):
        code, _, err = cli("render", *args, "-o", tmp_path / f"{where}.exr", *extra)
        assert code == 0, err
    assert (tmp_path / "local.exr").read_bytes() == (tmp_path / "dask.exr").read_bytes()


@pytest.mark.slow
def test_precompute_on_a_local_cluster_the_command_starts(tmp_path):
    """svf with --scheduler processes --workers 2: the command starts and stops its LocalCluster."""
    from tests.precompute.conftest import make_tiling

    tiling = make_tiling(tmp_path)
    base = ["precompute", "svf", str(tiling), "--resolution", "8", "--components", "4", "--sg-count", "4",
            "--chunk", "64"]
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    local = subprocess.run(LOOMLIGHT + base + ["-o", str(tmp_path / "local.zarr")], capture_output=True, text=True,
                           env=env)
    assert local.returncode == 0, local.stderr
    dask = subprocess.run(LOOMLIGHT + base + ["-o", str(tmp_path / "dask.zarr"), "--scheduler", "processes",
                                              "--workers", "2"], capture_output=True, text=True, env=env)
    assert dask.returncode == 0, dask.stderr
    assert "LocalCluster of 2 workers" in dask.stderr and "Dask dashboard" in dask.stderr
    assert _arrays(tmp_path / "local.zarr") == _arrays(tmp_path / "dask.zarr")


@pytest.mark.slow
def test_killed_worker_tasks_rerun_and_bytes_stay(demo):
    """A worker process killed while its tasks run: Dask reruns them elsewhere, the fibres are the same."""
    from distributed import Client

    local = demo / "fibers_local.zarr"
    if not local.exists():
        from pipeline.cli import main

        assert main(["realize", str(demo / "yarns.zarr"), "-o", str(local)]) == 0
    c = _cluster(LOOMLIGHT_TASK_SLEEP="0.7")
    try:
        with Client(c, set_as_default=False) as client:
            client.wait_for_workers(2)
            victim = next(iter(client.run(os.getpid).values()))
            out = demo / "fibers_killed.zarr"
            p = subprocess.Popen(LOOMLIGHT + ["realize", str(demo / "yarns.zarr"), "-o", str(out), "--scheduler",
                                              c.scheduler_address], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                 text=True)
            deadline = time.time() + 60
            while time.time() < deadline and not any(client.processing().values()):
                time.sleep(0.05)  # until the workers hold tasks
            time.sleep(0.3)
            assert p.poll() is None, p.communicate()
            os.kill(victim, signal.SIGKILL)
            _, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
        assert _arrays(out) == _arrays(local)
    finally:
        c.close()


LOST_CLUSTER = """
import sys, time
from distributed import LocalCluster
if __name__ == "__main__":
    c = LocalCluster(n_workers=1, threads_per_worker=1, dashboard_address=None, env={env!r})
    print(c.scheduler_address, flush=True)
    time.sleep(600)
"""


@pytest.mark.slow
def test_lost_scheduler_fails_with_its_address_and_keeps_the_artifact(demo, tmp_path):
    local = demo / "fibers_local.zarr"
    if not local.exists():
        from pipeline.cli import main

        assert main(["realize", str(demo / "yarns.zarr"), "-o", str(local)]) == 0
    out = tmp_path / "fibers.zarr"
    import shutil

    shutil.copytree(local, out)
    before = _content_hash(out)
    script = tmp_path / "cluster.py"
    script.write_text(textwrap.dedent(LOST_CLUSTER.format(env=_worker_env(LOOMLIGHT_TASK_SLEEP="2"))))
    host = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                            text=True, start_new_session=True)
    err_lines: list[str] = []
    try:
        addr = host.stdout.readline().strip()
        assert addr.startswith("tcp://")
        p = subprocess.Popen(LOOMLIGHT + ["realize", str(demo / "yarns.zarr"), "-o", str(out), "--force",
                                          "--scheduler", addr], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                             text=True)
        reader = threading.Thread(target=lambda: err_lines.extend(p.stderr), daemon=True)
        reader.start()
        # the scheduler goes only once the command has connected (its "scheduler:" line; a fixed wait lost
        # the race on a loaded machine, where the command had not reached the scheduler yet: "cannot reach"),
        # and a second later, while its tasks (2 s each) are in flight
        deadline = time.time() + 120
        while time.time() < deadline and p.poll() is None and not any(ln.startswith("scheduler:") for ln in err_lines):
            time.sleep(0.05)
        time.sleep(1.0)
        assert p.poll() is None, "".join(err_lines)
    finally:
        os.killpg(host.pid, signal.SIGKILL)
        host.wait()
    p.wait(timeout=120)
    reader.join(timeout=10)
    err = "".join(err_lines)
    assert p.returncode == 2, err
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("scheduler:")]
    assert len(lines) == 1 and addr in lines[0] and "lost the Dask scheduler" in lines[0], err
    assert _content_hash(out) == before and not _siblings(out)


def test_unreachable_scheduler_is_a_one_line_error(cli, demo, monkeypatch):
    monkeypatch.setenv("LOOMLIGHT_CONNECT_TIMEOUT", "1")
    out = demo / "unreached.zarr"
    code, _, err = cli("realize", demo / "yarns.zarr", "-o", out, "--scheduler", "tcp://127.0.0.1:9")
    assert code == 2 and "tcp://127.0.0.1:9" in err and "cannot reach" in err and not out.exists()


@pytest.mark.parametrize("args,env,words", [
    (["--scheduler", "threads"], {}, ["--scheduler", "unknown scheduler 'threads'"]),
    (["--scheduler", "tcp://nohost"], {}, ["--scheduler", "tcp://HOST:PORT"]),
    (["--scheduler", "processes", "--workers", "0"], {}, ["--workers", "positive integer"]),
    ([], {"LOOMLIGHT_SCHEDULER": "cluster"}, ["LOOMLIGHT_SCHEDULER", "unknown scheduler 'cluster'"]),
    (["--scheduler", "processes"], {"LOOMLIGHT_THREADS_PER_WORKER": "two"}, ["LOOMLIGHT_THREADS_PER_WORKER"]),
])
def test_bad_scheduler_values(cli, demo, monkeypatch, args, env, words):
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    out = demo / "bad.zarr"
    code, _, err = cli("realize", demo / "yarns.zarr", "-o", out, *args)
    assert code == 2 and all(w in err for w in words), err
    assert not out.exists()


def test_scene_scheduler_is_checked(cli, tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text(DEMO.read_text().replace("[render]", '[render]\nscheduler = "cluster"'))
    code, _, err = cli("render", scene, "--method", "fiberpath", "-o", tmp_path / "x.exr")
    assert code == 2 and "render.scheduler" in err, err


def test_local_commands_import_no_dask(demo, tmp_path):
    code = textwrap.dedent(f"""
        import sys
        from pipeline.cli import main
        assert main(["realize", {str(demo / 'yarns.zarr')!r}, "-o", {str(tmp_path / 'f.zarr')!r}]) == 0
        loaded = sorted(m for m in sys.modules if m.split(".")[0] in ("dask", "distributed"))
        assert not loaded, loaded
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
