"""Command line: ``arshadow <command> ...``.

Each command lives in its own module of this package with ``register(subparsers)``; heavy imports
(OpenGL above all) happen inside the command that needs them, never at start-up.

Exit status (CONVENTIONS.md): 0 all inputs done, 1 some inputs failed (the rest were still processed and
reported), 2 bad usage or unreadable configuration. Errors are one line on stderr, no traceback unless
``--debug``.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import re
import signal
import sys
from collections.abc import Callable, Iterable
from types import FrameType
from typing import Any, NoReturn, TypeAlias

from .. import __version__
from ..errors import ArshadowError, BatchStoppedError, EstimateError, ImageError, MarkerNotFoundError

#: command modules, in the order ``--help`` lists them
COMMAND_MODULES = (
    "render",
    "demo",
    "video",
    "batch",
    "export_track",
    "pose",
    "calibrate",
    "marker",
    "silhouette",
    "sun",
    "bench",
    "info",
    "light",
    "preview",
    "map",
)

EXIT_OK, EXIT_SOME_FAILED, EXIT_USAGE = 0, 1, 2


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors (``PROG: error: MESSAGE (see PROG --help)``, exit 2) instead of
    the usage block; subcommand parsers inherit it."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="arshadow",
        description="Composite a virtual object and its exact hard shadow into photos of an ArUco marker.",
    )
    parser.add_argument("--version", action="version", version=f"arshadow {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks and debug logging")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        try:
            mod = importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:  # a command not built yet must not break the others
            if exc.name != f"{__name__}.{name}":
                raise
            continue
        mod.register(sub)
    return parser


#: a comma-separated list of numbers whose first is negative (``-0.05,0,0``): argparse takes it for an option
_NEGATIVE_LIST = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?(,[-+]?[\d.eE+-]*)+$")


def join_negative_values(argv: Iterable[str]) -> list[str]:
    """``--place -0.05,0,0`` -> ``--place=-0.05,0,0``: a long option followed by a number list that starts
    with a minus (argparse would read the list as an unknown option and say "expected one argument").

    >>> join_negative_values(["render", "--place", "-0.05,0,0", "--rotate", "-90,0,0", "-o", "out"])
    ['render', '--place=-0.05,0,0', '--rotate=-90,0,0', '-o', 'out']
    """
    out: list[str] = []
    for tok in argv:
        if out and _NEGATIVE_LIST.match(tok) and out[-1].startswith("--") and "=" not in out[-1]:
            out[-1] = f"{out[-1]}={tok}"
        else:
            out.append(tok)
    return out


def main(argv: Iterable[str] | None = None) -> int:
    try:
        code = _main(argv)
        sys.stdout.flush()  # here, not at exit: a closed pipe is caught below
        return code
    except BrokenPipeError:  # `arshadow info | head -1`: the reader left; not an error of ours, no traceback
        _stdout_to_devnull()
        return 128 + int(getattr(signal, "SIGPIPE", 13))


def _stdout_to_devnull() -> None:
    """Point stdout at /dev/null so that the interpreter's final flush does not fail again on the closed pipe."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # no real stdout (captured in tests)
        pass


def _main(argv: Iterable[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(join_negative_values(sys.argv[1:] if argv is None else list(argv)))
    logging.basicConfig(
        level=logging.DEBUG if args.debug else logging.WARNING,
        format="arshadow: %(levelname)s: %(message)s",
    )
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return EXIT_USAGE
    quiet_opencv(args.debug)
    previous = _terminate_as_interrupt()
    try:
        return int(args.func(args) or 0)
    except ArshadowError as exc:
        if args.debug:
            raise
        print(f"arshadow {args.command}: error: {exc}", file=sys.stderr)
        return (
            EXIT_SOME_FAILED
            if isinstance(exc, (ImageError, MarkerNotFoundError, EstimateError, BatchStoppedError))
            else EXIT_USAGE
        )
    except KeyboardInterrupt as exc:
        signum = exc.args[0] if exc.args and isinstance(exc.args[0], int) else signal.SIGINT
        print(
            f"arshadow: interrupted ({signal.Signals(signum).name}); the outputs being written were removed",
            file=sys.stderr,
        )
        return 128 + int(signum)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


#: what ``signal.signal`` gives back: the previous handler
_Handler: TypeAlias = Callable[[int, FrameType | None], Any] | int | signal.Handlers | None


def _terminate_as_interrupt() -> _Handler:
    """SIGTERM (``kill``, a job scheduler's stop) unwinds like Ctrl-C: the temporary files of the outputs
    being written are removed, finished ones kept (only possible in the main thread; else left as is)."""

    def handler(signum: int, frame: FrameType | None) -> NoReturn:
        raise KeyboardInterrupt(signum)

    try:
        return signal.signal(signal.SIGTERM, handler)  # the previous handler, restored when main() returns
    except ValueError:  # not the main thread (main() called from a worker thread)
        return None


def quiet_opencv(debug: bool = False) -> None:
    """Silence OpenCV's own stderr logging (decoder warnings) so each failure is one line of ours."""
    import cv2

    try:
        lg = cv2.utils.logging
        lg.setLogLevel(lg.LOG_LEVEL_INFO if debug else lg.LOG_LEVEL_SILENT)
    except AttributeError:  # pragma: no cover - builds without the logging utils
        pass


def error_line(command: str, what: str, exc: BaseException | str) -> str:
    """The one-line message for a failed input: ``arshadow CMD: error: WHAT: MESSAGE``."""
    return f"arshadow {command}: error: {what}: {exc}"


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
