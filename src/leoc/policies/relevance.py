r"""Relevance functions of the LEOC hybrid: how much the linear part governs at an observation.

Letters: D observation dimension, S state dimension; ``...`` any leading batch shape.

The relevance modules map an observation batch (..., D) to :math:`r(x) \in [0, 1]`, shape
(..., 1); :class:`~leoc.policies.HybridPolicy` blends
:math:`\pi = \operatorname{sat}(r G + (1 - r) H)` with any of them.

**The paper's relevance** (Zhang & Capel 2021, eq. 5), :class:`PaperRelevance`:

.. math::

    r(x) = \frac{1}{(1 + d(x))^2}, \qquad d(x) = \sum_{i=1}^{D} \frac{(x_i - a_i)^2}{\lambda_i},

equal to 1 only at the operating point :math:`a` (in observation coordinates), with
:math:`\lambda = \exp(\text{log\_lambda})` learnable or frozen. It guarantees
:math:`\pi(a) = G(a)` and :math:`\partial \pi / \partial x (a) = W`, nothing more: anywhere
else the learned part leaks in, and training can shrink :math:`\lambda` until even a small
disturbance leaves the region the linear part governs.

**The floored paper relevance**, :class:`FlooredRelevance`: the same :math:`r = (1 + d)^{-2}`
with :math:`\lambda` bounded below by a floor :math:`f` (:func:`relevance_floor`) such that
:math:`r \ge r_{min}` on the LQR's proved region of attraction
:math:`\Omega = \{x : z^\top P z \le \rho\}` (:math:`z` the state deviation, as below),
whatever :math:`\lambda \ge f` training reaches. :math:`r \ge r_{min}` iff
:math:`d \le d_{max} = r_{min}^{-1/2} - 1`. Each observation entry is bounded by its state
deviation: a plain entry :math:`j` of state :math:`s` gives :math:`z_s^2 / \lambda_j`; an angle
:math:`s` seen as :math:`(\cos\theta, \sin\theta)` in columns :math:`c, k` gives
:math:`(\cos\theta - \cos a_s)^2 / \lambda_c + (\sin\theta - \sin a_s)^2 / \lambda_k \le
\max(\lambda_c^{-1}, \lambda_k^{-1}) \, 4 \sin^2(\delta / 2) \le
\max(\lambda_c^{-1}, \lambda_k^{-1}) \, z_s^2` (:math:`\delta = z_s`, any representative). So
:math:`d \le z^\top \mathcal{W} z`, :math:`\mathcal{W} = \operatorname{diag}(w_s)`, whose maximum
on :math:`\Omega` is :math:`\rho \, \lambda_{max}(\mathcal{W} P^{-1})`, monotone in the
diagonal :math:`\mathcal{W} \ge 0`. The floor takes the shape
:math:`w_s \propto 1 / (P^{-1})_{ss}` and scales it to reach :math:`d_{max}`. The weights are
held as :math:`\lambda_j = f_j (1 + e^{q_j})`, :math:`q` learnable, so :math:`\lambda > f`
always and :math:`r(a) = 1` exactly.

**The ROA relevance**, :class:`ROARelevance`: flat (exactly 1) on a certified sublevel set of
the LQR's Lyapunov function and falling smoothly to 0 outside it,

.. math::

    V(z) = z^\top P z, \qquad s(x) = \frac{V(z(x))}{\rho_{in}}, \qquad
    t(x) = \operatorname{clamp}\Big(\frac{s(x) - 1}{w}, 0, 1\Big), \qquad
    r(x) = 1 - (10 t^3 - 15 t^4 + 6 t^5),

where :math:`z(x)` is the *state deviation* recovered from the observation
(:class:`ObservationDeviation`: a plain entry :math:`x_j - a_s`; an angle seen as
:math:`(\cos\theta, \sin\theta)` gives :math:`\operatorname{wrap}(\operatorname{atan2}(\sin,
\cos) - a_s) \in [-\pi, \pi)`, the systems' convention), :math:`P` the Riccati solution of the
LQR design at the hybrid's control period, :math:`\rho_{in} \le \rho` a level no larger than the
certified one (:func:`leoc.control.certify_lqr`) and :math:`w > 0` the learnable width of the
transition band :math:`\rho_{in} < V \le (1 + w) \rho_{in}`. The quintic "smootherstep" has
value 1 and zero first and second derivatives at :math:`t = 0`, value 0 and zero first and second
derivatives at :math:`t = 1`, so :math:`r` is :math:`C^2` in :math:`V`, hence in :math:`x`
wherever the wrap is continuous. The wrap jumps only where an angle deviation is
:math:`\pm\pi`; there :math:`V \ge \pi^2 / (P^{-1})_{ss}` (the minimum of :math:`z^\top P z` on
:math:`z_s = \pm\pi`), and for systems with angles the width is bounded,
:math:`w = w_{max} \operatorname{sigmoid}(\text{width\_param})` with
:math:`w_{max} = \min_s \pi^2 / ((P^{-1})_{ss} \rho_{in}) - 1`, so the band ends strictly before
the cut and :math:`r \equiv 0` in a neighbourhood of it: :math:`r` is :math:`C^2` on the whole
observation manifold. Without angles :math:`w = \exp(\text{width\_param})`. Learning moves only
:math:`w`: it can widen (or sharpen) the transition but :math:`\rho_{in}` is a buffer, so the
flat top never shrinks.

**Theorem (the hybrid inherits the certified region of attraction).** Assume

1. :math:`\Omega = \{x : V(z(x)) \le \rho\}` is certified for the *linear* closed loop
   :math:`x^+ = F(x, \operatorname{sat}(G(o(x))))` run at the hybrid's control period (the
   held map, with the hybrid's own saturation): :math:`V(z(F(x))) < V(z(x))` for every
   :math:`x \in \Omega \setminus \{a\}` (for a sampling certificate: up to the stated
   violating-volume bound and confidence; :func:`leoc.control.certify_lqr`);
2. :math:`\Omega` lies inside one chart of the angle wrap (angular extent below :math:`\pi`)
   and inside the allowed region of the system (the certificate checks both);
3. the hybrid uses this relevance with :math:`\rho_{in} \le \rho` and the same :math:`P`,
   :math:`a` and :math:`G`, and no disturbance acts.

Then on :math:`\Omega_{in} = \{V \le \rho_{in}\} \subseteq \Omega` the relevance is exactly 1,
so :math:`\pi(x) = \operatorname{sat}(1 \cdot G(x) + 0 \cdot H(x)) = \operatorname{sat}(G(x))`
(bit for bit when :math:`H(x)` is finite): the hybrid's closed loop *is* the certified linear
closed loop there. Since :math:`V` strictly decreases along it, :math:`\Omega_{in}` is positively
invariant for the hybrid, and by the discrete-time Lyapunov theorem (Khalil 2002, Thm 4.1 and
its discrete analogue; a continuous :math:`V` strictly decreasing on the compact set
:math:`\Omega_{in} \setminus \{a\}`) every trajectory of the hybrid that enters
:math:`\Omega_{in}` converges to :math:`a`: the hybrid's basin contains :math:`\Omega_{in}`,
whatever :math:`H` and :math:`w` are learned. With a disturbance (the impulse test) the same
holds once the disturbance has stopped, for every state it leaves inside :math:`\Omega_{in}`.

**The Lyapunov relevance**, :class:`LyapunovRelevance`: the paper's shape with the LQR's own
Lyapunov function as the distance,

.. math::

    r(x) = \frac{1}{(1 + d(x))^2}, \qquad d(x) = \frac{\tilde V(x)}{\lambda \rho}, \qquad
    \tilde V = y^\top P y + \sum_{s \text{ angle}} P_{ss} (1 - \cos\delta_s)^2,

with :math:`\lambda = \exp(\text{log\_lambda})` one learnable scalar and :math:`P, \rho` the
LQR's Lyapunov matrix and proved level (:math:`d = 1 / \lambda` where :math:`\tilde V = \rho`,
close to the proved set's boundary :math:`V = \rho` when that set is small).
:math:`y_s = x_j - a_j` for a plain entry; for an angle
:math:`y_s = \sin\delta_s = (\sin\theta - \sin a_s) \cos a_s - (\cos\theta - \cos a_s) \sin a_s`
and :math:`1 - \cos\delta_s = ((\cos\theta - \cos a_s)^2 + (\sin\theta - \sin a_s)^2) / 2`,
:math:`\cos a_s, \sin a_s` read from the operating observation. Why not :math:`V(z)` itself:
the wrapped deviation jumps at :math:`\delta = \pm\pi`, and :math:`P`'s cross terms
(:math:`2 P_{sk} z_s z_k`) change sign with it, so :math:`d` would jump there. :math:`\tilde V`
is a polynomial in the observation, hence smooth on the whole observation manifold; it equals
:math:`V` to second order at :math:`a` (:math:`\sin\delta = \delta + O(\delta^3)`,
:math:`(1 - \cos\delta)^2 = O(\delta^4)`: the same Hessian :math:`2P`); it is positive away from
:math:`a` (:math:`y = 0` only at :math:`\delta_s \in \{0, \pi\}`, where the last term is
:math:`4 P_{ss} > 0`). At :math:`x = a` every difference is an exact 0, so :math:`r(a) = 1`
exactly and :math:`\nabla r(a) = 0`. The relevance is 1 only at :math:`a`: unlike the ROA
relevance it has no flat top, but its level sets follow the LQR's certified ellipsoids near
:math:`a`.

References
----------
Y. Zhang and F. Capel, "LEOC: A Principled Method in Integrating Reinforcement Learning and
Classical Control Theory", L4DC 2021, eq. 4-5.
H. K. Khalil, *Nonlinear Systems*, 3rd ed., Prentice Hall, 2002, sections 4.1 and 8.2.
A. Najafi, R. Babuska and G. A. D. Lopes, "A fast sampling method for estimating the domain of
attraction of nonlinear systems with hybrid controllers", Automatica, 2016.
K. Perlin, "Improving noise", SIGGRAPH 2002 (the quintic smootherstep).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
import torch
from torch import Tensor, nn

from leoc.control.intervals import Jet, pinned_rows, quadratic_form, smootherstep
from leoc.names import RELEVANCE_NAMES
from leoc.systems.observation import as_observation_map

from ._checks import (
    as_float_tensor,
    as_point,
    check_finite,
    check_flag,
    check_last_dim,
    check_shape,
    register_learnable,
)

__all__ = [
    "DEFAULT_ROA_WIDTH",
    "FLOOR_MARGIN",
    "RELEVANCE_KINDS",
    "FlatRegion",
    "FlooredRelevance",
    "LyapunovRelevance",
    "ObservationDeviation",
    "PaperRelevance",
    "PrecisionRelevance",
    "RELEVANCE_PARAMETRISATIONS",
    "ROARelevance",
    "check_relevance_power",
    "paper_relevance",
    "relevance_floor",
    "relevance_of_distance",
]

#: Relevance functions r(x) of a hybrid: the paper's ``(1 + d)^-2`` or the ROA relevance, flat on
#: the certified set (named in ``leoc.names``, where the command line reads them).
RELEVANCE_KINDS = RELEVANCE_NAMES
RELEVANCE_PARAMETRISATIONS = ("log_lambda", "precision")
r"""How the paper's relevance keeps its weights: ``log_lambda`` (:math:`\lambda = e^{\ell}`,
positive; :class:`PaperRelevance`) or ``precision`` (:math:`S = \Lambda^{-1}` itself,
unconstrained; :class:`PrecisionRelevance`)."""
DEFAULT_ROA_WIDTH = 1.0
"""Default band width w: the relevance falls from 1 at :math:`V = \\rho_{in}` to 0 at
:math:`V = 2 \\rho_{in}` (a radius :math:`\\sqrt 2` times the flat top's)."""
SYMMETRY_RTOL = 1e-9  # |P - P^T| allowed, relative to max |P_ij|
FLOOR_MARGIN = 1e-9
"""Relative margin of :func:`relevance_floor` over the exact bound, so that float64 rounding of
:math:`d` never puts :math:`r` below :math:`r_{min}` at the floor itself."""
UNIT_CIRCLE_ATOL = 1e-6  # |cos^2 a + sin^2 a - 1| allowed in an operating observation


def paper_relevance(
    x: Tensor, operating_point: Tensor, log_lambda: Tensor, power: float = 1.0
) -> Tensor:
    r"""The paper's :math:`r(x) = (1 + d(x))^{-2}`, :math:`d = \sum_i (x_i - a_i)^2 / \lambda_i`;
    with ``power`` :math:`p \ne 1`, :math:`r = (1 + d^p)^{-2}` (:func:`relevance_of_distance`).

    The one formula behind :class:`PaperRelevance` and :class:`~leoc.policies.HybridPolicy`'s
    default, so both give the same numbers bit for bit. Shapes: ``x`` (..., D),
    ``operating_point`` and ``log_lambda`` (D,) -> (..., 1).
    """
    distance = ((x - operating_point).square() / torch.exp(log_lambda)).sum(dim=-1, keepdim=True)
    return relevance_of_distance(distance, power)


def relevance_of_distance(distance: Tensor, power: float = 1.0) -> Tensor:
    r""":math:`r = (1 + d^p)^{-2}` of a distance :math:`d \ge 0` (the paper: :math:`p = 1`).

    Near the operating point :math:`1 - r \approx 2 d^p`: with :math:`p = 2` the hybrid leaks
    its learned part into the LQR's neighbourhood at fourth order in the deviation instead of
    second, while far from it (:math:`d > 1`) :math:`r` falls faster than the paper's. Any
    :math:`p \ge 1` keeps :math:`r(a) = 1` and :math:`\nabla r(a) = 0`, hence
    :math:`\pi(a) = G(a)` and :math:`d\pi/dx(a) = W`. ``power == 1`` computes exactly the
    paper's :math:`(1 + d)^{-2}` (no ``pow``), bit for bit as before the option existed.
    """
    if power != 1.0:
        distance = distance.pow(power)
    return (1.0 + distance).square().reciprocal()


def check_relevance_power(power: object) -> float:
    """``power`` as a float, or ValueError naming ``relevance_power``: a finite number >= 1
    (below 1, :math:`d^p` has an infinite slope at the operating point)."""
    ok = isinstance(power, (int, float)) and not isinstance(power, bool)
    if not ok or not math.isfinite(power) or power < 1.0:
        raise ValueError(f"relevance_power: expected a finite number >= 1, found {power!r}")
    return float(power)


class PaperRelevance(nn.Module):
    r"""The paper's relevance :math:`r(x) = (1 + d(x))^{-2}` as a module (eq. 5).

    Parameters
    ----------
    operating_point : array-like, shape (D,)
        :math:`a` in observation coordinates (buffer ``operating_point``).
    lambda_init : float or array-like (D,)
        Initial :math:`\lambda > 0`.
    learn_lambda : bool
        ``log_lambda`` (D,) is an ``nn.Parameter`` if True, else a buffer.
    dtype : torch.dtype
    power : float
        :math:`p \ge 1` of :math:`r = (1 + d^p)^{-2}` (:func:`relevance_of_distance`; 1: the
        paper's).
    """

    operating_point: Tensor
    log_lambda: Tensor

    def __init__(
        self,
        operating_point: object,
        lambda_init: float | object = 1.0,
        learn_lambda: bool = True,
        dtype: torch.dtype = torch.float64,
        power: float = 1.0,
    ) -> None:
        super().__init__()
        from ._checks import positive_scalar_or_vector

        check_flag(learn_lambda, "learn_lambda")
        self.power = check_relevance_power(power)
        point = as_point(operating_point, "operating_point", dtype)
        self.register_buffer("operating_point", point)
        size = point.shape[0]
        lam = positive_scalar_or_vector(lambda_init, "lambda_init", size, "D", dtype)
        log_lambda = torch.log(lam.expand(size).clone())
        register_learnable(self, "log_lambda", log_lambda, learn_lambda)

    @property
    def lambda_(self) -> Tensor:
        r""":math:`\lambda = \exp(\text{log\_lambda})`, shape (D,)."""
        return torch.exp(self.log_lambda)

    def forward(self, x: Tensor) -> Tensor:
        """Relevance (..., 1) of observations ``x`` (..., D)."""
        check_last_dim(x, self.operating_point.shape[0], self.operating_point.dtype)
        return paper_relevance(x, self.operating_point, self.log_lambda, self.power)

    def extra_repr(self) -> str:
        learned = isinstance(self.log_lambda, nn.Parameter)
        return f"D={self.operating_point.shape[0]}, learn_lambda={learned}, power={self.power:g}"


class PrecisionRelevance(nn.Module):
    r"""The paper's relevance with the precision :math:`S = \Lambda^{-1}` as its parameter.

    .. math::

        r(x) = \frac{1}{(1 + d(x))^2}, \qquad d(x) = \sum_{i=1}^{D} S_i (x_i - a_i)^2,

    the same function as :class:`PaperRelevance` for :math:`S_i = 1 / \lambda_i`, but trained
    in :math:`S` directly and **unconstrained**: a gradient step may make some :math:`S_i`
    negative, and then :math:`d` can be negative and :math:`r` may exceed 1 (or diverge where
    :math:`d = -1`). This is the parametrisation of nrjc/LEOC's DDPG hybrid actor
    (``DDPG/ddpg.py``, ``MyActorNetwork``: ``S = tf.Variable(S, trainable=True)``, its
    positivity constraint commented out). Whatever :math:`S`, :math:`d(a) = 0` and
    :math:`\nabla d(a) = 0`, so :math:`r(a) = 1` exactly and :math:`\nabla r(a) = 0`: the
    hybrid's identities :math:`\pi(a) = G(a)`, :math:`\partial\pi/\partial x(a) = W` hold.

    Parameters
    ----------
    operating_point : array-like, shape (D,)
        :math:`a` in observation coordinates (buffer ``operating_point``).
    precision_init : float or array-like (D,)
        Initial :math:`S > 0` (the authors': 1).
    learn_precision : bool
        ``precision`` (D,) is an ``nn.Parameter`` if True, else a buffer.
    dtype : torch.dtype
    """

    operating_point: Tensor
    precision: Tensor

    def __init__(
        self,
        operating_point: object,
        precision_init: float | object = 1.0,
        learn_precision: bool = True,
        dtype: torch.dtype = torch.float64,
    ) -> None:
        super().__init__()
        from ._checks import positive_scalar_or_vector

        check_flag(learn_precision, "learn_precision")
        point = as_point(operating_point, "operating_point", dtype)
        self.register_buffer("operating_point", point)
        size = point.shape[0]
        start = positive_scalar_or_vector(precision_init, "precision_init", size, "D", dtype)
        precision = start.expand(size).clone()
        register_learnable(self, "precision", precision, learn_precision)

    def forward(self, x: Tensor) -> Tensor:
        """Relevance (..., 1) of observations ``x`` (..., D)."""
        check_last_dim(x, self.operating_point.shape[0], self.operating_point.dtype)
        distance = ((x - self.operating_point).square() * self.precision).sum(dim=-1, keepdim=True)
        return relevance_of_distance(distance)

    def extra_repr(self) -> str:
        return (
            f"D={self.operating_point.shape[0]}, learn={isinstance(self.precision, nn.Parameter)}"
        )


def _layout_plan(
    obs_layout: Sequence[Any], state_dim: int
) -> tuple[tuple[str, int, int, int], ...]:
    """One entry ``(kind, state_index, column, sin_column)`` per state entry, in state order:
    ``kind`` is "plain" (observed as is in ``column``) or "angle" (cos in ``column``, sin in
    ``sin_column``), as the observation map reports them."""
    obs_map = as_observation_map(obs_layout, state_dim)
    plain = obs_map.state_columns()
    angles = {angle.state_index: angle for angle in obs_map.angle_columns()}
    plan = []
    for index in range(state_dim):
        if index in plain:
            plan.append(("plain", index, plain[index], -1))
        else:
            angle = angles[index]
            plan.append(("angle", index, angle.cos_column, angle.sin_column))
    return tuple(plan)


class ObservationDeviation(nn.Module):
    r"""The state deviation :math:`z = x - a` recovered from an observation (..., D) -> (..., S).

    A state entry observed as itself gives :math:`o_j - a_s`; an angle observed as
    :math:`(\cos\theta, \sin\theta)` gives :math:`\operatorname{wrap}(\operatorname{atan2}(\sin
    \theta, \cos\theta) - a_s) \in [-\pi, \pi)` (the wrap of
    :func:`leoc.systems.base.wrap_angle`, so the deviation is the one the systems and
    :func:`leoc.control.certify_lqr` use).

    Parameters
    ----------
    obs_layout : sequence of (kind, state_index)
        How each observation entry is built (``System.obs_layout``, or an
        :class:`~leoc.systems.observation.ObservationMap`).
    operating_state : array-like, shape (S,)
        The operating point :math:`a` in state coordinates.
    dtype : torch.dtype
    """

    operating_state: Tensor

    def __init__(
        self, obs_layout: Sequence[Any], operating_state: object, dtype: torch.dtype = torch.float64
    ) -> None:
        super().__init__()
        state = as_point(operating_state, "operating_state", dtype, "S")
        self.observation = as_observation_map(obs_layout, state.shape[0])
        self.layout = self.observation.pairs()
        self.plan = _layout_plan(self.observation, state.shape[0])
        self.register_buffer("operating_state", state)

    @property
    def obs_dim(self) -> int:
        """Observation dimension D."""
        return len(self.layout)

    @property
    def state_dim(self) -> int:
        """State dimension S."""
        return len(self.plan)

    @property
    def angle_indices(self) -> tuple[int, ...]:
        """State entries observed through cos and sin (wrapped deviations)."""
        return tuple(index for kind, index, _, _ in self.plan if kind == "angle")

    def forward(self, obs: Tensor) -> Tensor:
        """State deviation (..., S) of observations (..., D)."""
        check_last_dim(obs, self.obs_dim, self.operating_state.dtype, "obs")
        entries = []
        for kind, index, column, sin_column in self.plan:
            if kind == "plain":
                entries.append(obs[..., column] - self.operating_state[index])
            else:
                angle = torch.atan2(obs[..., sin_column], obs[..., column])
                deviation = angle - self.operating_state[index]
                entries.append(torch.remainder(deviation + math.pi, 2.0 * math.pi) - math.pi)
        return torch.stack(entries, dim=-1)


def lyapunov_matrix(P: object, size: int | None = None) -> Tensor:
    """``P`` as a float64 tensor (S, S), ``S = size`` (default: any square matrix), checked
    finite, symmetric (to :data:`SYMMETRY_RTOL`) and positive definite."""
    matrix = as_float_tensor(P, "P", torch.float64)
    if size is None:
        if matrix.ndim != 2 or matrix.shape[0] != matrix.shape[1] or matrix.shape[0] < 1:
            raise ValueError(
                f"P: expected a square matrix (S, S), found shape {tuple(matrix.shape)}"
            )
        size = matrix.shape[0]
    check_shape(matrix, "P", (size, size), "(S, S)")
    check_finite(matrix, "P")
    matrix_np = matrix.numpy()
    if not np.allclose(
        matrix_np, matrix_np.T, rtol=0.0, atol=SYMMETRY_RTOL * np.abs(matrix_np).max()
    ):
        raise ValueError(f"P must be symmetric, found {matrix_np.tolist()}")
    if float(np.linalg.eigvalsh(matrix_np)[0]) <= 0.0:
        raise ValueError(
            f"P must be positive definite, found eigenvalues "
            f"{np.linalg.eigvalsh(matrix_np).tolist()}"
        )
    return matrix


def chart_width_limit(P: np.ndarray, angle_indices: Sequence[int], rho_in: float) -> float:
    r"""Largest band width :math:`w_{max}` that keeps the band inside the angle chart.

    :math:`\min_{z : z_s = \pm\pi} z^\top P z = \pi^2 / (P^{-1})_{ss}`, so the band
    :math:`V \le (1 + w) \rho_{in}` stays off the wrap cut iff
    :math:`w < \pi^2 / ((P^{-1})_{ss} \rho_{in}) - 1` for every angle :math:`s`. ``inf``
    without angles.
    """
    if not angle_indices:
        return math.inf
    inverse = np.linalg.inv(P)
    cut = min(math.pi**2 / float(inverse[s, s]) for s in angle_indices)
    return cut / rho_in - 1.0


class FlatRegion(NamedTuple):
    r"""Where a controller is a simpler one, exactly: on the states :math:`x` with
    :math:`V(x) = z^\top P z \le` ``level`` (:math:`z = x - a`, angle entries wrapped; only where
    every angle deviation is in :math:`(-\pi, \pi)` is the wrap the identity), the controller
    equals ``inner`` in real arithmetic. The ROA relevance's flat top, where r = 1 and a hybrid
    is its linear part whatever its learned part is; a proof
    (:mod:`leoc.control.proof`) evaluates ``inner`` on the boxes it shows to lie inside.

    Attributes
    ----------
    lyapunov : Tensor (S, S)
        P, symmetric positive definite.
    operating_state : Tensor (S,)
        a.
    level : float
        The level bound (the relevance's ``rho_in``).
    angle_indices : tuple of int
        State entries whose deviation is wrapped.
    inner : callable
        Observation -> action, the controller there.
    """

    lyapunov: Tensor
    operating_state: Tensor
    level: float
    angle_indices: tuple[int, ...]
    inner: Any


class ROARelevance(nn.Module):
    r"""Relevance that is exactly 1 on a certified sublevel set :math:`\{V \le \rho_{in}\}`.

    :math:`r = 1 - S(t)`, :math:`t = \operatorname{clamp}((V / \rho_{in} - 1) / w, 0, 1)`,
    :math:`S` the quintic smootherstep; see the module docstring for the formula, the band
    width bound and the theorem. Shapes: observation (..., D) -> relevance (..., 1).

    Parameters
    ----------
    obs_layout : sequence of (kind, state_index)
        ``System.obs_layout``.
    operating_state : array-like, shape (S,)
        :math:`a` in state coordinates.
    P : array-like, shape (S, S)
        Symmetric positive definite Lyapunov matrix (the LQR design's Riccati solution at the
        hybrid's control period).
    rho_in : float
        Level of the flat top (> 0; at most the certified :math:`\rho`, which
        :func:`~leoc.policies.roa_hybrid` checks).
    width_init : float
        Initial band width :math:`w > 0` (below :math:`w_{max}` when there are angles).
    learn_width : bool
        ``width_param`` is an ``nn.Parameter`` if True, else a buffer.
    dtype : torch.dtype

    Attributes
    ----------
    max_width : float
        :math:`w_{max}` (``inf`` without angles).
    """

    lyapunov_matrix: Tensor
    rho_in: Tensor
    width_param: Tensor

    def __init__(
        self,
        obs_layout: Sequence[Any],
        operating_state: object,
        P: object,
        rho_in: float,
        width_init: float = DEFAULT_ROA_WIDTH,
        learn_width: bool = True,
        dtype: torch.dtype = torch.float64,
    ) -> None:
        super().__init__()
        check_flag(learn_width, "learn_width")
        self.deviation = ObservationDeviation(obs_layout, operating_state, dtype)
        size = self.deviation.state_dim
        matrix = lyapunov_matrix(P, size)
        matrix_np = matrix.numpy()
        for name, value in (("rho_in", rho_in), ("width_init", width_init)):
            if not isinstance(value, (int, float, np.floating)) or not 0.0 < value < math.inf:
                raise ValueError(f"{name} must be a positive finite number, found {value!r}")
        self.max_width = chart_width_limit(matrix_np, self.deviation.angle_indices, float(rho_in))
        if not width_init < self.max_width:
            raise ValueError(
                f"width_init must be below the chart's limit w_max = {self.max_width:.6g} (the "
                f"band V <= (1 + w) rho_in must end before an angle deviation of pi), found "
                f"{width_init!r}; with rho_in = {rho_in!r} choose a smaller width or rho_in"
            )
        self.register_buffer("lyapunov_matrix", matrix.to(dtype))
        self.register_buffer("rho_in", torch.tensor(float(rho_in), dtype=dtype))
        raw = torch.tensor(self._raw_width(float(width_init)), dtype=dtype)
        register_learnable(self, "width_param", raw, learn_width)

    def _raw_width(self, width: float) -> float:
        if math.isinf(self.max_width):
            return math.log(width)
        fraction = width / self.max_width
        return math.log(fraction / (1.0 - fraction))

    @property
    def width(self) -> Tensor:
        r"""Band width :math:`w` (scalar tensor): :math:`w_{max}\,\operatorname{sigmoid}` of
        ``width_param`` with angles, :math:`\exp` of it without."""
        if math.isinf(self.max_width):
            return torch.exp(self.width_param)
        return self.max_width * torch.sigmoid(self.width_param)

    def lyapunov(self, x: Tensor) -> Tensor:
        r""":math:`V(z(x)) = z^\top P z` of observations (..., D) -> (..., 1)."""
        return quadratic_form(self.deviation(x), self.lyapunov_matrix)

    def flat_region(self, inner: Any) -> FlatRegion:
        r"""The flat top :math:`\{V \le \rho_{in}\}`, where r = 1 exactly, as a
        :class:`FlatRegion` whose controller is ``inner`` (the hybrid's linear part)."""
        return FlatRegion(
            self.lyapunov_matrix,
            self.deviation.operating_state,
            float(self.rho_in),
            self.deviation.angle_indices,
            inner,
        )

    def forward(self, x: Tensor) -> Tensor:
        """Relevance (..., 1) of observations ``x`` (..., D)."""
        level = self.lyapunov(x) / self.rho_in
        t = torch.clamp((level - 1.0) / self.width, min=0.0, max=1.0)
        # Horner form of S(t) = 10 t^3 - 15 t^4 + 6 t^5 (Perlin 2002; on interval enclosures its
        # own tight rule); at t = 0 every term is an exact 0, so r = 1 exactly on the flat top.
        r = 1.0 - smootherstep(t)
        if isinstance(level, Jet) and level.ndim == 2:
            # A box whose level's enclosure stays below 1 (with a margin far above the rounding
            # of its upper end) lies in the flat top: t is 0 and r is 1 on all of it, exactly
            # (the interval rules would widen both by an ulp); the hybrid then skips H there.
            inside = (level.high < 1.0 - FLAT_TOP_MARGIN).reshape(level.shape[0], -1).all(-1)
            r = pinned_rows(r, inside, 1.0)
        return r

    def extra_repr(self) -> str:
        learned = isinstance(self.width_param, nn.Parameter)
        return (
            f"state_dim={self.deviation.state_dim}, rho_in={float(self.rho_in):.6g}, "
            f"max_width={self.max_width:.6g}, learn_width={learned}"
        )


FLAT_TOP_MARGIN = 1e-9
"""On interval enclosures a box counts as inside the ROA relevance's flat top when its level
``V / rho_in`` is below ``1 - FLAT_TOP_MARGIN`` everywhere (a margin far above the rounding of
the enclosure's upper end)."""


def _positive_number(value: object, name: str) -> float:
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float, np.floating))
        or not 0.0 < value < math.inf
    ):
        raise ValueError(f"{name}: expected a positive finite number, found {value!r}")
    return float(value)


