"""Animations of a controller: its swing-up and its impulse response, frame by frame.

An animation is two clips run on the one closed-loop simulation (:mod:`leoc.systems.rollout`):

* **swing-up**: one episode from the system's swing-up start (drawn with a seeded generator,
  :meth:`~leoc.systems.base.System.sample_start`);
* **impulse response**: the impulse test of :func:`~leoc.evaluation.rollout.response_test`,
  from the operating point.

Each frame draws the state (:mod:`leoc.systems.rendering`) with a caption (controller, clip,
time) and, for a hybrid controller, its relevance r(x) at the last decision as a bar (the
``relevance`` the rollout records; a controller without one shows no bar). Frames are drawn
every :func:`~leoc.systems.rendering.frame_stride` simulator steps, so an animation plays in
real time at no more than 25 frames per second.

Writers: ``.gif`` with Pillow (a matplotlib dependency); ``.mp4`` by piping the frames to the
``ffmpeg`` program (H.264), refused in one line where ``ffmpeg`` is not on the PATH.
:func:`write_report_animations` writes ``animations/SYSTEM.gif`` of one hybrid run per system
of a ``leoc reproduce`` folder.
"""

from __future__ import annotations

import math
import shutil
import subprocess
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np

from leoc.evaluation.rollout import Controller, Trajectory, response_test, rollout
from leoc.systems.base import System
from leoc.systems.rendering import Gauge, Renderer, frame_stride

#: Animation formats (file suffixes) and what writes them.
VIDEO_SUFFIXES = (".gif", ".mp4")
#: Seed of the swing-up start of an animation.
SWING_UP_SEED = 0
#: Folder of the report's animations, inside a ``leoc reproduce`` folder.
# ffmpeg: H.264 in yuv420p (what browsers play), each side padded to an even size.
EVEN_PAD = "pad=ceil(iw/2)*2:ceil(ih/2)*2"
FFMPEG_OUTPUT = ("-vf", EVEN_PAD, "-vcodec", "libx264", "-pix_fmt", "yuv420p")
MS_PER_SECOND = 1000.0


class Clip(NamedTuple):
    """One episode of an animation: its title and trajectory."""

    title: str
    trajectory: Trajectory


def check_video_path(path: str | Path) -> Path:
    """``path`` as a :class:`Path` if its suffix is a known format (and, for ``.mp4``, ffmpeg
    is on the PATH).

    Raises
    ------
    ValueError
        One line naming the suffix found, or the missing ``ffmpeg``.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in VIDEO_SUFFIXES:
        raise ValueError(
            f"--video: expected a file ending in {' or '.join(VIDEO_SUFFIXES)}, found {str(path)!r}"
        )
    if suffix == ".mp4" and shutil.which("ffmpeg") is None:
        raise ValueError(
            f"--video: writing {str(path)!r} needs the ffmpeg program, which is not on the PATH; "
            "install ffmpeg or write a .gif"
        )
    return path


def episode_clips(
    system: System, controller: Controller, steps: int | None = None, seed: int = SWING_UP_SEED
) -> list[Clip]:
    """The swing-up (from a start drawn with ``seed``) and the impulse response of
    ``controller``, ``steps`` simulator steps each (default ``system.episode_steps``; fewer if
    an episode terminates)."""
    steps = system.episode_steps if steps is None else steps
    start = system.sample_start(np.random.default_rng(seed), "swing_up")
    return [
        Clip("swing-up", rollout(system, controller, start, steps)),
        Clip("impulse response", response_test(system, controller, "impulse", steps).trajectory),
    ]


def clip_frames(
    system: System,
    clips: Sequence[Clip],
    label: str | None = None,
    stride: int | None = None,
) -> Iterator[np.ndarray]:
    """The ``(H, W, 3)`` uint8 frames of ``clips``: states ``0, stride, 2 stride, ...`` of each
    (default :func:`~leoc.systems.rendering.frame_stride`), captioned with ``label``, the clip's
    title and the time, with r(x) as a bar where the trajectory records it."""
    stride = frame_stride(system) if stride is None else stride
    renderer = Renderer(system, "rgb_array")
    try:
        for clip in clips:
            trajectory = clip.trajectory
            for index in range(0, trajectory.states.shape[0], stride):
                caption = f"{clip.title}   t = {index * system.dt:5.2f} s"
                if label:
                    caption = f"{label}\n{caption}"
                frame = renderer.frame(trajectory.states[index], caption, _gauge(trajectory, index))
                assert frame is not None  # rgb_array mode
                yield frame
    finally:
        renderer.close()


def _gauge(trajectory: Trajectory, index: int) -> Gauge | None:
    """r(x) of the decision that acts on state ``index`` (the last one for the final state)."""
    if trajectory.relevance is None or trajectory.relevance.shape[0] == 0:
        return None
    value = float(trajectory.relevance[min(index, trajectory.relevance.shape[0] - 1)])
    return Gauge(f"r(x) = {value:.2f}", value)


def frame_count(clips: Sequence[Clip], stride: int) -> int:
    """Frames :func:`clip_frames` draws: ``ceil((T + 1) / stride)`` per clip of ``T`` steps."""
    return sum(math.ceil(clip.trajectory.states.shape[0] / stride) for clip in clips)


def write_frames(frames: Iterator[np.ndarray], path: str | Path, fps: float) -> Path:
    """Write ``frames`` to ``path`` (``.gif`` or ``.mp4``, :func:`check_video_path`) at ``fps``
    frames per second; returns the path."""
    path = check_video_path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".mp4":
        return _write_mp4(frames, path, fps)
    from PIL import Image

    images = (Image.fromarray(frame) for frame in frames)
    first = next(images)
    first.save(
        path,
        save_all=True,
        append_images=images,
        duration=round(MS_PER_SECOND / fps),
        loop=0,
    )
    return path


def _write_mp4(frames: Iterator[np.ndarray], path: Path, fps: float) -> Path:
    first = next(frames)
    height, width = first.shape[:2]
    command = [
        "ffmpeg", "-y", "-loglevel", "error",
        "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{width}x{height}", "-r", f"{fps:g}",
        "-i", "-", *FFMPEG_OUTPUT, str(path),
    ]  # fmt: skip
    with subprocess.Popen(command, stdin=subprocess.PIPE, stderr=subprocess.PIPE) as process:
        assert process.stdin is not None
        for frame in (first, *frames):
            process.stdin.write(np.ascontiguousarray(frame).tobytes())
        process.stdin.close()
        error = process.stderr.read().decode(errors="replace") if process.stderr else ""
    if process.returncode != 0:
        raise ValueError(f"--video: ffmpeg could not write {str(path)!r}: {error.strip()}")
    return path


def write_video(
    system: System,
    controller: Controller,
    path: str | Path,
    steps: int | None = None,
    label: str | None = None,
    seed: int = SWING_UP_SEED,
) -> Path:
    """Animate ``controller`` on ``system``: its swing-up then its impulse response
    (:func:`episode_clips`), written to ``path`` (``.gif``, or ``.mp4`` with ffmpeg) in real
    time; returns the path.

    Raises
    ------
    ValueError
        Before simulating anything, if the format cannot be written or the system cannot be
        drawn (:func:`~leoc.systems.rendering.drawer_for`).
    """
    from leoc.systems.rendering import drawer_for

    path = check_video_path(path)
    drawer_for(system)
    clips = episode_clips(system, controller, steps, seed)
    stride = frame_stride(system)
    return write_frames(clip_frames(system, clips, label, stride), path, 1.0 / (stride * system.dt))
