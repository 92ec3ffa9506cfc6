"""The `scanplan` console script and `python -m scanplan`: Ctrl-C or SIGTERM while the
command's modules load (the first second or two) ends as it does later, in one line and exit
130 or 143, not a traceback (`cli.common` takes over once the app runs). Only the
interpreter's own start (its site module, some 50 ms) comes before this module.
"""

from __future__ import annotations

import signal
import sys

# Nothing else imported here: the sooner main() runs, the shorter the uncovered start.
_received: list[int] = []


def _record(signum: int, frame: object) -> None:
    # Recorded, not raised: a library imported now may swallow any exception in a bare
    # `except` around an optional import (trimesh does), and then go on as if not asked.
    _received.append(signum)


def main() -> None:
    previous = {sig: signal.signal(sig, _record) for sig in (signal.SIGINT, signal.SIGTERM)}
    from scanplan.cli import app

    for sig, handler in previous.items():
        signal.signal(sig, handler)
    if _received:
        stopped = _received[0] == signal.SIGTERM
        sys.stderr.write("terminated\n" if stopped else "interrupted\n")
        sys.exit(143 if stopped else 130)
    app()


if __name__ == "__main__":
    main()
