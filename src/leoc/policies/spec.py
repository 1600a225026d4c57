r"""A LEOC hybrid as data: what the user chooses, what the plant fixes, one builder for all.

Three pieces, in the order a run uses them:

1. :class:`HybridSpec`, frozen: the choices that make a hybrid (which relevance design, its
   parameters and what training may change). Validated once, where it is built; saved with a
   run (:meth:`HybridSpec.to_dict`) and read back (:meth:`HybridSpec.from_dict`).
2. :class:`HybridDesign`, frozen: what the plant and the LQR fix for that spec: the linear part
   :math:`G(o) = W o + b` in physical units, the operating point :math:`a` in observation
   coordinates and the relevance design's own data (for the ROA relevance: the observation
   layout, the operating state, the Lyapunov matrix :math:`P` and the flat top's level
   :math:`\rho_{in}` from the LQR's certificate; for the Lyapunov relevance: the layout,
   :math:`P` and the proved level :math:`\rho`; for the paper relevance with ``r_min``: the
   floor on :math:`\Lambda`). Plain numbers, so a learner that rebuilds its
   networks from saved keywords (Stable-Baselines3) rebuilds the same hybrid without the system.
   :func:`hybrid_design` resolves it from a system, an LQR design and a spec.
3. :func:`build_hybrid`: the :class:`~leoc.policies.HybridPolicy` of a spec, a design and a
   learned part :math:`H`, in physical units or in a learner's normalised action units. PILCO,
   DDPG/TD3 and SAC all build their hybrids here.

A relevance design is one class with a ``name`` in :data:`RELEVANCE_DESIGNS` (``paper``: the
paper's :math:`r = (1 + d)^{-2}`, with ``r_min`` its :math:`\Lambda` floored so that
:math:`r \ge r_{min}` on the LQR's proved region; ``roa``: exactly 1 on the LQR's certified
region of attraction; ``lyapunov``: :math:`(1 + d)^{-2}` with the LQR's Lyapunov function as
:math:`d`): it checks the spec fields it reads, resolves its data from the plant
(:meth:`RelevanceDesign.resolve`) and builds its relevance (:meth:`RelevanceDesign.build`).
Adding a design is one such class, one entry in :data:`RELEVANCE_DESIGNS` and, when it has a
parameter of its own, one :class:`HybridSpec` field.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
import torch
from torch import nn

from .hybrid import HybridPolicy, lqr_certificate
from .linear import LinearController
from .relevance import (
    DEFAULT_ROA_WIDTH,
    RELEVANCE_PARAMETRISATIONS,
    FlooredRelevance,
    LyapunovRelevance,
    PaperRelevance,
    PrecisionRelevance,
    ROARelevance,
    check_relevance_power,
    relevance_floor,
)

__all__ = [
    "DEFAULT",
    "DEFAULT_RELEVANCE_POWER",
    "DEFAULT_R_MIN",
    "LEGACY_FIELD_VALUES",
    "RELEVANCE_DESIGNS",
    "HybridDesign",
    "HybridSpec",
    "LyapunovRelevanceDesign",
    "PaperRelevanceDesign",
    "ROARelevanceDesign",
    "RelevanceDesign",
    "as_hybrid_spec",
    "build_hybrid",
    "hybrid_design",
    "legacy_hybrid_config",
    "roa_hybrid",
    "with_hybrid_overrides",
]


def _positive(value: object, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < math.inf:
        raise ValueError(f"{name}: expected a positive finite number, found {value!r}")
    return float(value)


def _flag(value: object, name: str) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"{name}: expected a bool, found {value!r}")
    return value


DEFAULT = "default"
"""A :class:`HybridSpec` field's value meaning "the default of the chosen relevance design"."""
DEFAULT_R_MIN = 0.5
"""The paper relevance's default floor: :math:`r \\ge 0.5` on the LQR's proved region."""
DEFAULT_RELEVANCE_POWER = 2.0
"""The paper relevance's default :math:`p` of :math:`r = (1 + d^p)^{-2}`."""
LEGACY_FIELD_VALUES: dict[str, Any] = {
    "r_min": None,
    "relevance_lr_scale": 1.0,
    "relevance_power": 1.0,
}
"""The value every run had of a :class:`HybridSpec` field added after specs were first saved:
what a saved spec without that field reads as (:meth:`HybridSpec.from_dict`)."""


