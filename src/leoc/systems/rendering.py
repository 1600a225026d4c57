"""Drawing a system's state: one frame, apart from the physics (as gymnasium's classic control).

Every frame is a matplotlib figure drawn from a state alone, so the same drawing serves the
environments' ``render_mode`` (:class:`~leoc.systems.envs.LeocEnv`) and the animations of
``leoc simulate --video`` (:mod:`leoc.evaluation.video`). matplotlib (a leoc dependency) draws
on its Agg canvas, so ``rgb_array`` frames need no display.

Built-in drawings (angles as the systems define them: 0 upright, pendulum and acrobot angles
anticlockwise, the cart-pole's theta positive when the pole leans towards +x):

==============  ==================================================================
pendulum        a rod of length l about its pivot (:func:`draw_pendulum`)
cartpole        the track ``|x| <= x_limit``, the cart and a pole of length 2 l
                (:func:`draw_cartpole`)
mountaincar     the hill h(x) over the track, the car, a flag on the hilltop
                (:func:`draw_mountaincar`)
acrobot         two links from a fixed shoulder, link 2 of length 2 l_c2
                (:func:`draw_acrobot`)
==============  ==================================================================

The hook for a user's system: give the ``System`` subclass a method ``draw(ax, state)`` that
draws the state ``(S,)`` on the matplotlib ``Axes`` ``ax`` (cleared, axis lines hidden, before
every frame) and sets the axes' limits; optionally a class attribute ``frame_size``, the frame's
``(width, height)`` in pixels (default :data:`DEFAULT_FRAME_SIZE`)::

    class DampedCart(System):
        frame_size = (480, 240)

        def draw(self, ax, state):
            ax.set_xlim(-2.0, 2.0)
            ax.set_ylim(-0.5, 0.5)
            ax.set_aspect("equal")
            ax.add_patch(matplotlib.patches.Rectangle((state[0] - 0.2, -0.1), 0.4, 0.2))

A system with neither a built-in drawing nor ``draw`` renders nothing: ``render()`` and
``leoc simulate --video`` raise a one-line ``ValueError`` that names it.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from leoc.systems.acrobot import Acrobot
from leoc.systems.base import System
from leoc.systems.cartpole import CartPole
from leoc.systems.mountaincar import TRACK_HIGH, TRACK_LOW, MountainCar
from leoc.systems.pendulum import Pendulum

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

#: The environments' render modes, as gymnasium names them.
RENDER_MODES = ("human", "rgb_array")
#: Frame resolution: pixels per inch of the figure.
DPI = 100
#: Frame size (width, height, pixels) of a user's system that sets no ``frame_size``.
DEFAULT_FRAME_SIZE = (480, 480)
#: Frames per second above which an animation skips frames (a GIF frame lasts >= 20 ms, and
#: browsers slow shorter ones down).
MAX_FPS = 25

# Colours (gymnasium's classic-control palette): links and poles, joints, cart, track, goal.
LINK_COLOUR = "#ca9865"
JOINT_COLOUR = "#8184cb"
BODY_COLOUR = "#333333"
TRACK_COLOUR = "#999999"
GOAL_COLOUR = "#2a9d8f"
GAUGE_COLOUR = "#e76f51"
GAUGE_BACKGROUND = "#dddddd"
LINK_WIDTH = 8.0  # points
JOINT_SIZE = 10.0  # points (marker size)
# Margin around a drawing, as a fraction of its extent.
MARGIN = 0.1
# Pendulum and acrobot: the reference line of the operating point (upright), dashed.
REFERENCE_STYLE = {"color": GOAL_COLOUR, "linestyle": "--", "linewidth": 1.0}
# Cart-pole: the cart's size in metres (half-width, height).
CART_HALF_WIDTH = 0.25
CART_HEIGHT = 0.15
# Mountain car: the car's half-length in metres and points along the hill it is drawn with.
CAR_HALF_LENGTH = 0.15
HILL_SAMPLES = 200
# Layout, in figure coordinates (0..1): the drawing between a caption band at the top and a
# gauge band at the bottom, so that neither covers the system.
DRAWING_BOX = (0.0, 0.1, 1.0, 0.76)  # left, bottom, width, height
CAPTION_POSITION = (0.02, 0.98)
GAUGE_BOX = (0.55, 0.025, 0.4, 0.05)
FONT_SIZE = 10

#: ``drawer(system, ax, state)``: draws ``state`` on ``ax`` and sets the axes' limits.
Drawer = Callable[[Any, "Axes", np.ndarray], None]


def _remove_drawing(ax: Axes) -> None:
    """Remove what the last frame drew on ``ax`` and restart its colour cycle: what
    ``ax.clear()`` does for leoc's own drawings (lines, patches, texts; each sets its limits
    again), without rebuilding the axes' ticks and spines (most of a frame's time). A system's
    own ``draw`` may leave anything on its axes, so those are cleared in full."""
    for artist in (*ax.lines, *ax.patches, *ax.texts, *ax.collections, *ax.images):
        artist.remove()
    ax.set_prop_cycle(None)


def _clear(ax: Axes) -> None:
    """``ax.clear()`` with the axis lines hidden: the axes a system's own ``draw`` gets."""
    ax.clear()
    ax.set_axis_off()


