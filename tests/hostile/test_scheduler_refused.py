"""A refused connection to a ``tcp://`` scheduler fails at once (issue 58, item 8): ``pipeline.chunks``
probes the address with a plain TCP connection before Dask's client, which retries a refused connection
until its timeout (``LOOMLIGHT_CONNECT_TIMEOUT``, 10 s: the 13-16 s the issue measured); only silence
waits the timeout out. The refusal follows ``tests/hostile/contract.py`` (exit code 2, one line naming
the option and the address, nothing written)."""
from __future__ import annotations

import socket
from pathlib import Path

import pytest

from tests.hostile.contract import assert_refused

H = Path(__file__).resolve().parent


@pytest.fixture(scope="module")
def ws(tmp_path_factory):
    from pipeline.cli import main

    W = tmp_path_factory.mktemp("scheduler")
    assert main(["ingest", str(H / "small.txt"), "--radius", "0.02", "-o", str(W / "yarns.zarr")]) == 0
    return W


def _closed_port() -> int:
    """A local port nothing listens on (bound, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_refused_scheduler_connection_fails_before_dask_waits(cli, ws, monkeypatch):
    """``--scheduler tcp://127.0.0.1:PORT`` with nothing listening. Reference: Dask's client is never
    constructed -- the probe refuses first, naming the address and ConnectionRefusedError -- and a wait
    would run into the 600 s timeout set here, not pass."""
    distributed = pytest.importorskip("distributed")

    def no_client(*args, **kwargs):
        raise AssertionError("Dask's Client was asked to connect to a refused address")

    monkeypatch.setattr(distributed, "Client", no_client)
    monkeypatch.setenv("LOOMLIGHT_CONNECT_TIMEOUT", "600")   # a wait would hang the test, not pass it
    address = f"tcp://127.0.0.1:{_closed_port()}"
    assert_refused(cli, ws, ["realize", ws / "yarns.zarr", "-o", ws / "fibers.zarr", "--spacing", "0.02",
                             "--scheduler", address], "--scheduler", address, "ConnectionRefusedError")
