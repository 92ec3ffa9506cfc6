"""What every command shares: one-line errors and exit codes (2 for a mistake, 1 for a bug,
3 for a result that fails --require, 130 for Ctrl-C, 143 for SIGTERM), the progress bar on
a terminal, and no half-made output directory after a failure.
"""

from __future__ import annotations

import functools
import os
import shutil
import signal
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

import typer
import typer.core

from scanplan.cli.help_text import ReadableHelp, polish
from scanplan.core import files


class OneLineErrors(ReadableHelp, typer.core.TyperGroup):
    """The app's Click group: a usage error (unknown option or command, missing argument, a
    value that does not convert or is out of bounds) is one line on stderr and exit 2, not
    Typer's boxed panel; --help stays rich, and reads as prose (`help_text`)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        polish(self)

    def main(
        self,
        args: Sequence[str] | None = None,
        prog_name: str | None = None,
        complete_var: str | None = None,
        standalone_mode: bool = True,
        windows_expand_args: bool = True,
        **extra: Any,
    ) -> Any:
        from typer._click.exceptions import ClickException

        # SIGTERM unwinds like Ctrl-C (signals reach only the main thread's handlers); both
        # are recorded too, in case a library swallows the exception (see `files.stopped_by`).
        global _said_stopped
        files.stopped_by = None  # a fresh run (tests invoke the app many times in one process)
        _said_stopped = False
        main_thread = threading.current_thread() is threading.main_thread()
        previous = (
            (signal.signal(signal.SIGTERM, _terminated), signal.signal(signal.SIGINT, _interrupted))
            if main_thread
            else None
        )
        try:
            rv = super().main(args, prog_name, complete_var, False, windows_expand_args, **extra)
            # Stopped, and not said yet: the exception was swallowed by a library, or Typer
            # made it a silent exit 130 (outside a command's own handler).
            if files.stopped_by is not None and not _said_stopped and rv in (None, 0, 130):
                raise Terminated if files.stopped_by == signal.SIGTERM else KeyboardInterrupt
        except Terminated:
            typer.echo("terminated", err=True)
            return _exit(143, standalone_mode)
        except KeyboardInterrupt:  # before a command's own handler: while importing, parsing
            typer.echo("interrupted", err=True)
            return _exit(130, standalone_mode)
        except ClickException as exc:
            if type(exc).__name__ == "NoArgsIsHelpError":  # bare `scanplan`: the help
                exc.show()
                code = 2
            else:
                typer.echo(f"error: {usage_message(exc)}", err=True)
                code = exc.exit_code
            if not standalone_mode:
                return code
            sys.exit(code)
        except typer.Abort:
            terminated = files.stopped_by == signal.SIGTERM
            typer.echo("terminated" if terminated else "interrupted", err=True)
            return _exit(143 if terminated else 130, standalone_mode)
        finally:
            if previous is not None:
                signal.signal(signal.SIGTERM, previous[0])
                signal.signal(signal.SIGINT, previous[1])
            # The stop is answered: the writers of whatever runs next in this process (a
            # test after an in-process run) must not take it for theirs.
            files.stopped_by = None
        if not standalone_mode:
            return rv
        sys.exit(rv if isinstance(rv, int) else 0)


# Whether `user_errors` has printed the stop line already (not twice).
_said_stopped = False


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the process is so that every `finally` and temporary-file
    clean-up runs, as for Ctrl-C."""


def _terminated(signum: int, frame: Any) -> None:
    if _stop_here(signum, frame):
        raise Terminated


def _interrupted(signum: int, frame: Any) -> None:
    if _stop_here(signum, frame):
        raise KeyboardInterrupt


def _stop_here(signum: int, frame: Any) -> bool:
    """Record the signal and say whether to raise here: not inside a module's import (the
    signal comes again 50 ms later instead), where an exception crashes a C extension's
    initialization (cascadio segfaults) or is swallowed around an optional import (trimesh)."""
    files.stopped_by = signum
    while frame is not None:
        if frame.f_code.co_filename.startswith("<frozen importlib"):
            again = threading.Timer(0.05, os.kill, (os.getpid(), signum))
            again.daemon = True
            again.start()
            return False
        frame = frame.f_back
    return True


def _exit(code: int, standalone_mode: bool) -> int:
    if not standalone_mode:
        return code
    sys.exit(code)