class Gauge(NamedTuple):
    """A value in [0, 1] drawn as a bar with its label (a hybrid's relevance r(x))."""

    label: str
    value: float


def _link(ax: Axes, start: tuple[float, float], end: tuple[float, float]) -> None:
    ax.plot(
        [start[0], end[0]],
        [start[1], end[1]],
        color=LINK_COLOUR,
        linewidth=LINK_WIDTH,
        solid_capstyle="round",
        zorder=2,
    )


def _joint(ax: Axes, point: tuple[float, float]) -> None:
    ax.plot(*point, "o", color=JOINT_COLOUR, markersize=JOINT_SIZE, zorder=3)


def _square_limits(ax: Axes, reach: float) -> None:
    bound = reach * (1.0 + MARGIN)
    ax.set_xlim(-bound, bound)
    ax.set_ylim(-bound, bound)
    ax.set_aspect("equal")


def upright_rotation(angle: float, length: float) -> tuple[float, float]:
    """The end of a rod of ``length`` from the origin at ``angle`` rad from upright,
    anticlockwise: ``(-length sin angle, length cos angle)``."""
    return (-length * math.sin(angle), length * math.cos(angle))


def draw_pendulum(system: Pendulum, ax: Axes, state: np.ndarray) -> None:
    """The rod from the pivot at the origin to ``(-l sin theta, l cos theta)``."""
    length = system.params.length
    ax.plot([0.0, 0.0], [0.0, length], **REFERENCE_STYLE)
    tip = upright_rotation(float(state[0]), length)
    _link(ax, (0.0, 0.0), tip)
    _joint(ax, (0.0, 0.0))
    _square_limits(ax, length)


def draw_cartpole(system: CartPole, ax: Axes, state: np.ndarray) -> None:
    """The track, the cart at ``x`` and the pole to ``(x + 2 l sin theta, 2 l cos theta)``
    (theta > 0 leans towards +x, as the equations of motion have it)."""
    from matplotlib.patches import Rectangle

    p = system.params
    x, theta = float(state[0]), float(state[2])
    pole = 2.0 * p.half_length
    ax.plot([-p.x_limit, p.x_limit], [0.0, 0.0], color=TRACK_COLOUR, linewidth=2.0, zorder=0)
    for end in (-p.x_limit, p.x_limit):
        ax.plot([end, end], [-CART_HEIGHT, CART_HEIGHT], color=TRACK_COLOUR, linewidth=2.0)
    ax.add_patch(
        Rectangle(
            (x - CART_HALF_WIDTH, -CART_HEIGHT / 2.0),
            2.0 * CART_HALF_WIDTH,
            CART_HEIGHT,
            color=BODY_COLOUR,
            zorder=1,
        )
    )
    _link(ax, (x, 0.0), (x + pole * math.sin(theta), pole * math.cos(theta)))
    _joint(ax, (x, 0.0))
    width = p.x_limit + CART_HALF_WIDTH
    ax.set_xlim(-width * (1.0 + MARGIN), width * (1.0 + MARGIN))
    ax.set_ylim(-pole * (1.0 + MARGIN), pole * (1.0 + MARGIN))
    ax.set_aspect("equal")


