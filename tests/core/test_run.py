"""The scheduler check (run.py `open_scheduler`): anything but a Dask scheduler with a worker
is one ValueError naming --scheduler within its timeouts (a port sending garbage, one that
never answers or hangs up, a Dask worker's port, a cluster without workers, TLS without
certificates); a scheduler is reached over TCP and over TLS with Dask's settings."""

from __future__ import annotations

import importlib.util
import random
import shutil
import socket
import struct
import subprocess
import time

import pytest

from helpers import tcp_server
from scanplan.core.run import open_scheduler, scheduler_address, scheduler_client

needs_dask = pytest.mark.skipif(
    importlib.util.find_spec("distributed") is None, reason="dask distributed not installed"
)


def frames(*payloads: bytes) -> bytes:
    """Dask's framing of `payloads`, length first."""
    body = struct.pack("<Q", len(payloads)) + b"".join(struct.pack("<Q", len(p)) for p in payloads)
    body += b"".join(payloads)
    return struct.pack("<Q", len(body)) + body


ANSWERS = {
    "garbage": lambda c: c.sendall(random.Random(0).randbytes(4096)),
    "an exabyte announced": lambda c: c.sendall(b"\xff" * 8 + b"x" * 64),
    "frames of garbage": lambda c: c.sendall(frames(b"\xc1\xc1 not msgpack")),
    "a msgpack list": lambda c: c.sendall(frames(b"\x93\x01\x02\x03")),
    "a hang-up": lambda c: c.close(),
    "half a message, then a hang-up": lambda c: (c.sendall(b"\x40" + b"\0" * 7 + b"ab"), c.close()),
}


@needs_dask
@pytest.mark.parametrize("kind", ANSWERS)
def test_a_port_that_answers_anything_but_dask_is_refused_at_once(kind):
    with tcp_server(ANSWERS[kind]) as address:
        start = time.monotonic()
        with pytest.raises(ValueError) as caught:
            open_scheduler(address, connect_s=20.0)
    # Refused without waiting out the connect timeout (a wide margin: a loaded CI machine).
    assert time.monotonic() - start < 10.0
    message = str(caught.value)
    assert message == f"--scheduler {address}: what answers there is not a Dask scheduler"


@needs_dask
def test_a_port_that_never_answers_is_refused_after_the_connect_timeout():
    with tcp_server(lambda c: None) as address:
        start = time.monotonic()
        with pytest.raises(ValueError, match=r"no answer in 0\.5 s \(not a Dask scheduler\?\)"):
            open_scheduler(address, connect_s=0.5)
    assert 0.4 < time.monotonic() - start < 2.0


@needs_dask
def test_nothing_listening_and_an_unknown_host_are_one_line():
    with socket.create_server(("127.0.0.1", 0)) as s:
        free = s.getsockname()[1]  # closed again: nothing listens there
    with pytest.raises(ValueError, match=r"cannot connect \(Connection refused\)"):
        open_scheduler(f"tcp://127.0.0.1:{free}", connect_s=2.0)
    with pytest.raises(ValueError, match="unknown host nowhere.invalid"):
        open_scheduler("tcp://nowhere.invalid:8786", connect_s=2.0)


@pytest.mark.parametrize(
    "text", ["localhost", "inproc://x", "http://h:80", "tcp://h:0", "tcp://h:70000", "tcp://"]
)
def test_an_address_that_is_not_tcp_or_tls_host_port_is_refused(text):
    with pytest.raises(ValueError, match="expected tcp://HOST:PORT"):
        scheduler_address(text)


def test_addresses_parse_with_dask_s_port_by_default():
    assert scheduler_address("tcp://10.0.0.2") == ("tcp", "10.0.0.2", 8786)
    assert scheduler_address("tls://[::1]:9000") == ("tls", "::1", 9000)


def test_without_dask_the_check_names_the_extra(monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "distributed" else real(name)
    )
    with pytest.raises(ValueError, match=r"needs the cluster extra"):
        open_scheduler("tcp://127.0.0.1:8786")


def local_cluster(workers: int, **kwargs):
    """An in-process Dask cluster over TCP on loopback (threads, not processes: seconds)."""
    from dask.distributed import LocalCluster

    return LocalCluster(
        n_workers=workers,
        processes=False,
        threads_per_worker=1,
        host="127.0.0.1",
        dashboard_address=":0",
        **kwargs,
    )


