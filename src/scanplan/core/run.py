"""The one place work is mapped over processes or a Dask cluster: independent tasks
(perturbation trials, defect trials, a catalogue's parts) in task order; and the one check
of a Dask scheduler's address (`open_scheduler`) every command with --scheduler goes through.
"""

from __future__ import annotations

import contextlib
import importlib.util
import logging
import multiprocessing
import os
import re
import signal
import socket
import ssl
import struct
import time
import warnings
from collections.abc import Callable, Iterator
from concurrent.futures import CancelledError, ProcessPoolExecutor
from contextlib import contextmanager
from typing import Any

CLUSTER_HINT = "--scheduler needs the cluster extra: pip install 'scanplan[cluster]'"
# How long a scheduler has to answer, and then to have a worker (one that is starting joins
# within seconds).
CONNECT_SECONDS = 10.0
WORKER_WAIT_SECONDS = 30.0
DASK_PORT = 8786
# What Dask's first message (its handshake, about 60 bytes) may announce before it is read.
_MAX_HANDSHAKE_BYTES = 1 << 16
_ADDRESS = re.compile(r"(tcp|tls)://(\[[0-9a-fA-F:.]+\]|[^\s/:\[\]]+)(?::(\d{1,5}))?")
TLS_HINT = (
    "TLS needs the cluster's certificates in Dask's configuration "
    "(distributed.comm.tls.ca-file, .client.cert, .client.key, or the variables "
    "DASK_DISTRIBUTED__COMM__TLS__CA_FILE, ..._CLIENT__CERT, ..._CLIENT__KEY); none are set"
)


def scheduler_address(address: str) -> tuple[str, str, int]:
    """(scheme, host, port) of a scheduler address tcp://HOST[:PORT] or tls://HOST[:PORT]
    (Dask's port 8786 when none is given), or a one-line ValueError."""
    match = _ADDRESS.fullmatch(address)
    port = int(match[3] or DASK_PORT) if match else 0
    if match is None or not 0 < port < 65536:
        raise ValueError(f"--scheduler {address!r}: expected tcp://HOST:PORT")
    return match[1], match[2].strip("[]"), port


def open_scheduler(
    address: str,
    connect_s: float = CONNECT_SECONDS,
    worker_wait_s: float = WORKER_WAIT_SECONDS,
    waiting: Callable[[str], None] | None = None,
) -> Any:
    """A Dask client on the scheduler at `address` once it is shown to be one and to have a
    worker: the address parsed, a connection made within `connect_s`, its first message
    read as Dask's handshake (a port that sends anything else, or nothing, is no scheduler),
    the server asked whether it is a scheduler, then up to `worker_wait_s` for a worker
    (`waiting` is told before that wait). TLS with the certificates of Dask's configuration.
    Any failure is one ValueError naming --scheduler; the caller closes the client."""
    scheme, host, port = scheduler_address(address)
    if importlib.util.find_spec("distributed") is None:
        raise ValueError(CLUSTER_HINT)
    # Deferred: Dask is the optional cluster extra.
    from dask.distributed import Client
    from distributed.security import Security

    security, context = None, None
    if scheme == "tls":
        try:
            security = Security()
            context = security.get_connection_args("client")["ssl_context"]
        except (OSError, ValueError) as exc:  # a certificate file missing or not one
            raise ValueError(f"--scheduler {address}: TLS settings: {exc}") from None
        if context is None:
            raise ValueError(f"--scheduler {address}: {TLS_HINT}")
    _read_handshake(address, host, port, connect_s, context)
    try:
        client = Client(address, timeout=connect_s, security=security)
    except (OSError, TimeoutError) as exc:
        raise ValueError(f"--scheduler {address}: cannot connect ({_first_line(exc)})") from None
    except Exception as exc:  # a Dask worker or nanny answers Client's questions otherwise
        raise ValueError(
            f"--scheduler {address}: a Dask server answers but is no scheduler "
            f"({type(exc).__name__}: {_first_line(exc)})"
        ) from None
    try:
        if not client.nthreads():
            if waiting is not None:
                waiting(f"--scheduler {address}: no worker yet; waiting {worker_wait_s:g} s")
            try:
                client.wait_for_workers(1, timeout=worker_wait_s)
            except TimeoutError:
                raise ValueError(
                    f"--scheduler {address}: no worker joined the cluster in {worker_wait_s:g} s"
                ) from None
    except BaseException:
        _close_quietly(client)
        raise
    return client