def draw_mountaincar(system: MountainCar, ax: Axes, state: np.ndarray) -> None:
    """The hill ``h(x) = a cos x + c`` over the track, a flag on the hilltop (x = 0) and the
    car at ``(x, h(x))``, tilted with the slope."""
    from matplotlib.patches import Rectangle
    from matplotlib.transforms import Affine2D

    p = system.params
    track = np.linspace(TRACK_LOW, TRACK_HIGH, HILL_SAMPLES)
    ax.plot(track, p.hill_amplitude * np.cos(track) + p.hill_offset, color=TRACK_COLOUR, lw=2.0)
    top = p.hill_amplitude + p.hill_offset
    flag = 0.4 * p.hill_amplitude
    ax.plot([0.0, 0.0], [top, top + flag], color=BODY_COLOUR, linewidth=1.5)
    ax.fill([0.0, 0.0, 0.3 * flag], [top + flag, top + 0.6 * flag, top + 0.8 * flag], GOAL_COLOUR)
    x = float(state[0])
    height = p.hill_amplitude * math.cos(x) + p.hill_offset
    slope = math.atan(-p.hill_amplitude * math.sin(x))
    car = Rectangle(
        (-CAR_HALF_LENGTH, 0.0),
        2.0 * CAR_HALF_LENGTH,
        CAR_HALF_LENGTH,
        color=BODY_COLOUR,
        zorder=3,
    )
    car.set_transform(Affine2D().rotate(slope).translate(x, height) + ax.transData)
    ax.add_patch(car)
    low, high = TRACK_LOW, TRACK_HIGH
    pad = MARGIN * (high - low)
    ax.set_xlim(low - pad, high + pad)
    ax.set_ylim(p.hill_offset - p.hill_amplitude - pad, top + flag + pad)
    ax.set_aspect("equal")


def draw_acrobot(system: Acrobot, ax: Axes, state: np.ndarray) -> None:
    """Link 1 from the shoulder at the origin at theta1 from upright, link 2 (length 2 l_c2,
    the centre of mass at mid-link) at theta1 + theta2; both anticlockwise."""
    p = system.params
    second = 2.0 * p.link_com_2
    ax.plot([0.0, 0.0], [0.0, p.link_length_1 + second], **REFERENCE_STYLE)
    theta1, theta2 = float(state[0]), float(state[1])
    elbow = upright_rotation(theta1, p.link_length_1)
    offset = upright_rotation(theta1 + theta2, second)
    tip = (elbow[0] + offset[0], elbow[1] + offset[1])
    _link(ax, (0.0, 0.0), elbow)
    _link(ax, elbow, tip)
    _joint(ax, (0.0, 0.0))
    _joint(ax, elbow)
    _square_limits(ax, p.link_length_1 + second)


#: The built-in drawings, by system class (a subclass is drawn as its base).
BUILTIN_DRAWERS: dict[type[System], Drawer] = {
    Pendulum: draw_pendulum,
    CartPole: draw_cartpole,
    MountainCar: draw_mountaincar,
    Acrobot: draw_acrobot,
}
#: Frame sizes (width, height, pixels) of the built-in drawings.
BUILTIN_FRAME_SIZES: dict[type[System], tuple[int, int]] = {
    Pendulum: (400, 400),
    CartPole: (600, 320),
    MountainCar: (600, 360),
    Acrobot: (400, 400),
}


def _builtin(system: System, table: dict[type[System], Any]) -> Any:
    for kind, value in table.items():
        if isinstance(system, kind):
            return value
    return None


def drawer_for(system: System) -> Callable[[Axes, np.ndarray], None]:
    """``draw(ax, state)`` of ``system``: its own ``draw`` method if it has one, else the
    built-in drawing of its class.

    Raises
    ------
    ValueError
        If the system has neither (one line, naming it and the hook).
    """
    own = getattr(system, "draw", None)
    if callable(own):
        return own
    builtin = _builtin(system, BUILTIN_DRAWERS)
    if builtin is not None:
        return functools.partial(builtin, system)
    raise ValueError(
        f"system {getattr(system, 'name', type(system).__name__)!r} cannot be drawn: give "
        f"{type(system).__name__} a draw(ax, state) method (see leoc.systems.rendering)"
    )


def frame_size(system: System) -> tuple[int, int]:
    """The frame size (width, height, pixels): the system's ``frame_size``, the built-in size
    of its class, or :data:`DEFAULT_FRAME_SIZE`."""
    size = getattr(system, "frame_size", None) or _builtin(system, BUILTIN_FRAME_SIZES)
    return tuple(size or DEFAULT_FRAME_SIZE)