@needs_dask
def test_a_scheduler_without_workers_is_waited_for_a_stated_time_then_refused():
    told: list[str] = []
    with local_cluster(0, protocol="tcp") as cluster:
        address = cluster.scheduler_address
        start = time.monotonic()
        with pytest.raises(ValueError) as caught:
            open_scheduler(address, worker_wait_s=0.5, waiting=told.append)
        waited = time.monotonic() - start
    assert str(caught.value) == f"--scheduler {address}: no worker joined the cluster in 0.5 s"
    assert told == [f"--scheduler {address}: no worker yet; waiting 0.5 s"]
    assert 0.4 < waited < 5.0


@needs_dask
def test_a_scheduler_with_a_worker_is_reached_and_a_worker_s_port_is_no_scheduler():
    told: list[str] = []
    with local_cluster(1, protocol="tcp") as cluster:
        with open_scheduler(cluster.scheduler_address, waiting=told.append) as client:
            assert sum(client.nthreads().values()) == 1
            assert client.submit(sum, [1, 2]).result() == 3
        (worker,) = cluster.workers.values()
        with pytest.raises(ValueError, match="a Dask server answers but is no scheduler"):
            open_scheduler(worker.address, connect_s=5.0)
    assert told == []  # a worker was there: no wait


@needs_dask
def test_tls_without_certificates_is_refused_in_one_line():
    import dask

    keys = ("ca-file", "client.cert", "client.key", "cert", "key")
    with dask.config.set({f"distributed.comm.tls.{k}": None for k in keys}):
        with pytest.raises(ValueError) as caught:
            open_scheduler("tls://127.0.0.1:8786")
    message = str(caught.value)
    assert "TLS needs the cluster's certificates" in message and "\n" not in message
    with dask.config.set({"distributed.comm.tls.ca-file": "/nonexistent/ca.pem"}):
        with dask.config.set({"distributed.comm.tls.client.cert": "/nonexistent/c.pem"}):
            with pytest.raises(ValueError, match="TLS settings"):
                open_scheduler("tls://127.0.0.1:8786")


@needs_dask
@pytest.mark.skipif(shutil.which("openssl") is None, reason="no openssl to make certificates")
def test_a_tls_scheduler_is_reached_with_dask_s_tls_settings(tmp_path):
    import dask
    from distributed.security import Security

    key, cert = tmp_path / "key.pem", tmp_path / "cert.pem"
    subprocess.run(
        ["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1",
         "-subj", "/CN=scanplan-test", "-keyout", key, "-out", cert],
        check=True, capture_output=True,
    )  # fmt: skip
    settings = {
        "distributed.comm.tls.ca-file": str(cert),
        "distributed.comm.tls.client.cert": str(cert),
        "distributed.comm.tls.client.key": str(key),
    }
    security = Security(
        tls_ca_file=str(cert),
        tls_scheduler_cert=str(cert),
        tls_scheduler_key=str(key),
        tls_worker_cert=str(cert),
        tls_worker_key=str(key),
        tls_client_cert=str(cert),
        tls_client_key=str(key),
        require_encryption=True,
    )
    with local_cluster(1, protocol="tls", security=security) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tls://")
        with dask.config.set(settings), open_scheduler(address) as client:
            assert client.submit(sum, [2, 3]).result() == 5
        with tcp_server(lambda c: c.sendall(b"HTTP/1.0 200 OK\r\n\r\n")) as plain:
            with dask.config.set(settings), pytest.raises(ValueError, match="TLS failed"):
                open_scheduler(plain.replace("tcp://", "tls://"), connect_s=2.0)


@needs_dask
def test_work_the_cluster_loses_is_one_line_and_dask_s_log_stays_quiet(capfd):
    cluster = local_cluster(1, protocol="tcp")
    with pytest.raises(ValueError) as caught:
        with scheduler_client(cluster.scheduler_address, connect_s=1.0) as client:
            future = client.submit(time.sleep, 30, pure=False)
            cluster.close()  # the scheduler goes away mid-run
            future.result()
    assert str(caught.value).startswith(
        f"--scheduler {cluster.scheduler_address}: the cluster lost the work ("
    )
    assert "\n" not in str(caught.value)
    assert capfd.readouterr().err == ""
