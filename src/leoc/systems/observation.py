r"""The observation map: the one place that knows how an observation is built from a state.

An observation layout is a sequence of :class:`ObsComponent` ``(kind, state_index)``, one per
observation entry, with ``kind`` one of :data:`OBS_KINDS`:

* ``"state"``: the state entry as is, :math:`o_k = x_i`;
* ``"cos"`` and ``"sin"``: :math:`o_k = \cos x_i` and :math:`o_k = \sin x_i` (the trigonometric
  augmentation of an angle; an angle is observed through both, never as itself).

:class:`ObservationMap` owns everything that depends on those kinds: the map itself (numpy-free,
differentiable torch), its inverse (angles by atan2), the bounds of its gymnasium observation
space, its exact Gaussian moments (PILCO), its Jacobian at a state (the LQR's observation gain)
and the columns of each angle. No other module interprets the kind strings.

Shapes: ``B`` batch (any leading dimensions), ``S`` state dimension, ``O`` observation dimension.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Sequence
from typing import Any, NamedTuple

import numpy as np
import torch
from torch import Tensor

STATE = "state"
COS = "cos"
SIN = "sin"
#: How an observation entry is made from a state entry: itself, its cosine or its sine.
OBS_KINDS: tuple[str, ...] = (STATE, COS, SIN)
HALF_PI = 0.5 * math.pi
TRIG_BOUND = 1.0  # |cos|, |sin| <= 1: the gymnasium bound of a trigonometric entry


class ObsComponent(NamedTuple):
    """How one observation entry is made from the state: ``kind`` in :data:`OBS_KINDS`."""

    kind: str
    state_index: int


class AngleColumns(NamedTuple):
    """The observation columns of one angle state entry: its cosine and its sine."""

    state_index: int
    cos_column: int
    sin_column: int


class ObservationMoments(NamedTuple):
    """Moments of ``o = h(x)`` for Gaussian x: ``mean`` (O,), ``cov`` (O, O) and
    ``io`` = Sigma_x^-1 Cov[x, o] (S, O) (PILCO's coefficient form)."""

    mean: Tensor
    cov: Tensor
    io: Tensor


def state_entry(index: int) -> ObsComponent:
    """Layout entry observing state entry ``index`` as is."""
    return ObsComponent(STATE, index)


def angle_entries(index: int) -> tuple[ObsComponent, ObsComponent]:
    """Layout entries observing angle ``index`` through ``(cos, sin)``."""
    return ObsComponent(COS, index), ObsComponent(SIN, index)


class _MomentConstants(NamedTuple):
    """Constant tensors of a layout's moments (O entries over S state entries)."""

    index: Tensor  # (O,) state entry of each observation entry
    trig: Tensor  # (O,) bool, sin or cos entry
    both_trig: Tensor  # (O, O) bool
    phase: Tensor  # (O,) pi/2 for cos (cos x = sin(x + pi/2)), else 0
    selector: Tensor  # (S, O) one-hot: selector[i, k] = 1 if entry k reads state i


def sine_product_cov(e_sin: Tensor, e_cos: Tensor, cov: Tensor) -> Tensor:
    r"""Covariance of :math:`\sin a_i` and :math:`\sin a_j` for jointly Gaussian ``a``.

    With :math:`C = \operatorname{Cov}[a]`, :math:`E[\sin a_i] = e^{-C_{ii}/2} \sin \mu_i` and
    :math:`E[\cos a_i] = e^{-C_{ii}/2} \cos \mu_i` (``e_sin``, ``e_cos``), the product rule
    :math:`\sin a \sin b = \tfrac12 (\cos(a - b) - \cos(a + b))` gives

    .. math::

        \operatorname{Cov}[\sin a_i, \sin a_j] = E[\cos a_i] E[\cos a_j] \sinh C_{ij}
            + E[\sin a_i] E[\sin a_j] (\cosh C_{ij} - 1).

    :math:`\cosh C - 1` is evaluated as :math:`2 \sinh^2(C / 2)`: no cancellation when C is
    small (a collapsed covariance near the operating point), unlike the difference of the two
    cosine terms. Exactly symmetric for a symmetric ``cov``. Shapes: (K,), (K,), (K, K).
    Shared with PILCO's sin-squash moments (:mod:`leoc.pilco.moments`).
    """
    cosh_minus_one = 2.0 * torch.sinh(0.5 * cov).square()
    return (e_cos[:, None] * e_cos[None, :]) * torch.sinh(cov) + (
        e_sin[:, None] * e_sin[None, :]
    ) * cosh_minus_one


class ObservationMap:
    """The observation map ``o = h(x)`` of a layout of :class:`ObsComponent`.

    Parameters
    ----------
    layout : sequence of (kind, state_index)
        One entry per observation column (``ObsComponent`` or plain pairs, e.g. read back from
        JSON).
    state_dim : int, optional
        S. Defaults to ``1 + max(state_index)``.
    complete : bool
        Require every state entry to be observed, either as itself or through both its cos and
        sin (so that :meth:`invert` exists; what a ``System`` needs). ``False`` allows partial
        layouts (PILCO's moments of a few features).

    Raises
    ------
    ValueError
        On an unknown kind, an index outside ``[0, S)``, a state entry observed neither as
        itself nor through both cos and sin, or an angle observed also as itself.
    """

    def __init__(
        self, layout: Iterable[Sequence[Any]], state_dim: int | None = None, complete: bool = True
    ) -> None:
        components = []
        for column, entry in enumerate(layout):
            if len(entry) != 2:
                raise ValueError(
                    f"layout[{column}]: expected (kind, state_index), found {tuple(entry)!r}"
                )
            kind, index = entry
            if (
                kind not in OBS_KINDS
                or isinstance(index, bool)
                or not isinstance(index, (int, np.integer))
            ):
                raise ValueError(
                    f"layout[{column}]: expected (kind, state_index) with kind in {OBS_KINDS} "
                    f"and an integer index, found {tuple(entry)!r}"
                )
            components.append(ObsComponent(str(kind), int(index)))
        if not components:
            raise ValueError("layout: expected at least one observation entry, found none")
        size = 1 + max(c.state_index for c in components) if state_dim is None else state_dim
        self.layout: tuple[ObsComponent, ...] = tuple(components)
        self.state_dim = int(size)
        self.complete = self._check_complete(strict=complete)
        self._index = torch.tensor([c.state_index for c in self.layout])
        self._trig = torch.tensor([c.kind != STATE for c in self.layout])
        self._phase = [HALF_PI if c.kind == COS else 0.0 for c in self.layout]
        self._moment_constants: dict[torch.dtype, _MomentConstants] = {}

    def _check_complete(self, strict: bool) -> bool:
        """Check indices and duplicates; return whether every state entry is observed (raise
        if not and ``strict``)."""
        seen: dict[int, set[str]] = {}
        for column, component in enumerate(self.layout):
            if not 0 <= component.state_index < self.state_dim:
                raise ValueError(
                    f"layout[{column}]: expected 0 <= state_index < {self.state_dim}, found "
                    f"{component.state_index}"
                )
            kinds = seen.setdefault(component.state_index, set())
            if component.kind in kinds:
                raise ValueError(f"layout: {component!r} appears twice")
            kinds.add(component.kind)
        for index in range(self.state_dim):
            kinds = seen.get(index, set())
            if kinds not in ({STATE}, {COS, SIN}):
                if not strict:
                    return False
                raise ValueError(
                    f"layout: state entry {index} must be observed as itself or as both its cos "
                    f"and sin, found {sorted(kinds) or 'nothing'}"
                )
        return True

    def __repr__(self) -> str:
        return f"ObservationMap({list(map(tuple, self.layout))!r}, state_dim={self.state_dim})"

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, ObservationMap)
            and self.layout == other.layout
            and self.state_dim == other.state_dim
        )

    def __hash__(self) -> int:
        return hash((self.layout, self.state_dim))

    # ------------------------------------------------------------------ structure
    @property
    def obs_dim(self) -> int:
        """O."""
        return len(self.layout)

    def to_list(self) -> list[list[Any]]:
        """JSON-friendly layout ``[[kind, state_index], ...]`` (read back by the constructor)."""
        return [[c.kind, c.state_index] for c in self.layout]

    def pairs(self) -> list[tuple[str, int]]:
        """The layout as plain ``(kind, state_index)`` tuples."""
        return [(c.kind, c.state_index) for c in self.layout]

    @property
    def angle_indices(self) -> tuple[int, ...]:
        """State entries observed through cos and sin, in state order."""
        return tuple(sorted({c.state_index for c in self.layout if c.kind != STATE}))

    def angle_columns(self) -> tuple[AngleColumns, ...]:
        """The cos and sin columns of every angle, in state order."""
        columns: dict[int, dict[str, int]] = {}
        for column, component in enumerate(self.layout):
            columns.setdefault(component.state_index, {})[component.kind] = column
        return tuple(
            AngleColumns(index, columns[index][COS], columns[index][SIN])
            for index in self.angle_indices
        )

    def state_columns(self) -> dict[int, int]:
        """``{state_index: column}`` of the entries observed as themselves."""
        return {c.state_index: k for k, c in enumerate(self.layout) if c.kind == STATE}

    def labels(self, state_names: Sequence[str]) -> list[str]:
        """Readable names of the observation entries, e.g. ``["cos(theta)", "theta_dot"]``."""
        names = [state_names[c.state_index] for c in self.layout]
        return [
            name if c.kind == STATE else f"{c.kind}({name})"
            for c, name in zip(self.layout, names, strict=True)
        ]

    def bounds(self) -> np.ndarray:
        """Upper bounds ``high`` (O,) of the observation (the space is ``[-high, high]``):
        1 for a cos or sin entry, ``inf`` for a plain state entry."""
        return np.array([TRIG_BOUND if c.kind != STATE else np.inf for c in self.layout])

    # ------------------------------------------------------------------ the map
    def observe(self, state: Tensor) -> Tensor:
        """Observation (..., O) of states (..., S); differentiable."""
        if state.shape[-1] != self.state_dim:
            raise ValueError(
                f"state: expected trailing dimension {self.state_dim}, found {tuple(state.shape)}"
            )
        columns = []
        for component in self.layout:
            value = state[..., component.state_index]
            if component.kind == COS:
                value = torch.cos(value)
            elif component.kind == SIN:
                value = torch.sin(value)
            columns.append(value)
        return torch.stack(columns, dim=-1)

    def invert(self, obs: Tensor) -> Tensor:
        """State (..., S) of observations (..., O): angles by ``atan2(sin, cos)`` in
        ``(-pi, pi]``, plain entries copied."""
        if obs.shape[-1] != self.obs_dim:
            raise ValueError(
                f"obs: expected trailing dimension {self.obs_dim}, found {tuple(obs.shape)}"
            )
        if not self.complete:
            raise ValueError(f"invert: {self!r} does not observe every state entry")
        entries: list[Tensor | None] = [None] * self.state_dim
        for index, column in self.state_columns().items():
            entries[index] = obs[..., column]
        for angle in self.angle_columns():
            entries[angle.state_index] = torch.atan2(
                obs[..., angle.sin_column], obs[..., angle.cos_column]
            )
        return torch.stack(entries, dim=-1)  # type: ignore[arg-type]

    def jacobian(self, state: Any) -> np.ndarray:
        r"""Jacobian :math:`J = \partial h / \partial x` (O, S) at one state (S,):
        1 for a plain entry, :math:`-\sin x_i` for ``cos``, :math:`\cos x_i` for ``sin``."""
        state_arr = np.asarray(state, dtype=float).reshape(-1)
        if state_arr.shape != (self.state_dim,):
            raise ValueError(f"state: expected shape ({self.state_dim},), found {state_arr.shape}")
        jac = np.zeros((self.obs_dim, self.state_dim))
        for column, component in enumerate(self.layout):
            value = state_arr[component.state_index]
            if component.kind == COS:
                jac[column, component.state_index] = -np.sin(value)
            elif component.kind == SIN:
                jac[column, component.state_index] = np.cos(value)
            else:
                jac[column, component.state_index] = 1.0
        return jac

    def linear_gain(self, K: np.ndarray, operating_state: Any) -> np.ndarray:
        r"""The observation gain ``W`` (A, O) of a state gain ``K`` (A, S) at ``a``:
        :math:`W = -K J(a)^\top`.

        Every column of :math:`J` has unit norm (:math:`\sin^2 + \cos^2 = 1` for an angle) and
        each row one non-zero entry, so :math:`J^\top J = I` and :math:`W J(a) = -K`: the
        policy :math:`G(o) = W o + b` has the Jacobian :math:`-K` in the state at ``a``. At
        :math:`a_i = 0` the gain of an angle acts on its sine only.
        """
        return -np.asarray(K, dtype=float) @ self.jacobian(operating_state).T

    # ------------------------------------------------------------------ Gaussian moments
    def _constants(self, dtype: torch.dtype) -> _MomentConstants:
        """Constant tensors of the moments, built once per dtype (never written to)."""
        if dtype not in self._moment_constants:
            trig = self._trig
            phase = torch.tensor(self._phase, dtype=dtype)
            selector = torch.nn.functional.one_hot(self._index, self.state_dim).to(dtype).T
            self._moment_constants[dtype] = _MomentConstants(
                self._index, trig, trig[:, None] & trig[None, :], phase, selector
            )
        return self._moment_constants[dtype]

    def moments(self, mean: Tensor, cov: Tensor) -> ObservationMoments:
        r"""Exact moments of ``h(x)`` for :math:`x \sim \mathcal N(\mu, \Sigma)`.

        Every trigonometric entry is written :math:`\sin(x_i + \varphi)` (``cos`` has
        :math:`\varphi = \pi/2`). Then, exactly,

        .. math::

            E[\sin(x_i + \varphi)] = e^{-\Sigma_{ii}/2} \sin(\mu_i + \varphi), \qquad
            \operatorname{Cov}[x, \sin(x_i + \varphi)] = \Sigma_{:i}\, e^{-\Sigma_{ii}/2}
                \cos(\mu_i + \varphi),

        the second by Stein's lemma (which also gives the covariance of a trigonometric and a
        plain entry), and the covariance of two trigonometric entries by
        :func:`sine_product_cov`.

        Shapes: ``mean`` (S,), ``cov`` (S, S) (symmetric) -> mean (O,), cov (O, O), io (S, O).
        """
        if mean.shape[-1] != self.state_dim:
            raise ValueError(f"mean: expected {self.state_dim} entries, found {tuple(mean.shape)}")
        const = self._constants(mean.dtype)
        mu = mean[const.index] + const.phase
        sub_cov = cov[const.index[:, None], const.index[None, :]]  # (O, O) of the state entries
        damp = torch.exp(-0.5 * sub_cov.diagonal())
        e_sin, e_cos = damp * torch.sin(mu), damp * torch.cos(mu)
        out_mean = torch.where(const.trig, e_sin, mu)  # plain entries have phase 0
        slope = torch.where(const.trig, e_cos, 1.0)  # E[d o_k / d x_i]
        # Any pair with at least one plain entry: Stein's lemma gives Sigma_ij E[o_i'] E[o_j'].
        stein_cov = sub_cov * (slope[:, None] * slope[None, :])
        trig_cov = sine_product_cov(e_sin, e_cos, sub_cov)
        out_cov = torch.where(const.both_trig, trig_cov, stein_cov)
        return ObservationMoments(out_mean, out_cov, const.selector * slope[None, :])


def as_observation_map(
    layout: Any, state_dim: int | None = None, complete: bool = True
) -> ObservationMap:
    """``layout`` as an :class:`ObservationMap` (an existing map is returned as is; plain
    layouts are built once per ``(layout, state_dim, complete)`` and cached, for hot loops)."""
    if isinstance(layout, ObservationMap):
        return layout
    key = tuple((str(kind), int(index)) for kind, index in layout)
    return _cached_map(key, state_dim, complete)


@functools.lru_cache(maxsize=64)
def _cached_map(
    layout: tuple[tuple[str, int], ...], state_dim: int | None, complete: bool
) -> ObservationMap:
    return ObservationMap(layout, state_dim, complete)
