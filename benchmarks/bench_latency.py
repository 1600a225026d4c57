"""Latency of one decision: the LQR, each hybrid kind and each baseline, in torch, TorchScript
and ONNX Runtime, batch 1, one thread.

Each controller is a tiny run of each ``--systems`` (default: the pendulum) with the paper's
architecture (latency does not
depend on training, only on the architecture): DDPG, TD3 and SAC trained for 300 steps with
their default settings (actor MLP 400 x 300: before any gradient step), PILCO for one iteration
of the smoke profile (``--profile smoke``: an RBF policy of 5 basis functions; the paper's has
30, a difference of a few hundred flops); trained once into ``--runs`` (kept, so a rerun reuses
them); plus ``leoc.load("pendulum")``'s LQR. For each, one float64
observation ``(1, 3)`` is decided ``--calls`` times after a warm-up, each call timed on its own
(``time.perf_counter_ns``), in:

- ``torch``: the loaded decision module (``leoc.load(RUN).module``) under ``torch.no_grad``;
- ``act``: ``leoc.load(RUN).act`` on a numpy observation (what a gymnasium loop calls: torch plus
  the conversions and input checks);
- ``TorchScript``: the exported TorchScript model (``torch.jit.load``);
- ``ONNX Runtime``: the exported ONNX model, ``SessionOptions`` with one intra- and one
  inter-op thread, ``session.run`` on a numpy array.

torch runs on one thread (``torch.set_num_threads(1)``). The table prints the median and the
99th percentile in microseconds, and whether each exported model's p99 is under the target
(100 us: a 1 kHz loop with room to spare).

Usage::

    python benchmarks/bench_latency.py [--calls 10000] [--runs runs/bench-latency]
        [--systems pendulum cartpole mountaincar]
"""

from __future__ import annotations

import argparse
import io
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

#: The runs timed on each system: each baseline and each hybrid kind (``leoc train`` arguments).
_PILCO = ["--algo", "pilco", "--profile", "smoke"]
_SB3_STEPS = ["--steps", "300"]
CONTROLLERS = {
    "pilco baseline": _PILCO,
    "ddpg baseline": ["--algo", "ddpg", *_SB3_STEPS],
    "td3 baseline": ["--algo", "td3", *_SB3_STEPS],
    "sac baseline": ["--algo", "sac", *_SB3_STEPS],
    "pilco hybrid (paper)": [*_PILCO, "--hybrid"],
    "ddpg hybrid (paper)": ["--algo", "ddpg", "--hybrid", *_SB3_STEPS],
    "ddpg hybrid (paper, r_min 0.5)": ["--algo", "ddpg", "--hybrid", "--r-min", "0.5", *_SB3_STEPS],
    "td3 hybrid (roa)": ["--algo", "td3", "--hybrid", "--relevance", "roa", *_SB3_STEPS],
    "sac hybrid (lyapunov)": ["--algo", "sac", "--hybrid", "--relevance", "lyapunov", *_SB3_STEPS],
}
LQR = "LQR alone"
TARGET_US = 100.0
WARMUP_CALLS = 1000
PERCENTILE = 99
RUNTIMES = ("torch", "act", "TorchScript", "ONNX Runtime")


def trained_runs(folder: Path, system: str = "pendulum") -> dict[str, Path]:
    """Every controller's run folder of ``system`` under ``folder`` (the pendulum's directly
    there, as before the option), trained (smoke profile) if missing."""
    from leoc.cli import main

    runs = {}
    base = folder if system == "pendulum" else folder / system
    for label, arguments in CONTROLLERS.items():
        out = base / label.replace(" ", "_").replace("(", "").replace(")", "").replace(",", "")
        if not (out / "config.json").is_file():
            print(f"training {label} into {out}", flush=True)
            command = ["train", system, *arguments, "--quiet"]
            if main([*command, "--out", str(out), "--overwrite"]) != 0:
                raise SystemExit(f"training {label} failed")
        runs[label] = out
    return runs


def time_calls(decide: Callable[[], object], calls: int) -> tuple[float, float]:
    """Median and 99th percentile (microseconds) of ``calls`` timed calls of ``decide``."""
    for _ in range(WARMUP_CALLS):
        decide()
    clock = time.perf_counter_ns
    times = np.empty(calls)
    for index in range(calls):
        started = clock()
        decide()
        times[index] = clock() - started
    return float(np.median(times)) / 1e3, float(np.percentile(times, PERCENTILE)) / 1e3


def deciders(controller) -> dict[str, Callable[[], object]]:
    """One no-argument call per runtime, each deciding the operating observation."""
    import onnxruntime
    import torch

    from leoc.deploy.export import model_bytes

    obs = np.asarray(controller.system.operating_obs, dtype=np.float64)[None]
    tensor = torch.as_tensor(obs)
    scripted = torch.jit.load(io.BytesIO(model_bytes(controller, "torchscript")))
    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    session = onnxruntime.InferenceSession(
        model_bytes(controller, "onnx"), options, providers=["CPUExecutionProvider"]
    )
    module = controller.module

    def run_torch() -> object:
        with torch.no_grad():
            return module(tensor)

    def run_scripted() -> object:
        with torch.no_grad():
            return scripted(tensor)

    return {
        "torch": run_torch,
        "act": lambda: controller.act(obs[0]),
        "TorchScript": run_scripted,
        "ONNX Runtime": lambda: session.run(["action"], {"observation": obs}),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--calls", type=int, default=10_000, help="timed calls per cell")
    parser.add_argument(
        "--runs", type=Path, default=Path("runs/bench-latency"), help="smoke runs (kept)"
    )
    parser.add_argument(
        "--systems", nargs="+", default=["pendulum"], help="systems timed (default: pendulum)"
    )
    args = parser.parse_args()
    import torch

    torch.set_num_threads(1)
    for system in args.systems:
        time_system(system, args.runs, args.calls)


def time_system(system: str, folder: Path, calls: int) -> None:
    """Print the latency table of ``system``'s controllers."""
    import leoc

    runs = trained_runs(folder, system)
    controllers = {LQR: leoc.load(system)} | {k: leoc.load(v) for k, v in runs.items()}
    title = f"{system}: latency of one decision, batch 1, one thread, {calls} calls"
    print(f"\n{title} (median / p99, us)")
    header = " | ".join(f"{name:>15}" for name in RUNTIMES)
    print(f"{'controller':<31}| {header} | exported p99 < {TARGET_US:g} us")
    for label, controller in controllers.items():
        cells, exported = [], []
        for runtime, decide in deciders(controller).items():
            median, p99 = time_calls(decide, calls)
            cells.append(f"{median:6.1f} / {p99:6.1f}")
            if runtime in ("TorchScript", "ONNX Runtime"):
                exported.append(p99)
        verdict = "yes" if max(exported) < TARGET_US else "NO"
        print(f"{label:<31}| {' | '.join(f'{c:>15}' for c in cells)} | {verdict}", flush=True)


if __name__ == "__main__":
    from leoc.cli import quiet_on_broken_pipe

    raise SystemExit(quiet_on_broken_pipe(main))