def relevance_floor(
    obs_layout: Sequence[Any], P: object, rho: float, r_min: float, power: float = 1.0
) -> np.ndarray:
    r"""Floor :math:`f` (D,) on the paper relevance's :math:`\lambda`: every :math:`\lambda \ge f`
    gives :math:`r \ge r_{min}` on :math:`\Omega = \{x : z^\top P z \le \rho\}`.

    Derivation. :math:`r = (1 + d^p)^{-2} \ge r_{min}` iff :math:`d \le d_{max} =
    (r_{min}^{-1/2} - 1)^{1/p}` (``power`` :math:`p`; the paper's :math:`p = 1`). A plain entry
    :math:`j` of state :math:`s` adds :math:`z_s^2 / \lambda_j`; an angle :math:`s` in columns
    :math:`c, k` adds :math:`(\cos\theta - \cos a)^2 / \lambda_c + (\sin\theta - \sin a)^2 /
    \lambda_k \le \max(\lambda_c^{-1}, \lambda_k^{-1})
    \cdot 4 \sin^2(\delta / 2) \le \max(\lambda_c^{-1}, \lambda_k^{-1}) z_s^2`. Hence
    :math:`d \le z^\top \mathcal{W} z`, :math:`\mathcal{W} = \operatorname{diag}(w_s)`, and with
    :math:`z = \sqrt\rho P^{-1/2} u`, :math:`|u| \le 1`: :math:`\max_\Omega z^\top \mathcal{W} z
    = \rho \lambda_{max}(P^{-1/2} \mathcal{W} P^{-1/2}) = \rho \lambda_{max}(\mathcal{W}
    P^{-1})`. The floor takes :math:`w_s = t / (P^{-1})_{ss}` with :math:`t = d_{max} / (\rho
    \lambda_{max}(\operatorname{diag}(1 / (P^{-1})_{ss}) P^{-1}))` (so that maximum is
    :math:`d_{max}`) and :math:`f_j = 1 / w_s` for every entry of state :math:`s` (an angle's
    cos and sin share it). Any :math:`\lambda \ge f` gives a diagonal :math:`\mathcal{W}` no
    larger, and :math:`\lambda_{max}(\mathcal{W} P^{-1})` is monotone in it (Loewner order), so
    :math:`d \le d_{max}` on all of :math:`\Omega`. The bound is tight without angles (at the
    top generalised eigenvector on the boundary); :math:`f` carries a relative margin
    :data:`FLOOR_MARGIN` for rounding.

    Parameters
    ----------
    obs_layout : sequence of (kind, state_index)
        ``System.observation.to_list()``.
    P : array-like, shape (S, S)
        The LQR's Lyapunov matrix (symmetric positive definite).
    rho : float
        The proved level (> 0).
    r_min : float in (0, 1)
    power : float
        :math:`p \ge 1` of the relevance :math:`(1 + d^p)^{-2}` the floor is for.

    Returns
    -------
    numpy.ndarray, shape (D,)
    """
    power = check_relevance_power(power)
    matrix = lyapunov_matrix(P).numpy()
    size = matrix.shape[0]
    rho = _positive_number(rho, "rho")
    if isinstance(r_min, bool) or not isinstance(r_min, (int, float)) or not 0.0 < r_min < 1.0:
        raise ValueError(f"r_min: expected a number in (0, 1), found {r_min!r}")
    inverse = np.linalg.inv(matrix)
    spread = np.diag(inverse).copy()  # (P^-1)_ss
    # diag(1/c) P^-1 is similar to the symmetric diag(c)^-1/2 P^-1 diag(c)^-1/2
    peak = float(np.linalg.eigvalsh(inverse / np.sqrt(np.outer(spread, spread)))[-1])
    d_max = (float(r_min) ** -0.5 - 1.0) ** (1.0 / power)
    per_state = (1.0 + FLOOR_MARGIN) * spread * rho * peak / d_max  # 1 / w_s
    floor = np.empty(as_observation_map(obs_layout, size).obs_dim)
    for kind, index, column, sin_column in _layout_plan(obs_layout, size):
        floor[column] = per_state[index]
        if kind == "angle":
            floor[sin_column] = per_state[index]
    return floor