@dataclasses.dataclass(frozen=True)
class HybridSpec:
    r"""The choices that make a LEOC hybrid, validated at construction.

    Attributes
    ----------
    relevance : str
        Name of the relevance design in :data:`RELEVANCE_DESIGNS`: ``"paper"`` (default,
        :math:`r = (1 + d)^{-2}`, Zhang & Capel eq. 5), ``"roa"`` (exactly 1 on the LQR's
        certified region of attraction, :class:`~leoc.policies.ROARelevance`) or
        ``"lyapunov"`` (:math:`r = (1 + \tilde V / (\lambda \rho))^{-2}`, the LQR's Lyapunov
        function as the distance, :class:`~leoc.policies.LyapunovRelevance`).
    relevance_parametrisation : {"log_lambda", "precision"}
        How the paper's relevance holds its weights: :math:`\lambda = e^{\ell}` (positive,
        default) or the precision :math:`S = \Lambda^{-1}` itself, unconstrained
        (:class:`~leoc.policies.PrecisionRelevance`, nrjc/LEOC's DDPG actor).
    lambda_init : float or tuple of float
        Initial diagonal of :math:`\Lambda` (> 0; the paper: 1, the identity); with ``r_min``
        raised to twice the floor where below it. Lyapunov relevance: the initial scale
        :math:`\lambda` of :math:`\tilde V / (\lambda \rho)`, one number (1: :math:`d = 1`
        where :math:`\tilde V = \rho`, near the proved set's boundary).
    learn_lambda : bool
        Whether training changes :math:`\Lambda` (or :math:`S`, or the Lyapunov relevance's
        :math:`\lambda`).
    rho_in_fraction : float in (0, 1]
        ROA relevance: the flat top's level :math:`\rho_{in}` as a fraction of the certified
        :math:`\rho`.
    width_init : float
        ROA relevance: the initial band width :math:`w > 0` over which :math:`r` falls to 0.
    learn_width : bool
        ROA relevance: whether training changes the band width.
    r_min : float in (0, 1), optional
        Paper relevance (``log_lambda``): a floor on :math:`\Lambda` such that
        :math:`r \ge r_{min}` on the LQR's proved region of attraction :math:`\{V \le \rho\}`
        (:class:`~leoc.policies.FlooredRelevance`, :func:`~leoc.policies.relevance_floor`);
        None: no floor (the paper's). Default: :data:`DEFAULT_R_MIN` (0.5) with the paper
        relevance held as log lambda, None with any other design. Not with the ``precision``
        parametrisation (no floor on an unconstrained :math:`S`) nor the Lyapunov relevance;
        the ROA relevance ignores it.
    relevance_lr_scale : float
        The relevance's parameters train in their own optimiser group, at the actor's learning
        rate times this (> 0; default 1: one group, as before). Stable-Baselines3 learners only.
    relevance_power : float
        Paper relevance (``log_lambda``, floored or not): :math:`p \ge 1` of
        :math:`r = (1 + d^p)^{-2}` (:func:`~leoc.policies.relevance_of_distance`); 1: the
        paper's. Default: :data:`DEFAULT_RELEVANCE_POWER` (2) with the paper relevance held as
        log lambda, 1 with any other design. With :math:`p = 2` the learned part leaks into the
        LQR's neighbourhood at fourth order in the deviation instead of second. Not with the
        ``precision`` parametrisation, the ROA or the Lyapunov relevance.

    The defaults of ``r_min`` and ``relevance_power`` (issue 40's ablation,
    ``results/relevance-ablation``): the paper's relevance learned as it is (``r_min=None,
    relevance_power=1``) left its LQR's impulse response by 2-400 % on 44 of 45 trained
    hybrids; floored at 0.5 with :math:`p = 2` it keeps it within 2 %. Pass
    ``r_min=None, relevance_power=1`` for the paper's relevance as published. A field left at
    its default follows the design: :meth:`replace` with another ``relevance`` or
    ``relevance_parametrisation`` resolves it again.

    Raises
    ------
    ValueError
        Naming the field, the expectation and what was found.
    """

    relevance: str = "paper"
    relevance_parametrisation: str = "log_lambda"
    lambda_init: float | tuple[float, ...] = 1.0
    learn_lambda: bool = True
    rho_in_fraction: float = 1.0
    width_init: float = DEFAULT_ROA_WIDTH
    learn_width: bool = True
    r_min: float | None | str = DEFAULT
    relevance_lr_scale: float = 1.0
    relevance_power: float | str = DEFAULT
    _defaulted: frozenset[str] = dataclasses.field(
        default=frozenset(), init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        if self.relevance not in RELEVANCE_DESIGNS:
            raise ValueError(
                f"relevance: expected one of {tuple(RELEVANCE_DESIGNS)}, found {self.relevance!r}"
            )
        self._resolve_defaults()
        if isinstance(self.lambda_init, (list, tuple)):
            values = tuple(_positive(value, "lambda_init") for value in self.lambda_init)
            object.__setattr__(self, "lambda_init", values)
        else:
            _positive(self.lambda_init, "lambda_init")
        for name in ("learn_lambda", "learn_width"):
            _flag(getattr(self, name), name)
        _positive(self.relevance_lr_scale, "relevance_lr_scale")
        object.__setattr__(self, "relevance_power", check_relevance_power(self.relevance_power))
        if self.r_min is not None:
            value = self.r_min
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < 1:
                raise ValueError(f"r_min: expected None or a number in (0, 1), found {value!r}")
        # every design's fields are checked, whichever design is chosen: a spec saved with a
        # bad value for another design would fail only once someone switched to it
        for design in RELEVANCE_DESIGNS.values():
            design.check(self)

    def _resolve_defaults(self) -> None:
        """Give the fields left at :data:`DEFAULT` the value their design takes (class
        docstring) and remember which they were, for :meth:`replace`."""
        floored = self.relevance == "paper" and self.relevance_parametrisation == "log_lambda"
        values = {
            "r_min": DEFAULT_R_MIN if floored else None,
            "relevance_power": DEFAULT_RELEVANCE_POWER if floored else 1.0,
        }
        defaulted = set(self._defaulted)
        for name, value in values.items():
            if isinstance(getattr(self, name), str) and getattr(self, name) == DEFAULT:
                object.__setattr__(self, name, value)
                defaulted.add(name)
        object.__setattr__(self, "_defaulted", frozenset(defaulted))

    @property
    def design(self) -> RelevanceDesign:
        """The relevance design this spec names."""
        return RELEVANCE_DESIGNS[self.relevance]

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        """Every field, in order (the settings a run's overrides may name)."""
        return tuple(field.name for field in dataclasses.fields(cls) if field.init)

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly dict of every field, defaults resolved (tuples become lists)."""
        data = {name: getattr(self, name) for name in self.field_names()}
        if isinstance(self.lambda_init, tuple):
            data["lambda_init"] = list(self.lambda_init)
        return data

    @classmethod
    def check_keys(cls, data: Mapping[str, Any]) -> dict[str, Any]:
        """``data`` as a dict, checked to name fields only (an unknown key is an error)."""
        unknown = sorted(set(data) - set(cls.field_names()))
        if unknown:
            raise ValueError(
                f"hybrid spec: unknown fields {unknown}; expected some of {list(cls.field_names())}"
            )
        return dict(data)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> HybridSpec:
        """Inverse of :meth:`to_dict`, for saved specs: a field missing from ``data`` was saved
        before it existed and takes the value every run had then (:data:`LEGACY_FIELD_VALUES`),
        not today's default; an unknown key is an error naming it."""
        return cls(**{**LEGACY_FIELD_VALUES, **cls.check_keys(data)})

    def replace(self, **changes: Any) -> HybridSpec:
        """A copy with ``changes`` applied (and validated); fields left at their default follow
        a changed design (class docstring)."""
        kept = {name: DEFAULT for name in self._defaulted if name not in changes}
        return dataclasses.replace(self, **kept, **changes)


def as_hybrid_spec(value: object) -> HybridSpec | None:
    """A learner config's ``hybrid``: None (or False) for a baseline, ``True`` for the default
    :class:`HybridSpec`, a spec, or its dict.

    Raises
    ------
    ValueError
        On anything else, naming ``hybrid``.
    """
    if value is None or value is False:
        return None
    if value is True:
        return HybridSpec()
    if isinstance(value, HybridSpec):
        return value
    if isinstance(value, Mapping):
        return HybridSpec(**HybridSpec.check_keys(value))
    raise ValueError(
        f"hybrid: expected None (a baseline), True, a HybridSpec or its dict, found {value!r}"
    )


def with_hybrid_overrides(hybrid: object, overrides: dict[str, Any]) -> HybridSpec | None:
    """``hybrid`` (see :func:`as_hybrid_spec`) with the :class:`HybridSpec` fields named in a
    learner's keyword ``overrides`` applied, those keys *popped* from ``overrides``.

    A baseline (None) has no hybrid, so those fields are dropped, once checked (a bad value is
    an error for every kind of run): a variant's or a study's settings hold for every kind of
    run of a learner (the authors' DDPG settings name the relevance's parametrisation for the
    baseline too).
    """
    changes = {name: overrides.pop(name) for name in HybridSpec.field_names() if name in overrides}
    spec = as_hybrid_spec(hybrid)
    if spec is None:
        HybridSpec(**changes)  # checked, then dropped
        return None
    return spec.replace(**changes)


LEGACY_FIELD_NAMES = {"roa_rho_fraction": "rho_in_fraction", "roa_width": "width_init"}
"""Names of :class:`HybridSpec` fields in run configs saved before it existed."""


def legacy_hybrid_config(data: Mapping[str, Any]) -> dict[str, Any]:
    """A learner's saved config in today's form: one saved before :class:`HybridSpec` (``hybrid``
    a bool, the hybrid's fields beside it) gets its ``hybrid`` spec dict (None for a baseline)
    and loses those fields; a spec dict saved before a field existed gets the value runs had
    then (:data:`LEGACY_FIELD_VALUES`);
    any other config is returned as it is (a copy)."""
    out = dict(data)
    if isinstance(out.get("hybrid"), Mapping):  # fields added since take their values of then
        out["hybrid"] = HybridSpec.from_dict(out["hybrid"]).to_dict()
    if not isinstance(out.get("hybrid"), bool):
        return out
    fields = {}
    for name in (*HybridSpec.field_names(), *LEGACY_FIELD_NAMES):
        if name in out:
            fields[LEGACY_FIELD_NAMES.get(name, name)] = out.pop(name)
    out["hybrid"] = HybridSpec.from_dict(fields).to_dict() if data["hybrid"] else None
    return out


@dataclasses.dataclass(frozen=True)
class HybridDesign:
    """What the plant and the LQR fix for a hybrid: plain numbers (see the module docstring).

    Attributes
    ----------
    gain : tuple of tuple of float, shape (F, D)
        :math:`W` of :math:`G(o) = W o + b`, physical units.
    bias : tuple of float, shape (F,)
        :math:`b`, physical units.
    operating_obs : tuple of float, shape (D,)
        Operating point :math:`a` in observation coordinates.
    relevance_data : dict
        The relevance design's resolved data (:meth:`RelevanceDesign.resolve`), JSON-friendly.
    """

    gain: tuple[tuple[float, ...], ...]
    bias: tuple[float, ...]
    operating_obs: tuple[float, ...]
    relevance_data: Mapping[str, Any] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        gain = np.asarray(self.gain, dtype=np.float64)
        bias = np.asarray(self.bias, dtype=np.float64).reshape(-1)
        point = np.asarray(self.operating_obs, dtype=np.float64).reshape(-1)
        if gain.shape != (bias.shape[0], point.shape[0]):
            raise ValueError(
                f"gain: expected shape (F, D) = ({bias.shape[0]}, {point.shape[0]}) from bias and "
                f"operating_obs, found {gain.shape}"
            )
        for name, array in (("gain", gain), ("bias", bias), ("operating_obs", point)):
            if not np.all(np.isfinite(array)):
                raise ValueError(f"{name}: expected finite numbers, found {array.tolist()}")
        object.__setattr__(self, "gain", tuple(tuple(row) for row in gain.tolist()))
        object.__setattr__(self, "bias", tuple(bias.tolist()))
        object.__setattr__(self, "operating_obs", tuple(point.tolist()))
        object.__setattr__(self, "relevance_data", dict(self.relevance_data))

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly dict (lists of floats)."""
        return {
            "gain": [list(row) for row in self.gain],
            "bias": list(self.bias),
            "operating_obs": list(self.operating_obs),
            "relevance_data": dict(self.relevance_data),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> HybridDesign:
        """Inverse of :meth:`to_dict`."""
        return cls(**dict(data))


class RelevanceDesign:
    """One relevance design of :data:`RELEVANCE_DESIGNS` (subclass it to add one).

    Attributes
    ----------
    name : str
        Its ``HybridSpec.relevance`` value.
    """

    name: ClassVar[str] = ""

    def check(self, spec: HybridSpec) -> None:
        """Raise ``ValueError`` on a spec field this design cannot use (default: none)."""

    def resolve(
        self, spec: HybridSpec, system: Any, lqr_design: Any, certificate: Any
    ) -> dict[str, Any]:
        """The design's data fixed by the plant (JSON-friendly; default: none).

        ``certificate`` is a callable returning the LQR's certificate for the hybrid's
        saturation, so that designs that need no proof do not pay for one.
        """
        return {}

    def build(
        self, spec: HybridSpec, data: Mapping[str, Any], operating_obs: np.ndarray, dtype: Any
    ) -> dict[str, Any]:
        """Keywords of :class:`~leoc.policies.HybridPolicy` that make this relevance."""
        raise NotImplementedError


def _matching_certificate(lqr_design: Any, certificate: Any) -> Any:
    """The proved certificate of ``certificate()``, checked to be for ``lqr_design``'s
    :math:`P` at its control period."""
    proved = certificate()
    if proved.action_repeat != lqr_design.action_repeat or not np.array_equal(
        proved.P, lqr_design.P
    ):
        raise ValueError(
            f"certificate: expected one for the design's P at action_repeat="
            f"{lqr_design.action_repeat}, found action_repeat={proved.action_repeat} and a "
            "different P"
        )
    return proved


class PaperRelevanceDesign(RelevanceDesign):
    r"""The paper's :math:`r = (1 + d)^{-2}`, :math:`d = (x - a)^\top \Lambda^{-1} (x - a)`,
    with :math:`\Lambda` held as :math:`\log\lambda` (on the policy itself) or as the precision
    :math:`S = \Lambda^{-1}` (:class:`~leoc.policies.PrecisionRelevance`); with ``r_min``,
    :math:`\Lambda` above the floor of :func:`~leoc.policies.relevance_floor` on the LQR's proved
    set (:class:`~leoc.policies.FlooredRelevance`)."""

    name: ClassVar[str] = "paper"

    def check(self, spec: HybridSpec) -> None:
        if spec.relevance_parametrisation not in RELEVANCE_PARAMETRISATIONS:
            raise ValueError(
                f"relevance_parametrisation: expected one of {RELEVANCE_PARAMETRISATIONS}, "
                f"found {spec.relevance_parametrisation!r}"
            )
        if spec.r_min is not None and spec.relevance_parametrisation == "precision":
            raise ValueError(
                f"r_min: expected None with relevance_parametrisation='precision' (an "
                f"unconstrained S has no floor), found {spec.r_min!r}"
            )
        if spec.relevance_power != 1.0 and (
            spec.relevance != "paper" or spec.relevance_parametrisation == "precision"
        ):
            raise ValueError(
                "relevance_power: expected 1 except with the paper relevance held as log lambda "
                f"(relevance={spec.relevance!r}, relevance_parametrisation="
                f"{spec.relevance_parametrisation!r}), found {spec.relevance_power!r}"
            )

    def resolve(
        self, spec: HybridSpec, system: Any, lqr_design: Any, certificate: Any
    ) -> dict[str, Any]:
        if spec.r_min is None:
            return {}
        proved = _matching_certificate(lqr_design, certificate)
        if not proved.certified:
            raise ValueError(
                f"r_min: expected an LQR with a certified region of attraction to floor Lambda "
                f"on, found none for {system.name} (rho = {proved.rho!r}); drop r_min"
            )
        layout = system.observation.to_list()
        floor = relevance_floor(layout, proved.P, proved.rho, spec.r_min, spec.relevance_power)
        return {"lambda_floor": floor.tolist(), "rho": float(proved.rho), "r_min": spec.r_min}

    def build(
        self, spec: HybridSpec, data: Mapping[str, Any], operating_obs: np.ndarray, dtype: Any
    ) -> dict[str, Any]:
        if spec.r_min is not None and "lambda_floor" not in data:
            raise ValueError(
                f"r_min: expected the design's relevance_data to hold the floor on Lambda "
                f"(hybrid_design resolves it from the LQR's certificate), found none for "
                f"r_min={spec.r_min!r}; resolve the design with hybrid_design, or pass r_min=None"
            )
        if "lambda_floor" in data:
            floored = FlooredRelevance(
                operating_obs,
                data["lambda_floor"],
                lambda_init=spec.lambda_init,
                learn_lambda=spec.learn_lambda,
                dtype=dtype,
                power=spec.relevance_power,
            )
            return {"relevance": floored}
        if spec.relevance_parametrisation == "precision":
            precision = PrecisionRelevance(
                operating_obs,
                1.0 / np.asarray(spec.lambda_init, dtype=np.float64),
                learn_precision=spec.learn_lambda,
                dtype=dtype,
            )
            return {"relevance": precision}
        if spec.relevance_power != 1.0:
            paper = PaperRelevance(
                operating_obs, spec.lambda_init, spec.learn_lambda, dtype, spec.relevance_power
            )
            return {"relevance": paper}
        return {"lambda_init": spec.lambda_init, "learn_lambda": spec.learn_lambda}


class ROARelevanceDesign(RelevanceDesign):
    r"""Exactly 1 on the LQR's certified sublevel set :math:`\{V \le \rho_{in}\}`,
    :math:`\rho_{in}` = ``rho_in_fraction`` :math:`\cdot \rho` of the certificate of the hybrid's
    saturated linear part at its control period (:class:`~leoc.policies.ROARelevance`)."""

    name: ClassVar[str] = "roa"

    def check(self, spec: HybridSpec) -> None:
        fraction = spec.rho_in_fraction
        if isinstance(fraction, bool) or not isinstance(fraction, (int, float)):
            raise ValueError(f"rho_in_fraction: expected a number in (0, 1], found {fraction!r}")
        if not 0.0 < fraction <= 1.0:
            raise ValueError(f"rho_in_fraction: expected a number in (0, 1], found {fraction!r}")
        _positive(spec.width_init, "width_init")

    def resolve(
        self, spec: HybridSpec, system: Any, lqr_design: Any, certificate: Any
    ) -> dict[str, Any]:
        proved = _matching_certificate(lqr_design, certificate)
        if not proved.certified:
            raise ValueError(
                f"relevance='roa': the LQR of {system.name} has no certified region of attraction "
                f"(rho = 0, linear decrease {proved.linear_decrease}); use relevance='paper'"
            )
        return {
            "obs_layout": system.observation.to_list(),
            "operating_state": np.asarray(system.operating_state, dtype=np.float64).tolist(),
            "lyapunov_matrix": np.asarray(lqr_design.P, dtype=np.float64).tolist(),
            "rho_in": float(spec.rho_in_fraction * proved.rho),
        }

    def build(
        self, spec: HybridSpec, data: Mapping[str, Any], operating_obs: np.ndarray, dtype: Any
    ) -> dict[str, Any]:
        relevance = ROARelevance(
            [tuple(entry) for entry in data["obs_layout"]],
            data["operating_state"],
            data["lyapunov_matrix"],
            data["rho_in"],
            width_init=spec.width_init,
            learn_width=spec.learn_width,
            dtype=dtype,
        )
        return {"relevance": relevance}


class LyapunovRelevanceDesign(RelevanceDesign):
    r""":math:`r = (1 + \tilde V / (\lambda \rho))^{-2}`: the LQR's Lyapunov function, written
    smoothly on the observation manifold, as the distance, scaled by its proved level
    :math:`\rho` and one learnable :math:`\lambda` (:class:`~leoc.policies.LyapunovRelevance`)."""

    name: ClassVar[str] = "lyapunov"

    def check(self, spec: HybridSpec) -> None:
        if spec.relevance != self.name:
            return
        if isinstance(spec.lambda_init, tuple):
            raise ValueError(
                f"lambda_init: expected one positive number with relevance='lyapunov' (its "
                f"lambda is a scalar), found {spec.lambda_init!r}"
            )
        if spec.r_min is not None:
            raise ValueError(
                f"r_min: expected None with relevance='lyapunov' (the floor is the paper "
                f"relevance's), found {spec.r_min!r}"
            )

    def resolve(
        self, spec: HybridSpec, system: Any, lqr_design: Any, certificate: Any
    ) -> dict[str, Any]:
        proved = _matching_certificate(lqr_design, certificate)
        if not proved.certified:
            raise ValueError(
                f"relevance='lyapunov': the LQR of {system.name} has no certified region of "
                f"attraction (rho = {proved.rho!r}) to scale V by; use relevance='paper'"
            )
        return {
            "obs_layout": system.observation.to_list(),
            "lyapunov_matrix": np.asarray(proved.P, dtype=np.float64).tolist(),
            "rho": float(proved.rho),
        }

    def build(
        self, spec: HybridSpec, data: Mapping[str, Any], operating_obs: np.ndarray, dtype: Any
    ) -> dict[str, Any]:
        relevance = LyapunovRelevance(
            [tuple(entry) for entry in data["obs_layout"]],
            operating_obs,
            data["lyapunov_matrix"],
            data["rho"],
            lambda_init=spec.lambda_init,  # type: ignore[arg-type]  # a scalar: check()
            learn_lambda=spec.learn_lambda,
            dtype=dtype,
        )
        return {"relevance": relevance}


RELEVANCE_DESIGNS: dict[str, RelevanceDesign] = {
    design.name: design
    for design in (PaperRelevanceDesign(), ROARelevanceDesign(), LyapunovRelevanceDesign())
}
"""Every relevance design by name (``HybridSpec.relevance``)."""


def hybrid_design(
    spec: HybridSpec,
    system: Any,
    lqr_design: Any,
    saturation: str = "clip",
    action_limit: float | None = None,
    certificate: Any = None,
    **certify_options: Any,
) -> HybridDesign:
    r"""The :class:`HybridDesign` of ``spec`` on ``system`` with the LQR ``lqr_design``.

    Parameters
    ----------
    spec : HybridSpec
    system : leoc.systems.System
    lqr_design : LQRDesign
        :math:`W, b` and :math:`P` at the hybrid's control period (``action_repeat``).
    saturation : {"clip", "sin", "tanh", "none"}
        The hybrid's saturation: a design that needs the LQR's certificate
        (:func:`~leoc.policies.hybrid.lqr_certificate`) proves the loop with this saturation.
    action_limit : float, optional
        :math:`u_{max}` of that saturation; default ``system.action_limit``.
    certificate : LyapunovCertificate, optional
        A proved certificate to use instead (for ``lqr_design.P`` at its period).
    **certify_options
        Passed to :func:`leoc.control.certify_level` when a certificate is proved here.
    """

    def proved() -> Any:
        if certificate is not None:
            return certificate
        return lqr_certificate(system, lqr_design, saturation, action_limit, **certify_options)

    return HybridDesign(
        gain=np.asarray(lqr_design.W, dtype=np.float64),
        bias=np.asarray(lqr_design.b, dtype=np.float64),
        operating_obs=np.asarray(system.operating_obs, dtype=np.float64),
        relevance_data=spec.design.resolve(spec, system, lqr_design, proved),
    )


def build_hybrid(
    spec: HybridSpec,
    design: HybridDesign,
    learned_part: nn.Module,
    *,
    action_limit: float | None = None,
    saturation: str = "clip",
    action_box: tuple[np.ndarray, np.ndarray] | None = None,
    dtype: torch.dtype = torch.float64,
) -> HybridPolicy:
    r"""The :class:`~leoc.policies.HybridPolicy` :math:`\operatorname{sat}(r G + (1 - r) H)`.

    Parameters
    ----------
    spec : HybridSpec
    design : HybridDesign
    learned_part : nn.Module
        :math:`H`, (..., D) -> (..., F), in the units the hybrid acts in.
    action_limit : float, optional
        :math:`u_{max}` of the saturation (None: no saturation).
    saturation : {"clip", "sin", "tanh", "none"}
    action_box : (centre, half_width), optional
        For a learner acting in normalised units :math:`\tilde u = (u - c) / h` (SB3's
        :math:`[-1, 1]`): the linear part becomes :math:`\tilde G = (W o + b - c) / h`; the
        relevance is unchanged (it reads the observation). None: physical units.
    dtype : torch.dtype
        Of the linear part and the relevance (SB3: float32; PILCO: float64).
    """
    gain = np.asarray(design.gain, dtype=np.float64)
    bias = np.asarray(design.bias, dtype=np.float64)
    point = np.asarray(design.operating_obs, dtype=np.float64)
    if action_box is None:
        linear = LinearController(gain, bias, dtype=dtype)
    else:
        centre, half = action_box
        linear = LinearController(gain / half[:, None], (bias - centre) / half, dtype=dtype)
    relevance = spec.design.build(spec, design.relevance_data, point, dtype)
    return HybridPolicy(
        linear,
        learned_part,
        point,
        action_limit=action_limit,
        saturation=saturation,
        **relevance,
    )


def roa_hybrid(
    system: Any,
    design: Any,
    nonlinear: nn.Module,
    certificate: Any = None,
    rho_in: float | None = None,
    rho_in_fraction: float = 1.0,
    width_init: float = DEFAULT_ROA_WIDTH,
    learn_width: bool = True,
    action_limit: float | None = None,
    saturation: str = "clip",
    **certify_options: Any,
) -> HybridPolicy:
    r"""A :class:`~leoc.policies.HybridPolicy` whose relevance is 1 on the LQR's certified region
    of attraction, in physical units: :func:`build_hybrid` of the ``roa`` :class:`HybridSpec`.

    E.g. ``roa_hybrid(system, design_lqr(system, action_repeat=3), rbf, saturation="sin")``,
    run at the design's period in a :class:`~leoc.policies.HeldPolicy`.

    Parameters
    ----------
    system : leoc.systems.System
    design : LQRDesign
        :math:`G(o) = W o + b` and the Lyapunov matrix :math:`P`, at the hybrid's period.
    nonlinear : nn.Module
        :math:`H`, (..., D) -> (..., F), float64.
    certificate : LyapunovCertificate, optional
        Default: :func:`leoc.control.certify_lqr` of :math:`\operatorname{sat}(G)` with this
        saturation at the design's period (``certify_options`` passed on). A given certificate
        must be for ``design.P`` at ``design.action_repeat``.
    rho_in : float, optional
        Level of the flat top, ``0 < rho_in <= rho``; default ``rho_in_fraction * rho``.
    rho_in_fraction, width_init, learn_width
        See :class:`HybridSpec` and :class:`~leoc.policies.ROARelevance`.
    action_limit : float, optional
        Default ``system.action_limit``.
    saturation : {"clip", "sin", "tanh"}
        The hybrid's saturation (and its certificate's).

    Raises
    ------
    ValueError
        If the certificate does not match the design or proves nothing, or ``rho_in`` is not in
        (0, rho].
    """
    limit = float(system.action_limit if action_limit is None else action_limit)
    spec = HybridSpec("roa", rho_in_fraction=rho_in_fraction, width_init=width_init)
    spec = spec.replace(learn_width=learn_width)
    if certificate is None:
        certificate = lqr_certificate(system, design, saturation, limit, **certify_options)
    resolved = hybrid_design(spec, system, design, certificate=certificate)
    if rho_in is not None:
        if not 0.0 < float(rho_in) <= certificate.rho:
            raise ValueError(
                f"rho_in: expected a level in (0, rho = {certificate.rho:.6g}], found {rho_in!r}"
            )
        data = {**resolved.relevance_data, "rho_in": float(rho_in)}
        resolved = dataclasses.replace(resolved, relevance_data=data)
    return build_hybrid(spec, resolved, nonlinear, action_limit=limit, saturation=saturation)
