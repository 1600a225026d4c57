"""Checkpoint and resume of a DDPG, TD3 or SAC run, bit for bit.

A run checkpoints the whole training state every ``interval`` environment steps, at the start
of SB3's rollout (:meth:`~stable_baselines3.common.callbacks.BaseCallback.on_rollout_start`):
there the previous step's transition is stored and its gradient update done, so the state is
exactly the one between two iterations of SB3's ``learn`` loop. The checkpoint holds

* the SB3 model, pickled whole (networks, optimisers, replay buffer, the training environment
  with its state and generator, the action space's generator, SB3's counters and last
  observation);
* the exploration noise (SB3's ``learn`` resets it when it starts, so it is restored after);
* the global generators SB3 draws from (torch: SAC's actions and TD3's target noise; numpy:
  the replay buffer's minibatches; Python's ``random``);
* the state of every callback that can give it (:class:`CheckpointedState`): the learning
  curve, the best return, the model selection's candidate.

Resuming unpickles the model and calls ``learn`` for the remaining steps without resetting
SB3's counters; the resumed run then computes exactly what the uninterrupted run would have
(a test compares the two to the last bit). The file is written atomically (a crash while
writing keeps the previous checkpoint) and removed when the run completes.
"""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import cloudpickle
import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback

from leoc.io import set_aside, write_bytes_atomic

__all__ = [
    "CHECKPOINT_FILE",
    "CHECKPOINT_INTERVAL_STEPS",
    "CheckpointCallback",
    "CheckpointedState",
    "TrainingCheckpoint",
    "load_checkpoint",
]

CHECKPOINT_FILE = "checkpoint.pkl"
#: Environment steps between two checkpoints (about 5-10 s of training on one core; a
#: checkpoint of the paper's networks and a full replay buffer is about 10 MB).
CHECKPOINT_INTERVAL_STEPS = 1000
CHECKPOINT_FORMAT = 1


@runtime_checkable
class CheckpointedState(Protocol):
    """A callback whose state a checkpoint keeps: :meth:`checkpoint_state` returns a picklable
    object, :meth:`restore_checkpoint_state` takes it back before training resumes."""

    def checkpoint_state(self) -> Any: ...

    def restore_checkpoint_state(self, state: Any) -> None: ...


class TrainingCheckpoint(dict):
    """What :func:`load_checkpoint` returns: ``steps``, ``model``, ``noise``, ``rng``,
    ``callbacks`` (``(class name, state)`` of each :class:`CheckpointedState` callback)."""


def _global_rng_state() -> dict[str, Any]:
    return {
        "torch": torch.get_rng_state(),
        "numpy": np.random.get_state(),  # noqa: NPY002 (SB3 samples from the global one)
        "python": random.getstate(),
    }


def _restore_global_rng(state: dict[str, Any]) -> None:
    torch.set_rng_state(state["torch"])
    np.random.set_state(state["numpy"])  # noqa: NPY002
    random.setstate(state["python"])


class CheckpointCallback(BaseCallback):
    """Write the training state to ``path`` every ``interval`` steps; restore the noise and
    the generators of a resumed run when its training starts.

    Parameters
    ----------
    path : Path
        The checkpoint file.
    interval : int
        Environment steps between checkpoints (positive).
    callbacks : sequence of BaseCallback
        The run's other callbacks; those that are :class:`CheckpointedState` are saved with it.
    resumed : TrainingCheckpoint, optional
        The checkpoint this run resumes from: its noise and generators are restored when
        training starts (after SB3's ``learn`` reset the noise), its callbacks' states by
        :meth:`restore_callbacks` before training.
    """

    def __init__(
        self,
        path: Path,
        interval: int = CHECKPOINT_INTERVAL_STEPS,
        callbacks: tuple[BaseCallback, ...] = (),
        resumed: TrainingCheckpoint | None = None,
    ) -> None:
        if isinstance(interval, bool) or not isinstance(interval, int) or interval < 1:
            raise ValueError(f"checkpoint_interval: expected a positive int, found {interval!r}")
        super().__init__(verbose=0)
        self.path = Path(path)
        self.interval = interval
        self.callbacks = tuple(callbacks)
        self.resumed = resumed
        self._saved_steps = None if resumed is None else resumed["steps"]

    def restore_callbacks(self) -> None:
        """Give each callback its state from the resumed checkpoint (no-op for a fresh run)."""
        if self.resumed is None:
            return
        # by class, in order: a rerun may pass other callbacks than the interrupted run (one
        # that stopped it, say); a callback of a class the checkpoint has no state for starts
        # afresh
        saved = list(self.resumed["callbacks"])
        for callback in self.callbacks:
            if not isinstance(callback, CheckpointedState):
                continue
            name = type(callback).__qualname__
            match = next((entry for entry in saved if entry[0] == name), None)
            if match is not None:
                saved.remove(match)
                callback.restore_checkpoint_state(match[1])

    def _on_training_start(self) -> None:
        if self.resumed is not None:
            self.model.action_noise = self.resumed["noise"]
            _restore_global_rng(self.resumed["rng"])

    def _on_rollout_start(self) -> None:
        steps = int(self.num_timesteps)
        if steps > 0 and steps % self.interval == 0 and steps != self._saved_steps:
            self.save()

    def _on_step(self) -> bool:
        return True

    def save(self) -> None:
        """Write the checkpoint of the current step atomically."""
        steps = int(self.num_timesteps)
        state = {
            "format": CHECKPOINT_FORMAT,
            "steps": steps,
            "model": self.model,
            # a copy: SB3's learn resets the model's own noise object when a run resumes
            "noise": cloudpickle.loads(cloudpickle.dumps(self.model.action_noise)),
            "rng": _global_rng_state(),
            "callbacks": [
                (type(c).__qualname__, c.checkpoint_state())
                for c in self.callbacks
                if isinstance(c, CheckpointedState)
            ],
        }
        write_bytes_atomic(self.path, cloudpickle.dumps(state))
        self._saved_steps = steps


def load_checkpoint(path: Path, label: str = "ddpg") -> TrainingCheckpoint | None:
    """The checkpoint at ``path``, or None if there is none. A file that cannot be read (it is
    written atomically, so only a damaged disk or a hand edit makes one, or a leoc whose classes
    have moved since: a run interrupted before ``leoc.ddpg`` became :mod:`leoc.sb3`) is set aside
    with a printed line, and the run starts afresh, as PILCO's does."""
    path = Path(path)
    if not path.is_file():
        return None
    try:
        state = cloudpickle.loads(path.read_bytes())
        if state.get("format") != CHECKPOINT_FORMAT:
            raise ValueError(f"format {state.get('format')!r}, expected {CHECKPOINT_FORMAT}")
    except Exception as error:
        aside = set_aside(path)
        moved = isinstance(error, ImportError)  # a class of a module that has moved since
        what = "checkpoint of an older leoc" if moved else "damaged checkpoint"
        print(
            f"[{label}] {what} {path} ({type(error).__name__}: {error}); set aside "
            f"as {aside.name}, starting the run afresh",
            flush=True,
        )
        return None
    return TrainingCheckpoint(state)
