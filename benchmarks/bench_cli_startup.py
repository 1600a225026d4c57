"""Start-up time of the ``leoc`` command: ``leoc --help``, every ``leoc COMMAND --help`` and
``leoc --version``, each in a fresh interpreter, as a user's shell starts it.

Each command line runs ``--repeats`` times (``python -m leoc ARGS``, output discarded); the table
prints the median and the slowest wall time, and whether the median is under the target
(0.5 s: the parser imports no torch, Stable-Baselines3, matplotlib or Ray). With ``--imports``
it also prints the modules costing the most at ``leoc --help`` (``python -X importtime``).

Usage::

    python benchmarks/bench_cli_startup.py [--repeats 5] [--target 0.5] [--imports]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time

COMMAND_LINES = (
    ("--help",),
    ("--version",),
    *(
        (name, "--help")
        for name in ("lqr", "simulate", "roa", "train", "export", "reproduce", "plot")
    ),
    ("publish", "--help"),
)
TARGET_S = 0.5
TOP_IMPORTS = 8


def time_command(args: tuple[str, ...], repeats: int) -> list[float]:
    """Wall seconds of ``python -m leoc ARGS`` in a fresh interpreter, ``repeats`` times."""
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        subprocess.run([sys.executable, "-m", "leoc", *args], check=True, stdout=subprocess.DEVNULL)
        times.append(time.perf_counter() - started)
    return times


def slowest_imports(count: int) -> list[tuple[float, str]]:
    """The ``count`` largest cumulative import times (s) at ``leoc --help``."""
    result = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "leoc", "--help"],
        capture_output=True,
        text=True,
        check=True,
    )
    rows = []
    for line in result.stderr.splitlines():
        if not line.startswith("import time:") or "cumulative" in line:
            continue
        _, cumulative, name = line.split("|")
        rows.append((int(cumulative) / 1e6, name.strip()))
    return sorted(rows, reverse=True)[:count]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--target", type=float, default=TARGET_S)
    parser.add_argument("--imports", action="store_true", help="also list the slowest imports")
    args = parser.parse_args()
    print(f"{'command':<24} {'median [s]':>10} {'max [s]':>8}  under {args.target:g} s")
    for command in COMMAND_LINES:
        times = time_command(command, args.repeats)
        median = statistics.median(times)
        text = "leoc " + " ".join(command)
        verdict = "yes" if median < args.target else "NO"
        print(f"{text:<24} {median:10.3f} {max(times):8.3f}  {verdict}")
    if args.imports:
        print("\nslowest imports at `leoc --help` (cumulative):")
        for seconds, name in slowest_imports(TOP_IMPORTS):
            print(f"  {seconds:6.3f} s  {name}")


if __name__ == "__main__":
    from leoc.cli import quiet_on_broken_pipe

    raise SystemExit(quiet_on_broken_pipe(main))