def _read_handshake(
    address: str, host: str, port: int, timeout_s: float, context: ssl.SSLContext | None
) -> None:
    """Connect to host:port and read the first message a Dask server sends unasked: a
    length, then frames whose first is a msgpack map of the peer's versions. Reads at most
    `_MAX_HANDSHAKE_BYTES`, all within `timeout_s`."""
    deadline = time.monotonic() + timeout_s
    where = f"--scheduler {address}"
    try:
        with socket.create_connection((host, port), timeout=timeout_s) as raw:
            sock = raw if context is None else context.wrap_socket(raw, server_hostname=host)
            with sock:
                (size,) = struct.unpack("<Q", _read(sock, 8, deadline))
                if size > _MAX_HANDSHAKE_BYTES:
                    raise _NotDask
                first = _first_frame(_read(sock, size, deadline))
    except _NotDask:
        raise ValueError(f"{where}: what answers there is not a Dask scheduler") from None
    except TimeoutError:
        raise ValueError(f"{where}: no answer in {timeout_s:g} s (not a Dask scheduler?)") from None
    except socket.gaierror as exc:
        raise ValueError(f"{where}: unknown host {host} ({exc.strerror})") from None
    except ssl.SSLError as exc:
        raise ValueError(f"{where}: TLS failed ({exc.reason or exc})") from None
    except OSError as exc:
        raise ValueError(f"{where}: cannot connect ({exc.strerror or exc})") from None
    # Deferred with Dask: msgpack is its dependency.
    import msgpack

    try:
        info = msgpack.unpackb(first)
    except Exception:  # msgpack raises several kinds on garbage
        info = None
    if not (isinstance(info, dict) and "python" in info):
        raise ValueError(f"{where}: what answers there is not a Dask scheduler")


class _NotDask(Exception):
    """Bytes no Dask server sends."""


def _read(sock: socket.socket, size: int, deadline: float) -> bytes:
    data = bytearray()
    while len(data) < size:
        sock.settimeout(max(deadline - time.monotonic(), 1e-3))
        chunk = sock.recv(size - len(data))
        if not chunk:  # closed before a whole message
            raise _NotDask
        data += chunk
    return bytes(data)


def _first_frame(message: bytes) -> bytes:
    """The first frame of Dask's framing: a count, the lengths, then the frames."""
    if len(message) < 16:
        raise _NotDask
    (count,) = struct.unpack_from("<Q", message)
    if not 0 < count <= 64 or len(message) < 8 * (count + 1):
        raise _NotDask
    (length,) = struct.unpack_from("<Q", message, 8)
    start = 8 * (count + 1)
    if start + length > len(message):
        raise _NotDask
    return message[start : start + length]


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _close_quietly(client: Any) -> None:
    with contextlib.suppress(Exception):
        client.close(timeout=2)


@contextmanager
def scheduler_client(address: str, **checks: Any) -> Iterator[Any]:
    """`open_scheduler(address, **checks)`'s client for the block, closed after it, with
    Dask's own log (a lost connection's retries and tracebacks) kept off the terminal; work
    the cluster lost (the scheduler went away) is one ValueError naming --scheduler."""
    with _quiet_dask():
        client = open_scheduler(address, **checks)
        try:
            yield client
        except CancelledError as exc:  # Dask's futures cancel when the scheduler goes away
            why = getattr(exc, "reason", None) or _first_line(exc)
            raise ValueError(f"--scheduler {address}: the cluster lost the work ({why})") from None
        finally:
            _close_quietly(client)