class FlooredRelevance(nn.Module):
    r"""The paper's relevance with :math:`\lambda` held above a floor :math:`f`.

    .. math::

        r(x) = \frac{1}{(1 + d(x)^p)^2}, \qquad d(x) = \sum_{j=1}^{D} \frac{(x_j - a_j)^2}
        {\lambda_j}, \qquad \lambda_j = f_j (1 + e^{q_j}),

    :math:`q` (``log_excess``) learnable: whatever training does, :math:`\lambda > f`, so with the
    floor of :func:`relevance_floor` :math:`r \ge r_{min}` on the LQR's proved set (module
    docstring). :math:`d(a) = 0` exactly, so :math:`r(a) = 1`.

    Parameters
    ----------
    operating_point : array-like, shape (D,)
        :math:`a` in observation coordinates (buffer ``operating_point``).
    floor : array-like, shape (D,)
        :math:`f > 0` (buffer ``floor``).
    lambda_init : float or array-like (D,)
        Initial :math:`\lambda > 0`, raised to :math:`\max(\lambda_{init}, 2 f)` entrywise.
    learn_lambda : bool
        ``log_excess`` (D,) is an ``nn.Parameter`` if True, else a buffer.
    dtype : torch.dtype
    power : float
        :math:`p \ge 1` (1: the paper's relevance); the floor must be
        :func:`relevance_floor`'s for the same :math:`p`.
    """

    operating_point: Tensor
    floor: Tensor
    log_excess: Tensor

    def __init__(
        self,
        operating_point: object,
        floor: object,
        lambda_init: float | object = 1.0,
        learn_lambda: bool = True,
        dtype: torch.dtype = torch.float64,
        power: float = 1.0,
    ) -> None:
        super().__init__()
        from ._checks import check_positive, positive_scalar_or_vector

        check_flag(learn_lambda, "learn_lambda")
        self.power = check_relevance_power(power)
        point = as_point(operating_point, "operating_point", torch.float64)
        size = point.shape[0]
        lower = as_float_tensor(floor, "floor", torch.float64)
        check_shape(lower, "floor", (size,), "(D,)")
        check_positive(lower, "floor")
        start = positive_scalar_or_vector(lambda_init, "lambda_init", size, "D", torch.float64)
        start = torch.maximum(start.expand(size), 2.0 * lower)
        excess = torch.log(start / lower - 1.0).to(dtype)
        self.register_buffer("operating_point", point.to(dtype))
        self.register_buffer("floor", lower.to(dtype))
        register_learnable(self, "log_excess", excess, learn_lambda)

    @property
    def lambda_(self) -> Tensor:
        r""":math:`\lambda = f (1 + e^{q})`, shape (D,)."""
        return self.floor * (1.0 + torch.exp(self.log_excess))

    def forward(self, x: Tensor) -> Tensor:
        """Relevance (..., 1) of observations ``x`` (..., D)."""
        check_last_dim(x, self.operating_point.shape[0], self.operating_point.dtype)
        distance = ((x - self.operating_point).square() / self.lambda_).sum(dim=-1, keepdim=True)
        return relevance_of_distance(distance, self.power)

    def extra_repr(self) -> str:
        learned = isinstance(self.log_excess, nn.Parameter)
        return f"D={self.operating_point.shape[0]}, learn_lambda={learned}, power={self.power:g}"


