"""A second process beside this one, running the calls given to it one after another
(`SecondProcess`): the demo fits its plan to the arm there while it plans, evaluates and
draws here.
"""

from __future__ import annotations

import multiprocessing
import pickle
import queue
import signal
import threading
import traceback
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any


class SecondProcess:
    """A spawned process that runs the calls `submit`ted to it one after another, beside
    this one, after `setup(*args)`; `result` returns the next call's result, or raises its
    exception as the call would have raised it here (the other process's traceback as its
    cause). Calls and results go through queues that never block the sender, so neither side
    waits for the other to read. Leaving the `with` block ends the process, busy or not: on
    Ctrl-C or a failure here nobody waits for work no longer wanted."""

    def __init__(self, setup: Callable[..., None], *args: Any) -> None:
        # Spawned, not forked: this process may already run Embree's and torch's threads.
        context = multiprocessing.get_context("spawn")
        self._calls: multiprocessing.Queue[Any] = context.Queue()
        self._results: multiprocessing.Queue[Any] = context.Queue()
        self._process = context.Process(
            target=_serve,
            args=(self._calls, self._results, setup, args),
            name="scanplan-demo",
            daemon=True,
        )
        with _sigint_ignored():  # inherited: Ctrl-C is this process's to handle
            self._process.start()

    def __enter__(self) -> SecondProcess:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self._calls.cancel_join_thread()  # calls it will not read are dropped at exit
        if exc_info[0] is None:
            self._calls.put(None)  # done: an idle process returns on it
        else:
            self._process.terminate()
        self._process.join(10.0)
        if self._process.is_alive():
            self._process.kill()
            self._process.join()

    def submit(self, fn: Callable[..., Any], *args: Any) -> None:
        self._calls.put((fn, args))

    def result(self) -> Any:
        while True:
            try:
                ok, value, trace = pickle.loads(self._results.get(timeout=1.0))
                break
            except queue.Empty:
                if not self._process.is_alive():
                    raise RuntimeError(
                        f"the demo's second process ended unexpectedly (exit code "
                        f"{self._process.exitcode})"
                    ) from None
        if not ok:
            raise value from _RemoteTraceback(trace)
        return value


class _RemoteTraceback(Exception):
    def __str__(self) -> str:
        return str(self.args[0])


def _serve(
    calls: multiprocessing.Queue[Any],
    results: multiprocessing.Queue[Any],
    setup: Callable[..., None],
    args: tuple[Any, ...],
) -> None:
    """The second process: setup, then each call received, its result or exception sent
    back, until told it is done (None)."""
    failed: tuple[bool, BaseException, str] | None = None
    try:
        setup(*args)
    except Exception as exc:  # told at the first call: the main process raises it
        failed = (False, exc, traceback.format_exc())
    while (call := _next_call(calls)) is not None:
        fn, fn_args = call
        reply = failed
        if reply is None:
            try:
                reply = (True, fn(*fn_args), "")
            except Exception as exc:
                reply = (False, exc, traceback.format_exc())
        try:  # pickled here, so that one that does not pickle is told, not lost
            results.put(pickle.dumps(reply))
        except Exception as exc:
            reply = (False, RuntimeError(f"{type(exc).__name__}: {exc}"), reply[2])
            results.put(pickle.dumps(reply))


def _next_call(calls: multiprocessing.Queue[Any]) -> Any:
    """The next call, or None once told so or once the process that gives them has gone."""
    parent = multiprocessing.parent_process()
    while True:
        try:
            return calls.get(timeout=1.0)
        except queue.Empty:
            if parent is not None and not parent.is_alive():
                return None


@contextmanager
def _sigint_ignored() -> Iterator[None]:
    """SIGINT ignored meanwhile (in the main thread; signals go there only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


__all__ = ["SecondProcess"]
