"""Rendering: every env's render modes, what the frames show, animations, envs without import.

The drawings are checked against the systems' angle conventions by where their colours land
in the frame (the rod of an upright pendulum above its pivot, theta = pi/2 to the pivot's left
as theta is anticlockwise), not against frames the code drew earlier.
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import matplotlib
import numpy as np
import pytest
import torch
from PIL import Image

from leoc.cli import main
from leoc.evaluation import video
from leoc.experiments import animations
from leoc.names import BUILTIN_ENV_IDS
from leoc.systems import LeocEnv, make_system
from leoc.systems import rendering as rd

matplotlib.use("Agg")  # "human" mode must neither open a window nor wait

EXAMPLE = Path(__file__).resolve().parents[1] / "docs" / "examples" / "damped_cart.py"
ENV_IDS = {name: env_id for name, (env_id, _) in BUILTIN_ENV_IDS.items()}
MODES = (None, "rgb_array", "human")
# A pixel "has" a colour within this distance per channel (antialiased edges blend).
COLOUR_TOLERANCE = 12
TINY_STEPS = 5
# Pixels blended between the gauge's bar and its background.
GAUGE_GAP = 3


def _rgb(colour: str) -> np.ndarray:
    return np.array([int(colour[i : i + 2], 16) for i in (1, 3, 5)])


def _mask(frame: np.ndarray, colour: str) -> np.ndarray:
    """(H, W) bool: pixels of ``colour``."""
    return np.all(np.abs(frame.astype(int) - _rgb(colour)) <= COLOUR_TOLERANCE, axis=-1)


def _centroid(mask: np.ndarray) -> np.ndarray:
    """(row, column) mean of the set pixels (rows grow downwards)."""
    rows, columns = np.nonzero(mask)
    assert rows.size > 0, "the colour is not in the frame"
    return np.array([rows.mean(), columns.mean()])


def _frame(name: str, state) -> np.ndarray:
    return rd.Renderer(make_system(name)).frame(np.asarray(state, dtype=float))


def _load_example():
    spec = importlib.util.spec_from_file_location("damped_cart_rendering", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while being defined
    spec.loader.exec_module(module)
    return module


# --------------------------------------------------------------------------- render modes
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("name", list(ENV_IDS))
def test_every_env_accepts_every_render_mode(name, mode) -> None:
    env = gym.make(ENV_IDS[name], render_mode=mode)
    try:
        assert env.metadata["render_modes"] == ["human", "rgb_array"]
        assert env.metadata["render_fps"] == pytest.approx(1.0 / make_system(name).dt)
        env.reset(seed=0)
        env.step(env.action_space.sample())
        if mode is None:
            with pytest.warns(UserWarning, match="without a render_mode"):
                assert env.render() is None
            return
        frame = env.render()
        if mode == "human":
            assert frame is None
            return
        width, height = rd.frame_size(make_system(name))
        assert frame.shape == (height, width, 3) and frame.dtype == np.uint8
    finally:
        env.close()


def test_human_mode_draws_in_reset_and_step_and_close_releases_the_figure(monkeypatch) -> None:
    import matplotlib.pyplot as plt

    drawn = []
    frame = rd.Renderer.frame
    monkeypatch.setattr(rd.Renderer, "frame", lambda self, state: drawn.append(state.copy()))
    env = gym.make(ENV_IDS["pendulum"], render_mode="human")
    env.reset(seed=0)
    renderer = env.unwrapped._renderer
    assert renderer is not None and renderer.mode == "human"
    for _ in range(2):
        env.step(env.action_space.sample())
    # one frame of each state, as gymnasium's human mode: the start and each step's
    assert len(drawn) == 3
    np.testing.assert_array_equal(drawn[-1], env.unwrapped.state)
    monkeypatch.setattr(rd.Renderer, "frame", frame)
    assert env.render() is None  # human mode draws and returns nothing
    assert plt.fignum_exists(renderer.figure.number)
    number = renderer.figure.number
    env.close()
    assert not plt.fignum_exists(number)


@pytest.mark.parametrize("name", list(ENV_IDS))
def test_gymnasiums_env_checker_passes_with_rgb_array(name) -> None:
    from gymnasium.utils.env_checker import check_env

    env = gym.make(ENV_IDS[name], render_mode="rgb_array").unwrapped
    with warnings.catch_warnings():
        # the checker's advice on the spaces' ranges is not about rendering
        warnings.simplefilter("ignore")
        warnings.filterwarnings("error", message=".*render", category=UserWarning)
        check_env(env, skip_render_check=False)


@pytest.mark.parametrize("mode", ["rgb", "RGB_ARRAY", "ansi"])
def test_an_invalid_render_mode_is_refused_in_one_line(mode) -> None:
    with pytest.raises(ValueError, match=r"render_mode: expected None or one of") as error:
        LeocEnv(system="pendulum", render_mode=mode)
    assert "\n" not in str(error.value) and repr(mode) in str(error.value)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # gymnasium warns first, then the env refuses
        with pytest.raises(ValueError, match="render_mode"):
            gym.make(ENV_IDS["cartpole"], render_mode=mode)


def test_render_before_reset_is_refused() -> None:
    env = LeocEnv(system="pendulum", render_mode="rgb_array")
    with pytest.raises(RuntimeError, match="before reset"):
        env.render()


@pytest.mark.parametrize("name", list(ENV_IDS))
def test_make_vec_env_emits_no_render_warning(name) -> None:
    from stable_baselines3.common.env_util import make_vec_env

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        vec_env = make_vec_env(ENV_IDS[name], n_envs=1)
        vec_env.reset()
        frame = vec_env.render()  # SB3 asks for rgb_array by default
        vec_env.close()
    assert not [w for w in caught if "render" in str(w.message).lower()]
    assert frame is not None and frame.ndim == 3


# --------------------------------------------------------------------------- what frames show
@pytest.mark.parametrize(
    ("name", "state", "moved"),
    [
        ("pendulum", [0.0, 0.0], [0.3, 0.0]),
        ("cartpole", [0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.3, 0.0]),
        ("cartpole", [0.0, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]),
        ("mountaincar", [-np.pi, 0.0], [-2.0, 0.0]),
        ("acrobot", [0.0, 0.0, 0.0, 0.0], [0.0, 0.3, 0.0, 0.0]),
    ],
)
def test_a_frame_changes_with_the_state_and_only_with_it(name, state, moved) -> None:
    first, again, other = _frame(name, state), _frame(name, state), _frame(name, moved)
    np.testing.assert_array_equal(first, again)
    assert np.count_nonzero(np.any(first != other, axis=-1)) > 100


def test_the_upright_pendulum_is_drawn_above_its_pivot_and_the_hanging_one_below() -> None:
    upright, hanging = _frame("pendulum", [0.0, 0.0]), _frame("pendulum", [np.pi, 0.0])
    pivot = _centroid(_mask(upright, rd.JOINT_COLOUR))
    np.testing.assert_allclose(pivot, _centroid(_mask(hanging, rd.JOINT_COLOUR)), atol=1.0)
    rows = np.arange(upright.shape[0])[:, None]
    for frame, above_expected in ((upright, True), (hanging, False)):
        rod = _mask(frame, rd.LINK_COLOUR)
        above = np.count_nonzero(rod & (rows < pivot[0]))
        below = np.count_nonzero(rod & (rows > pivot[0]))
        assert (above > 20 * below) if above_expected else (below > 20 * above)


@pytest.mark.parametrize(
    ("name", "state", "pivot_colour", "side"),
    [
        # theta anticlockwise from upright: +pi/2 points to -x (left)
        ("pendulum", [np.pi / 2, 0.0], rd.JOINT_COLOUR, -1),
        ("pendulum", [-np.pi / 2, 0.0], rd.JOINT_COLOUR, 1),
        ("acrobot", [np.pi / 2, 0.0, 0.0, 0.0], rd.JOINT_COLOUR, -1),
        # the cart-pole's theta > 0 leans towards +x (what its equations of motion say)
        ("cartpole", [0.0, 0.0, 0.5, 0.0], rd.JOINT_COLOUR, 1),
        ("cartpole", [0.0, 0.0, -0.5, 0.0], rd.JOINT_COLOUR, -1),
    ],
)
def test_angles_are_drawn_on_the_side_their_convention_says(name, state, pivot_colour, side):
    frame = _frame(name, state)
    rod = _centroid(_mask(frame, rd.LINK_COLOUR))
    # the shoulder/pivot/cart joint: the topmost joint marker (the acrobot's elbow is lower)
    joints = _mask(frame, pivot_colour)
    pivot_column = _centroid(joints)[1] if name != "acrobot" else frame.shape[1] / 2
    assert np.sign(rod[1] - pivot_column) == side


def test_the_cart_and_the_mountain_car_are_drawn_where_x_says() -> None:
    columns = [_centroid(_mask(_frame("cartpole", [x, 0, 0, 0]), rd.BODY_COLOUR))[1] for x in
               (-1.0, 0.0, 1.0)]  # fmt: skip
    assert columns[0] < columns[1] < columns[2]
    # equal steps in x, equal steps in pixels (a linear, unflipped axis)
    assert columns[2] - columns[1] == pytest.approx(columns[1] - columns[0], abs=2.0)
    valley = _frame("mountaincar", [-np.pi, 0.0])
    hilltop = _frame("mountaincar", [0.0, 0.0])
    car_valley = _centroid(_mask(valley, rd.BODY_COLOUR) & ~_mask(hilltop, rd.BODY_COLOUR))
    car_top = _centroid(_mask(hilltop, rd.BODY_COLOUR) & ~_mask(valley, rd.BODY_COLOUR))
    assert car_valley[1] < car_top[1] and car_valley[0] > car_top[0]  # left of it, lower


# --------------------------------------------------------------------------- custom systems
def test_a_system_without_a_drawing_renders_nothing_and_says_so_in_one_line(tmp_path) -> None:
    cart = _load_example().DampedCart()
    env = LeocEnv(system=cart, render_mode="rgb_array")  # accepted, as make_vec_env asks
    env.reset(seed=0)
    with pytest.raises(ValueError, match="'damped_cart' cannot be drawn") as error:
        env.render()
    assert "\n" not in str(error.value) and "draw(ax, state)" in str(error.value)
    with pytest.raises(ValueError, match="'damped_cart' cannot be drawn"):
        video.write_video(cart, lambda obs: torch.zeros(obs.shape[0], 1), tmp_path / "a.gif")
    assert not (tmp_path / "a.gif").exists()


def test_a_systems_draw_hook_and_frame_size_are_used() -> None:
    from matplotlib.patches import Rectangle

    example = _load_example()

    class DrawnCart(example.DampedCart):
        frame_size = (300, 200)

        def draw(self, ax, state):
            ax.set_xlim(-2.0, 2.0)
            ax.set_ylim(-1.0, 1.0)
            ax.add_patch(Rectangle((state[0] - 0.2, -0.2), 0.4, 0.4, color=rd.BODY_COLOUR))

    env = LeocEnv(system=DrawnCart(), render_mode="rgb_array")
    env.reset(options={"state": [-1.0, 0.0]})
    left = env.render()
    env.reset(options={"state": [1.0, 0.0]})
    right = env.render()
    assert left.shape == (200, 300, 3)
    assert _centroid(_mask(left, rd.BODY_COLOUR))[1] < _centroid(_mask(right, rd.BODY_COLOUR))[1]


def test_a_systems_draw_gets_cleared_axes_before_every_frame() -> None:
    """The hook's axes are cleared before every frame, as documented: a frame depends on its
    state only, not on the frames before it, even for a drawing that leaves its limits to
    matplotlib's autoscaling and sets a title (which leoc's own drawings never do)."""
    example = _load_example()

    class AutoscaledCart(example.DampedCart):
        frame_size = (300, 200)

        def draw(self, ax, state):
            ax.set_title(f"x = {state[0]:.1f}")
            ax.plot([state[0] - 0.2, state[0] + 0.2], [0.0, 0.4], color=rd.BODY_COLOUR)

    def frame(*states: float) -> np.ndarray:
        env = LeocEnv(system=AutoscaledCart(), render_mode="rgb_array")
        for x in states:
            env.reset(options={"state": [x, 0.0]})
            image = env.render()
        env.close()
        return image

    np.testing.assert_array_equal(frame(-1.0, 1.0), frame(1.0))


# --------------------------------------------------------------------------- animations
class _ConstantHybrid:
    """Zero action and a constant relevance: what the gauge must show is known."""

    def __init__(self, value: float) -> None:
        self.value = value

    def __call__(self, obs):
        return torch.zeros(obs.shape[0], 1, dtype=obs.dtype)

    def relevance(self, obs):
        return torch.full((obs.shape[0], 1), self.value, dtype=obs.dtype)


def _gauge_fraction(frame: np.ndarray) -> float:
    """Filled fraction of the gauge, on the middle row of its bar: the bar's length against
    the gauge's (the bar and the background after it, gaps of a blended pixel or two
    allowed where they meet; the label's text lies further left)."""
    bar = _mask(frame, rd.GAUGE_COLOUR)
    if not bar.any():
        return 0.0
    rows = np.nonzero(bar.any(axis=1))[0]
    row = rows[rows.size // 2]
    columns = np.nonzero(bar[row] | _mask(frame, rd.GAUGE_BACKGROUND)[row])[0]
    start = end = int(np.nonzero(bar[row])[0][0])
    for column in columns[columns > start]:
        if column - end > GAUGE_GAP:
            break
        end = int(column)
    return np.count_nonzero(bar[row]) / (end - start + 1)


@pytest.mark.parametrize("value", [0.25, 0.8])
def test_the_animation_shows_the_hybrids_relevance_as_a_bar(value) -> None:
    system = make_system("pendulum")
    clips = video.episode_clips(system, _ConstantHybrid(value), steps=TINY_STEPS)
    frames = list(video.clip_frames(system, clips, label="test"))
    assert len(frames) == 2 * (TINY_STEPS + 1)
    for frame in (frames[0], frames[-1]):
        assert _gauge_fraction(frame) == pytest.approx(value, abs=0.02)


def test_an_animation_of_a_controller_without_relevance_has_no_bar() -> None:
    system = make_system("pendulum")
    controller = lambda obs: torch.zeros(obs.shape[0], 1, dtype=obs.dtype)  # noqa: E731
    clips = video.episode_clips(system, controller, steps=TINY_STEPS)
    frame = next(video.clip_frames(system, clips))
    assert not _mask(frame, rd.GAUGE_COLOUR).any()


def test_the_swing_up_clip_starts_at_the_swing_up_start_and_the_impulse_at_the_top() -> None:
    system = make_system("pendulum")
    swing_up, impulse = video.episode_clips(system, _ConstantHybrid(0.5), steps=TINY_STEPS)
    expected = system.sample_start(np.random.default_rng(video.SWING_UP_SEED), "swing_up")
    np.testing.assert_allclose(swing_up.trajectory.states[0], expected)
    np.testing.assert_allclose(impulse.trajectory.states[0], system.operating_state)


def test_fast_systems_are_animated_at_no_more_than_25_frames_per_second(tmp_path) -> None:
    cartpole = make_system("cartpole")  # dt = 0.02 s: every second step, 40 ms a frame
    path = video.write_video(cartpole, _ConstantHybrid(1.0), tmp_path / "c.gif", TINY_STEPS)
    with Image.open(path) as gif:
        assert gif.n_frames == 2 * 3  # states 0, 2, 4 of each 6-state clip
        assert gif.info["duration"] == 40


def test_leoc_simulate_video_writes_a_gif_with_a_frame_per_state(tmp_path, capsys) -> None:
    path = tmp_path / "out.gif"
    steps = 7
    assert main(["simulate", "pendulum", "--steps", str(steps), "--video", str(path)]) == 0
    assert f"animation written to {path}" in capsys.readouterr().out
    with Image.open(path) as gif:
        # the swing-up and the impulse response, steps + 1 states each, 50 ms apart (dt)
        assert gif.n_frames == 2 * (steps + 1)
        assert gif.info["duration"] == 50
        assert gif.size == rd.frame_size(make_system("pendulum"))


def test_leoc_simulate_video_keeps_json_output_clean(tmp_path, capsys) -> None:
    import json

    path = tmp_path / "out.gif"
    assert main(["simulate", "pendulum", "--steps", "3", "--video", str(path), "--json"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["system"] == "pendulum"
    assert "animation written" in captured.err and path.is_file()


@pytest.mark.parametrize(
    ("name", "which", "message"),
    [
        ("out.avi", "/usr/bin/ffmpeg", "expected a file ending in .gif or .mp4"),
        ("out.mp4", None, "needs the ffmpeg program, which is not on the PATH"),
    ],
)
def test_an_unwritable_video_format_is_refused_in_one_line(
    tmp_path, capsys, monkeypatch, name, which, message
) -> None:
    monkeypatch.setattr(video.shutil, "which", lambda program: which)
    args = ["simulate", "pendulum", "--steps", "2", "--video", str(tmp_path / name)]
    assert main(args) == 2
    error = capsys.readouterr().err.strip()
    assert message in error and "\n" not in error
    assert not (tmp_path / name).exists()


def test_the_representative_run_is_the_median_by_swing_up_return() -> None:
    runs = [
        {"spec": {"seed": seed}, "swing_up": {"mean_return": value}}
        for seed, value in enumerate([-5.0, -1.0, -3.0, -4.0])
    ]
    # returns sorted: -5 (seed 0), -4 (3), -3 (2), -1 (1): the lower median is seed 3
    assert animations.representative_run(runs)["spec"]["seed"] == 3
    assert animations.representative_run(runs[:3])["spec"]["seed"] == 2


def test_a_folder_without_trained_controllers_gets_no_animations(tmp_path) -> None:
    published = Path(__file__).resolve().parents[1] / "results" / "paper"
    if not (published / "runs").is_dir():
        pytest.skip("no published study in this checkout")
    # results/paper keeps evaluations but no trained controllers
    runs = tmp_path / "runs" / "pendulum" / "ddpg_hybrid" / "seed0"
    runs.mkdir(parents=True)
    source = published / "runs" / "pendulum" / "ddpg_hybrid" / "seed0" / "evaluation.json"
    (runs / "evaluation.json").write_text(source.read_text())
    assert animations.write_report_animations(tmp_path) == {}
    assert not (tmp_path / animations.ANIMATIONS_DIR).exists()


@pytest.mark.slow
def test_report_animations_of_a_trained_hybrid(tmp_path) -> None:
    """A tiny DDPG hybrid trained into a reproduce-style folder gets animations/pendulum.gif."""
    import json

    run = tmp_path / "runs" / "pendulum" / "ddpg_hybrid" / "seed0"
    train = ["train", "pendulum", "--algo", "ddpg", "--hybrid", "--steps", "300", "--quiet"]
    assert main([*train, "--out", str(run / "train")]) == 0
    record = {
        "spec": {"system": "pendulum", "controller": "ddpg_hybrid", "seed": 0},
        "variant": "leoc",
        "swing_up": {"mean_return": -1.0},
    }
    (run / "evaluation.json").write_text(json.dumps(record))
    written = animations.write_report_animations(tmp_path)
    assert written == {"pendulum": tmp_path / "animations" / "pendulum.gif"}
    with Image.open(written["pendulum"]) as gif:
        assert gif.n_frames == 2 * (make_system("pendulum").episode_steps + 1)
    # a report rewritten over the same runs keeps the animation instead of redrawing it
    drawn_at = written["pendulum"].stat().st_mtime_ns
    assert animations.write_report_animations(tmp_path) == written
    assert written["pendulum"].stat().st_mtime_ns == drawn_at


# --------------------------------------------------------------------------- no prior import
FRESH_INTERPRETER = """
import sys
import gymnasium
assert "leoc" not in sys.modules
try:
    gymnasium.make("leoc/PendulumSwingUp-v0")
except gymnasium.error.NamespaceNotFound:
    print("without prefix: namespace not found")
for env_id in sys.argv[1:]:
    env = gymnasium.make("leoc:" + env_id, render_mode="rgb_array")
    env.reset(seed=0)
    print(env_id, env.render().shape)
"""


@pytest.mark.slow
def test_envs_are_made_in_a_fresh_interpreter_through_the_leoc_prefix() -> None:
    ids = list(ENV_IDS.values())
    result = subprocess.run(
        [sys.executable, "-c", FRESH_INTERPRETER, *ids],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0] == "without prefix: namespace not found"
    for line, (name, env_id) in zip(lines[1:], ENV_IDS.items(), strict=True):
        width, height = rd.frame_size(make_system(name))
        assert line == f"{env_id} ({height}, {width}, 3)"