def frame_stride(system: System) -> int:
    """Simulator steps per animation frame: 1, or more when 1 / dt exceeds :data:`MAX_FPS`."""
    return max(1, math.ceil(1.0 / (system.dt * MAX_FPS)))


class Renderer:
    """Draws frames of one system on one figure (kept between frames).

    Parameters
    ----------
    system : System
    mode : {"rgb_array", "human"}
        ``rgb_array``: an off-screen Agg canvas, :meth:`frame` returns ``(H, W, 3)`` uint8.
        ``human``: a pyplot window, updated by :meth:`frame` at the system's pace
        (1 / dt frames per second); :meth:`frame` returns None. Under a non-interactive
        backend (``MPLBACKEND=Agg``) nothing is shown and nothing waits.

    Raises
    ------
    ValueError
        If ``mode`` is not a render mode or the system cannot be drawn (:func:`drawer_for`).
    """

    def __init__(self, system: System, mode: str = "rgb_array") -> None:
        if mode not in RENDER_MODES:
            raise ValueError(f"render_mode: expected None or one of {RENDER_MODES}, found {mode!r}")
        self.system = system
        self.mode = mode
        self.draw = drawer_for(system)
        # leoc's drawings are removed artist by artist; a system's own draw gets cleared axes
        self._reset_drawing = (
            _clear if self.draw == getattr(system, "draw", None) else _remove_drawing
        )
        width, height = frame_size(system)
        figsize = (width / DPI, height / DPI)
        if mode == "human":
            import matplotlib.pyplot as plt

            self.figure: Figure = plt.figure(figsize=figsize, dpi=DPI)
        else:
            from matplotlib.backends.backend_agg import FigureCanvasAgg
            from matplotlib.figure import Figure

            self.figure = Figure(figsize=figsize, dpi=DPI)
            FigureCanvasAgg(self.figure)
        # captions and the gauge on a figure-wide axes beneath the drawing's
        self.overlay = self.figure.add_axes((0.0, 0.0, 1.0, 1.0))
        self.axes = self.figure.add_axes(DRAWING_BOX)
        for ax in (self.overlay, self.axes):
            ax.set_axis_off()

    def frame(
        self, state: Any, caption: str | None = None, gauge: Gauge | None = None
    ) -> np.ndarray | None:
        """Draw ``state`` ``(S,)``, with an optional caption (top left) and gauge (bottom right)
        in bands of their own.

        Returns the ``(H, W, 3)`` uint8 frame in ``rgb_array`` mode, None in ``human`` mode.
        """
        _remove_drawing(self.overlay)
        self._reset_drawing(self.axes)
        self.draw(self.axes, np.asarray(state, dtype=float))
        if caption:
            self.overlay.text(
                *CAPTION_POSITION,
                caption,
                transform=self.overlay.transAxes,
                va="top",
                fontsize=FONT_SIZE,
                family="monospace",
            )
        if gauge is not None:
            self._gauge(gauge)
        if self.mode == "human":
            self._show()
            return None
        canvas = self.figure.canvas
        canvas.draw()
        return np.asarray(canvas.buffer_rgba())[..., :3].copy()

    def _gauge(self, gauge: Gauge) -> None:
        from matplotlib.patches import Rectangle

        ax = self.overlay
        left, bottom, width, height = GAUGE_BOX
        value = float(np.clip(gauge.value, 0.0, 1.0))
        for fill, colour in ((1.0, GAUGE_BACKGROUND), (value, GAUGE_COLOUR)):
            ax.add_patch(
                Rectangle(
                    (left, bottom), width * fill, height, transform=ax.transAxes, color=colour
                )
            )
        ax.text(
            left - 0.01,
            bottom + height / 2.0,
            gauge.label,
            transform=ax.transAxes,
            ha="right",
            va="center",
            fontsize=FONT_SIZE,
            family="monospace",
        )

    def _show(self) -> None:
        import matplotlib.pyplot as plt

        if self.figure.canvas.required_interactive_framework is None:  # e.g. Agg: no window
            self.figure.canvas.draw()
            return
        plt.pause(self.system.dt)

    def close(self) -> None:
        """Release the figure (and close the window in ``human`` mode)."""
        if self.mode == "human":
            import matplotlib.pyplot as plt

            plt.close(self.figure)
        self.figure = None  # type: ignore[assignment]
