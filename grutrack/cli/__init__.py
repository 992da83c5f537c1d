"""The ``grutrack`` command line. Each sub-command lives in its own module of this package with
``add_parser(subparsers)`` (registers the sub-command and sets ``func``) and is listed in COMMANDS."""

from __future__ import annotations

import argparse
import functools
import importlib
import os
import sys

from grutrack import __version__
from grutrack.errors import GrutrackError

#: sub-command modules, in the order ``grutrack --help`` lists them
COMMANDS: tuple[str, ...] = (
    "grutrack.cli.track",
    "grutrack.cli.evaluate",
    "grutrack.cli.train",
    "grutrack.cli.demo",
    "grutrack.cli.detections",
    "grutrack.cli.resolve",
    "grutrack.cli.submit",
    "grutrack.cli.report",
    "grutrack.cli.render",
    "grutrack.cli.check",
    "grutrack.cli.compare",
)


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line naming the command and the flag, exit status 2 (argparse's
    own prints its usage block first)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser with every sub-command registered."""
    # allow_abbrev=False: a misspelt flag that happens to be a prefix of another (--detection) is refused, not
    # silently taken for it
    parser = _Parser(
        prog="grutrack",
        allow_abbrev=False,
        description="3D multi-object tracking with a semi-supervised GRU-Kalman filter: "
        "tracking, official submissions and evaluation for nuScenes and Argoverse 2.",
    )
    parser.add_argument("--version", action="version", version=f"grutrack {__version__}")
    sub = parser.add_subparsers(
        dest="command", metavar="COMMAND", required=True, parser_class=functools.partial(_Parser, allow_abbrev=False)
    )
    for name in COMMANDS:
        importlib.import_module(name).add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``grutrack`` console script; returns the exit status."""
    args = build_parser().parse_args(argv)
    try:
        status = int(args.func(args) or 0)
        sys.stdout.flush()  # a closed stdout shows here, not at interpreter exit
        return status
    except BrokenPipeError:
        # the reader of stdout went away (e.g. `| head -1`); outputs are already written (atomically): say no more
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # 128 + SIGPIPE, what a shell reports for a command killed by it
    except GrutrackError as exc:
        print(f"grutrack {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"grutrack {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