class LyapunovRelevance(nn.Module):
    r"""Relevance :math:`r = (1 + \tilde V / (\lambda \rho))^{-2}` with the LQR's Lyapunov
    function, written smoothly on the observation manifold, as the distance.

    :math:`\tilde V = y^\top P y + \sum_{s \text{ angle}} P_{ss} (1 - \cos\delta_s)^2`, :math:`y`
    the plain deviations and, for angles, :math:`\sin\delta_s`; see the module docstring for the
    formula and why. Shapes: observation (..., D) -> relevance (..., 1).

    Parameters
    ----------
    obs_layout : sequence of (kind, state_index)
        ``System.observation.to_list()``.
    operating_point : array-like, shape (D,)
        :math:`a` in observation coordinates (an angle's :math:`(\cos a_s, \sin a_s)` on the
        unit circle).
    P : array-like, shape (S, S)
        Symmetric positive definite Lyapunov matrix of the LQR at the hybrid's period.
    rho : float
        The LQR's proved level (> 0).
    lambda_init : float
        Initial scale :math:`\lambda > 0` (one number).
    learn_lambda : bool
        ``log_lambda`` (a scalar) is an ``nn.Parameter`` if True, else a buffer.
    dtype : torch.dtype
    """

    operating_point: Tensor
    lyapunov_matrix: Tensor
    rho: Tensor
    log_lambda: Tensor

    def __init__(
        self,
        obs_layout: Sequence[Any],
        operating_point: object,
        P: object,
        rho: float,
        lambda_init: float = 1.0,
        learn_lambda: bool = True,
        dtype: torch.dtype = torch.float64,
    ) -> None:
        super().__init__()
        check_flag(learn_lambda, "learn_lambda")
        matrix = lyapunov_matrix(P)
        point = as_float_tensor(operating_point, "operating_point", torch.float64)
        obs_map = as_observation_map(obs_layout, matrix.shape[0])
        self.plan = _layout_plan(obs_map, matrix.shape[0])
        check_shape(point, "operating_point", (obs_map.obs_dim,), "(D,) from obs_layout")
        check_finite(point, "operating_point")
        for kind, _, column, sin_column in self.plan:
            radius = float(point[column] ** 2 + point[sin_column] ** 2) if kind == "angle" else 1.0
            if abs(radius - 1.0) > UNIT_CIRCLE_ATOL:
                raise ValueError(
                    f"operating_point: expected (cos a, sin a) on the unit circle in columns "
                    f"{column}, {sin_column}, found cos^2 + sin^2 = {radius!r}"
                )
        log_lambda = torch.tensor(
            math.log(_positive_number(lambda_init, "lambda_init")), dtype=torch.float64
        )
        self.register_buffer("operating_point", point.to(dtype))
        self.register_buffer("lyapunov_matrix", matrix.to(dtype))
        self.register_buffer("rho", torch.tensor(_positive_number(rho, "rho"), dtype=dtype))
        register_learnable(self, "log_lambda", log_lambda.to(dtype), learn_lambda)

    @property
    def lambda_(self) -> Tensor:
        r""":math:`\lambda = \exp(\text{log\_lambda})` (scalar tensor)."""
        return torch.exp(self.log_lambda)

    def lyapunov(self, x: Tensor) -> Tensor:
        r""":math:`\tilde V(x)` of observations (..., D) -> (..., 1) (see the module docstring)."""
        check_last_dim(x, self.operating_point.shape[0], self.operating_point.dtype)
        deviation = x - self.operating_point
        entries, extra = [], []
        for kind, index, column, sin_column in self.plan:
            if kind == "plain":
                entries.append(deviation[..., column])
                continue
            d_cos, d_sin = deviation[..., column], deviation[..., sin_column]
            cos_a, sin_a = self.operating_point[column], self.operating_point[sin_column]
            entries.append(d_sin * cos_a - d_cos * sin_a)  # sin(delta)
            one_minus_cos = 0.5 * (d_cos.square() + d_sin.square())
            extra.append(self.lyapunov_matrix[index, index] * one_minus_cos.square())
        y = torch.stack(entries, dim=-1)
        value = ((y @ self.lyapunov_matrix) * y).sum(dim=-1)
        for term in extra:
            value = value + term
        return value.unsqueeze(-1)

    def forward(self, x: Tensor) -> Tensor:
        """Relevance (..., 1) of observations ``x`` (..., D)."""
        distance = self.lyapunov(x) / (self.lambda_ * self.rho)
        return relevance_of_distance(distance)

    def extra_repr(self) -> str:
        learned = isinstance(self.log_lambda, nn.Parameter)
        return f"state_dim={len(self.plan)}, rho={float(self.rho):.6g}, learn_lambda={learned}"
