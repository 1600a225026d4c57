"""The ``leoc`` command: LQR design, simulation, training, the paper's experiments and plots.

Run ``leoc --help`` or ``leoc COMMAND --help``. One module per command (``leoc.cli.lqr``,
``leoc.cli.simulate``, ...), each with ``add_parser(commands)`` and ``run(args)``; the parser is
built from light modules only, and each command imports torch, Stable-Baselines3, matplotlib or
Ray inside ``run``, so ``--help`` answers at once (``benchmarks/bench_cli_startup.py``).
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from collections.abc import Callable, Sequence

from leoc import __version__
from leoc.cli import (
    ablation,
    export,
    gym_study,
    headline,
    lqr,
    plot,
    publish,
    reproduce,
    roa,
    robustness,
    simulate,
    train,
)
from leoc.cli._args import OneLineParser

# Exit statuses of an interrupted command: 128 + the signal number, as a shell reports it.
EXIT_SIGINT = 128 + signal.SIGINT
EXIT_SIGTERM = 128 + signal.SIGTERM
EXIT_SIGPIPE = 128 + signal.SIGPIPE
COMMANDS = (
    lqr,
    simulate,
    roa,
    robustness,
    train,
    export,
    reproduce,
    ablation,
    gym_study,
    plot,
    publish,
    headline,
)
RESUMABLE_COMMANDS = ("reproduce", "ablation", "gym-study", "train")


def build_parser() -> argparse.ArgumentParser:
    """The ``leoc`` parser with every command's subparser."""
    parser = OneLineParser(
        prog="leoc",
        description="LEOC hybrid controllers: LQR near the operating point, a learned policy "
        "elsewhere (Zhang & Capel, L4DC 2021).",
    )
    parser.add_argument("--version", action="version", version=f"leoc {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        command.add_parser(commands)
    return parser


class Terminated(Exception):
    """Raised in the main process by SIGTERM, so it stops as cleanly as on Ctrl-C."""


def _raise_terminated(signum: int, frame: object) -> None:
    raise Terminated()


def _interrupted(args: argparse.Namespace, code: int) -> int:
    """Print one line on stderr (with how to resume, for a resumable command)."""
    if args.command in RESUMABLE_COMMANDS:
        print(
            f"leoc {args.command}: interrupted; finished runs and checkpoints are kept, run the "
            "same command again to resume from the last checkpoint",
            file=sys.stderr,
        )
    else:
        print(f"leoc {args.command}: interrupted", file=sys.stderr)
    return code


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``leoc`` command; returns its exit status (2 for bad input). A reader that
    closes the pipe early (``leoc ... | head``) ends it quietly with the status of a process
    killed by SIGPIPE, as a shell reports it."""
    return quiet_on_broken_pipe(lambda: _run(argv))


def quiet_on_broken_pipe(run: Callable[[], int | None]) -> int:
    """``run()``'s status (0 for None), or :data:`EXIT_SIGPIPE` without a traceback when the
    reader of stdout closed it early (``... | head``); the benchmark scripts run through it
    too."""
    try:
        status = run()
        sys.stdout.flush()
    except BrokenPipeError:
        # Point stdout at /dev/null so that the interpreter's final flush does not raise again.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
        return EXIT_SIGPIPE
    return int(status or 0)


def _run(argv: Sequence[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        return int(args.run(args))
    except (ValueError, FileNotFoundError) as error:
        print(f"leoc {args.command}: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return _interrupted(args, EXIT_SIGINT)
    except Terminated:
        return _interrupted(args, EXIT_SIGTERM)
    finally:
        signal.signal(signal.SIGTERM, previous)


__all__ = [
    "EXIT_SIGINT",
    "EXIT_SIGPIPE",
    "EXIT_SIGTERM",
    "build_parser",
    "main",
    "quiet_on_broken_pipe",
]
