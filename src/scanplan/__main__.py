"""The `scanplan` console script and `python -m scanplan`: Ctrl-C or SIGTERM while the
command's modules load (the first second) ends as it does later, in one line and exit 130
or 143, not a traceback (`cli.common` takes over once the app runs). Only the interpreter's
own start (its site module, some 50 ms) comes before this module and is not covered.
"""

from __future__ import annotations

import signal
import sys

# Nothing else imported here: the sooner main() runs, the shorter the uncovered start.


class _Terminated(KeyboardInterrupt):
    pass


def _terminated(signum: int, frame: object) -> None:
    raise _Terminated


def main() -> None:
    if signal.getsignal(signal.SIGTERM) is signal.SIG_DFL:
        signal.signal(signal.SIGTERM, _terminated)
    try:
        from scanplan.cli import app
    except KeyboardInterrupt as exc:
        stopped = isinstance(exc, _Terminated)
        sys.stderr.write("terminated\n" if stopped else "interrupted\n")
        sys.exit(143 if stopped else 130)
    app()


if __name__ == "__main__":
    main()