@contextmanager
def _quiet_dask() -> Iterator[None]:
    """Dask's loggers (each with its own handler on stderr) raised to CRITICAL for the block:
    scanplan says what matters in one line. Tornado's, which Dask logs through too, stay
    raised after it: a Ctrl-C inside the client's event loop is reported by that loop's
    thread once the block is left (a traceback from `tornado.application`)."""
    if importlib.util.find_spec("distributed") is not None:
        import distributed  # noqa: F401  its import sets these loggers' levels: ours after

    for name in ("tornado", "tornado.application", "tornado.general"):
        logging.getLogger(name).setLevel(logging.CRITICAL)
    names = ["distributed"] + [
        name for name in list(logging.root.manager.loggerDict) if name.startswith("distributed.")
    ]
    loggers = [logging.getLogger(name) for name in names]
    levels = [logger.level for logger in loggers]
    for logger in loggers:
        logger.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        for logger, level in zip(loggers, levels, strict=True):
            logger.setLevel(level)


def check_scheduler(address: str, waiting: Callable[[str], None] | None = None) -> None:
    """`open_scheduler`'s checks before any work (the client is closed again)."""
    with scheduler_client(address, waiting=waiting):
        pass


@contextmanager
def task_runner(scheduler: str | None, tasks: int) -> Iterator[Any]:
    """A map(function, tasks) for independent tasks: on the Dask scheduler at `scheduler`,
    else over worker processes, one per core (one after another if one suffices). Leaving
    the block early (an error, Ctrl-C, SIGTERM) drops the tasks not run and stops those
    running."""
    if scheduler is not None:
        with scheduler_client(scheduler) as client:
            try:
                yield lambda f, items: _dask_map(client, f, items)
            except (OSError, TimeoutError) as exc:  # the scheduler went away
                raise ValueError(f"--scheduler {scheduler}: {_first_line(exc)}") from None
        return
    workers = min(os.cpu_count() or 1, tasks)
    if workers == 1:
        yield map
        return
    # Spawned, not forked: the parent already runs Embree's threads.
    pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"))
    try:
        yield lambda f, items: _pool_map(pool, f, items)
    except BaseException:
        _stop_pool(pool)
        raise
    pool.shutdown()


def _pool_map(pool: ProcessPoolExecutor, f: Any, items: Any) -> Iterator[Any]:
    # Ctrl-C reaches every process of the terminal's group: the workers, started here, are
    # spawned with SIGINT blocked (they inherit the mask), so only this process answers it
    # and stops them; a Ctrl-C meanwhile waits until the workers are started.
    blocked = hasattr(signal, "pthread_sigmask")
    if blocked:
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        results = pool.map(f, items)
    finally:
        if blocked:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    yield from results


def _stop_pool(pool: ProcessPoolExecutor) -> None:
    """Drop the queued tasks and stop the running ones (an executor cannot stop a running
    task before Python 3.14: its processes are)."""
    processes = list((pool._processes or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    for process in processes:
        process.join(timeout=5)


def _dask_map(client: Any, f: Any, items: Any) -> Iterator[Any]:
    """`f` over `items` as Dask tasks, results in task order as each is ready (not gathered
    at once: an interrupted gather leaves Dask's waiting tasks to print their tracebacks)."""
    with warnings.catch_warnings():
        # A task holds its part: Dask's advice on graphs of large arguments is not the user's.
        warnings.filterwarnings("ignore", message="Sending large graph", category=UserWarning)
        futures = client.map(f, items, pure=False)
    done = False
    try:
        for future in futures:
            yield future.result()
        done = True
    finally:
        if not done:
            with contextlib.suppress(Exception):
                client.cancel(futures)


def counted(run: Any, progress: Callable[[int, int], None] | None) -> Any:
    """`run` that reports each finished task to `progress` (results stay in task order)."""
    if progress is None:
        return run

    def counting(f: Any, tasks: Any) -> Iterator[Any]:
        for i, result in enumerate(run(f, tasks)):
            progress(i + 1, len(tasks))
            yield result

    return counting