def usage_message(exc: Exception) -> str:
    """A Click usage error as one line naming the option or argument."""
    message = getattr(exc, "message", str(exc))
    param = getattr(exc, "param", None)
    hint = getattr(exc, "param_hint", None)
    if hint is None and param is not None:
        hint = param.get_error_hint()
    if isinstance(hint, list | tuple):
        hint = " / ".join(hint)
    errors = getattr(exc.__cause__, "errors", None)
    if callable(errors):  # a pydantic conversion error
        first = (errors() or [{}])[0]
        kind = str(first.get("type", ""))
        value = first.get("input")
        if kind.startswith("int_"):
            message = f"{value!r} is not a valid integer"
        elif kind.startswith("float_"):
            message = f"{value!r} is not a valid number"
        elif "input" in first:
            message = f"{value!r}: {first.get('msg', message)}"
    if type(exc).__name__ == "MissingParameter" or not hint:
        text = exc.format_message() if hasattr(exc, "format_message") else message
    else:
        text = f"{str(hint).replace(chr(39), '')}: {message}"
    ctx = getattr(exc, "ctx", None)
    where = f" (see '{ctx.command_path} --help')" if ctx is not None else ""
    return " ".join(f"{text}{where}".split())


# A run that worked but whose result fails a --require criterion (0 success, 1 a bug or a
# failed part, 2 a mistake in the input).
EXIT_FAILED_REQUIREMENT = 3

F = TypeVar("F", bound=Callable[..., Any])
# Set it to see the traceback of an internal error.
DEBUG_ENV = "SCANPLAN_DEBUG"


def user_errors(fn: F) -> F:
    """Turn the library's ValueError (and file errors) into one clear line and exit 2, and
    any other exception, a bug, into one line and exit 1 (the traceback with the environment
    variable `DEBUG_ENV` set)."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            result = fn(*args, **kwargs)
            if files.stopped_by is not None:  # a library swallowed the signal's exception
                raise Terminated if files.stopped_by == signal.SIGTERM else KeyboardInterrupt
            return result
        except (ValueError, OSError) as exc:
            typer.echo(f"error: {error_line(exc)}", err=True)
            raise typer.Exit(2) from None
        except KeyboardInterrupt as exc:  # Terminated too, and a writer's check of stopped_by
            raise _stop(isinstance(exc, Terminated) or files.stopped_by == signal.SIGTERM) from None
        except (typer.Exit, typer.Abort):
            raise
        except Exception as exc:
            if files.stopped_by is not None:  # what a swallowed signal left half-imported
                raise _stop(files.stopped_by == signal.SIGTERM) from None
            if os.environ.get(DEBUG_ENV):
                raise
            first = str(exc).splitlines()[0] if str(exc) else ""
            typer.echo(
                f"error: internal error, a bug in scanplan ({type(exc).__name__}: {first}); "
                f"please report it, with the traceback that {DEBUG_ENV}=1 prints",
                err=True,
            )
            raise typer.Exit(1) from None

    return wrapper  # type: ignore[return-value]


def error_line(exc: Exception) -> str:
    """A user's mistake, or a file the system refused (a full disk), as one line: an OSError
    as its reason and file ("out.csv: Permission denied"), not Python's "[Errno 13] ..."."""
    text = str(exc)
    if isinstance(exc, OSError) and exc.strerror:
        text = exc.strerror if exc.filename is None else f"{exc.filename}: {exc.strerror}"
    return text.splitlines()[0] if text.strip() else type(exc).__name__


def _stop(terminated: bool) -> typer.Exit:
    """The one line of a stopped run, said once, and its exit."""
    global _said_stopped
    _said_stopped = True
    typer.echo("terminated" if terminated else "interrupted", err=True)
    return typer.Exit(143 if terminated else 130)


@contextmanager
def progress_bar(label: str, quiet: bool) -> Iterator[Callable[[int, int], None] | None]:
    """A transient rich progress bar on stderr, fed by the library's progress(done, total);
    None (no output at all) with --quiet or when stderr is not a terminal."""
    if quiet or not sys.stderr.isatty():
        yield None
        return
    # Deferred: rich loads only when a bar is drawn.
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    columns = (TextColumn(label), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    with Progress(*columns, console=Console(stderr=True), transient=True) as bar:
        task = bar.add_task(label, total=None)

        def update(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        yield update


@contextmanager
def removed_on_error(directory: Path, keep: Callable[[Path], bool]) -> Iterator[None]:
    """Remove `directory` (and the parents made for it) if the block fails and it did not
    exist before, unless keep(directory) says it holds something worth resuming from."""
    created = None
    for candidate in (directory, *directory.parents):
        if candidate.exists():
            break
        created = candidate
    try:
        yield
    except BaseException:
        if created is not None and created.exists() and not keep(directory):
            shutil.rmtree(created, ignore_errors=True)
        raise
