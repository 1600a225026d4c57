"""``leoc export``: write a controller's whole decision as ONNX or TorchScript, checked."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from leoc.cli._args import SYSTEM_HELP, positive_int, system_or_run_dir
from leoc.names import LQR_METHODS, VARIANT_NAMES

#: What ``--format`` accepts (``leoc.deploy.EXPORT_FORMATS``, without importing torch).
FORMATS = ("onnx", "torchscript")
#: Observations the export is checked on by default (``leoc.deploy.export.CHECK_COUNT``).
DEFAULT_CHECK_COUNT = 100_000


def add_parser(commands: Any) -> None:
    """Add the ``export`` command to the subparsers ``commands``."""
    export = commands.add_parser(
        "export",
        help="export a controller as ONNX or TorchScript (observation in, saturated action out)",
        description="Write the whole decision of a trained controller (learned part, "
        "relevance, linear part, blend, squash and the actuator's limits) as one float64 "
        "model, with its control period, observation and action layouts, units, limits, LQR "
        "design and certificate in a JSON file beside it (MODEL.json). The exported model is "
        "checked against torch on observations of the operating region and of the swing-up "
        "region before it is written: |a - b| <= 1e-6 max(1, |b|).",
    )
    export.add_argument(
        "target",
        type=system_or_run_dir,
        metavar="RUN_DIR|SYSTEM",
        help=f"a run folder of 'leoc train' or 'leoc reproduce'; or {SYSTEM_HELP} (its LQR)",
    )
    export.add_argument("--format", choices=FORMATS, default="onnx", help="default onnx")
    export.add_argument(
        "--out",
        type=Path,
        help="model file (default RUN_DIR/controller.onnx or controller.torchscript.pt; "
        "SYSTEM_lqr.onnx for a system's LQR)",
    )
    export.add_argument(
        "--overwrite", action="store_true", help="replace an existing model and metadata"
    )
    export.add_argument(
        "--check-count",
        type=positive_int,
        default=DEFAULT_CHECK_COUNT,
        help="observations the export is checked on (default 100000)",
    )
    export.add_argument("--seed", type=int, default=0, help="seed of the check (default 0)")
    export.add_argument(
        "--method", choices=LQR_METHODS, help="a system's LQR only: its design method"
    )
    export.add_argument(
        "--action-repeat",
        type=positive_int,
        default=1,
        help="a system's LQR only: its control period in simulator steps (default 1)",
    )
    export.add_argument(
        "--variant",
        choices=VARIANT_NAMES,
        help="a system's LQR only: leoc's (default) or the authors' (their LQR and sin squash)",
    )
    export.set_defaults(run=run)


def _default_out(target: str | Path, fmt: str) -> Path:
    """``RUN_DIR/controller.onnx`` (or ``.torchscript.pt``); ``SYSTEM_lqr.onnx`` here."""
    suffix = ".onnx" if fmt == "onnx" else ".torchscript.pt"
    if isinstance(target, Path):
        return target / f"controller{suffix}"
    return Path(f"{target}_lqr{suffix}")


def run(args: argparse.Namespace) -> int:
    from leoc.deploy import export_controller, load

    if isinstance(args.target, Path):
        if args.method is not None or args.action_repeat != 1 or args.variant is not None:
            raise ValueError(
                "--method, --action-repeat, --variant: expected them only with SYSTEM (its LQR "
                f"alone), found them with the run folder {str(args.target)!r} (its LQR is its "
                "own)"
            )
        controller = load(args.target)
    else:
        variant = args.variant or "leoc"
        controller = load(args.target, args.method, args.action_repeat, variant)
    out = args.out if args.out is not None else _default_out(args.target, args.format)
    try:
        result = export_controller(
            controller, out, args.format, args.overwrite, args.check_count, args.seed
        )
    except ImportError as error:
        print(f"leoc export: error: {error}", file=sys.stderr)
        return 1
    runtime = "ONNX Runtime" if args.format == "onnx" else "TorchScript"
    print(f"{controller!r}")
    print(result.check.describe(runtime))
    print(f"model written to {result.model}")
    print(f"metadata written to {result.metadata}")
    return 0
