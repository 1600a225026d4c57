"""A system description from a gymnasium environment: linearisation and LQR without torch.

leoc's own systems are linearised by automatic differentiation of their torch step map
(:func:`leoc.control.linearise`). A gymnasium environment written by others (a MuJoCo model, a
classic-control env) has no such map; this module linearises the env's *own* step,
``x' = f(x, u)`` with ``x`` its physical state and ``u`` its action, and designs the discrete
LQR on the result:

* :func:`linearise_env`: central finite differences of ``f`` about ``(state, action)``, for
  envs whose state can be set (MuJoCo's ``set_state``, classic control's ``state`` attribute,
  or a pair of user hooks), with a stated error bound per entry;
* :func:`identify_linear`: least-squares identification of ``A_d, B_d`` from small seeded
  perturbations, for envs that can only be *started* near a state (a ``reset_to`` hook), with
  the fit's residual and an error bound;
* :func:`design_env_lqr` and :class:`LQRPolicy`: the discrete LQR
  ``u = clip(u_eq - K (x - x_eq), low, high)`` on either result, and a callable that maps the
  env's observation to that action.

Error bound of the finite differences. With :math:`D_h` the central difference of step ``h``
along one coordinate (``h`` from :func:`default_steps`: ``eps^(1/3)`` times the coordinate's
scale, ``eps`` the machine epsilon of the state the env computes), each entry of ``A_d, B_d``
is :math:`D_h`, and its error is bounded by

.. math::

    e = \\tfrac{4}{3} |D_h - D_{h/2}| + 5 \\, k \\, \\epsilon \\, \\max |f(z \\pm h)| / h,

the first term the Richardson estimate of the truncation error :math:`c h^2` of :math:`D_h`
(:math:`D_h - D_{h/2} = \\tfrac34 c h^2`, with :math:`c` a sixth of the third derivative; terms
of order :math:`h^4` neglected), the second the rounding: each output of ``f`` carries at most
``k = ROUNDING_ULPS`` roundings, which perturb :math:`D_h` by at most
:math:`R = k \\epsilon \\max|f| / h`, :math:`D_{h/2}` by :math:`2R`, hence the Richardson term
by :math:`\\tfrac43 \\cdot 3R` and the total by :math:`5R`. The step map is evaluated on float64
actions: gymnasium's ``Pendulum-v1`` then computes in float64 (only its observation is
float32) and its bound is about 1e-11 or smaller; with a float32 state
(``MountainCarContinuous-v0``: ``h`` about 5e-3) the bound is about 2e-4 (dominated by
rounding; the actual errors there are nearer 1e-6).

Letters: S the state size, F the action size (the env's ``action_space.shape == (F,)``).

Where each is exact. Finite differences approximate the derivative of the env's step map as
the env computes it (its integrator, frame skip and solver included), so they need no model,
but they are exact only up to the truncation and rounding error that
:class:`EnvLinearisation` reports; they are only meaningful where the step map is smooth
within the step size of the point (no contact switching, no active clip of the action or of a
velocity). Identification is exact for a linear map and otherwise biased by the curvature of
``f`` over the sampled region; its bound combines that bias (estimated by fitting at two
scales) and the fit's standard errors.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from leoc.control.lqr import _weight_matrix, check_stabilisable

__all__ = [
    "DEFAULT_SEED",
    "IDENTIFY_SCALE",
    "RICHARDSON_RATIO",
    "ROUNDING_ULPS",
    "SAMPLES_PER_PARAMETER",
    "STANDARD_ERRORS",
    "EnvIdentification",
    "EnvLQR",
    "EnvLinearisation",
    "LQRPolicy",
    "StateAccess",
    "StateGetter",
    "StateSetter",
    "default_steps",
    "design_env_lqr",
    "identify_linear",
    "linearise_env",
    "state_access",
]

#: Ratio of the two step sizes (``h`` and ``h / RICHARDSON_RATIO``) whose derivative estimates
#: are compared to estimate the truncation error, and of the two identification scales.
RICHARDSON_RATIO = 2.0
#: Roundings per evaluation of the step map charged to the rounding term of the error bound:
#: each output of ``f`` is taken to carry an absolute error of ``ROUNDING_ULPS * eps * |f|``.
ROUNDING_ULPS = 4.0
#: Relative size of the identification's perturbations: coordinate ``j`` is perturbed by a
#: standard normal draw times ``IDENTIFY_SCALE * max(1, |z_j|)``.
IDENTIFY_SCALE = 1e-3
#: Samples per fitted parameter of one output row (``S + F + 1`` parameters) and scale.
SAMPLES_PER_PARAMETER = 20
#: Standard errors of the fit added to the identification's error bound.
STANDARD_ERRORS = 4.0
#: Seed of the env's reset before the step map is evaluated (and of the identification draws).
DEFAULT_SEED = 0

#: A user hook ``get_state(env.unwrapped) -> (S,)`` reading the env's state.
StateGetter = Callable[[Any], np.ndarray]
#: A user hook ``set_state(env.unwrapped, state)`` writing the env's state (or, as
#: ``reset_to`` of :func:`identify_linear`, starting the env at or near it).
StateSetter = Callable[[Any, np.ndarray], None]


class StateAccess(NamedTuple):
    """How the state of an env (``env.unwrapped``) is read and written, and by which route."""

    get: Callable[[], np.ndarray]  # the raw state array, in the env's own dtype
    set: Callable[[np.ndarray], None]
    route: str  # "hooks", "mujoco" or "attribute"


class EnvLinearisation(NamedTuple):
    """The central-difference Jacobians of an env's step map at ``(state, action)``.

    ``A_d[i, j] ~ d f_i / d x_j`` and ``B_d[i, k] ~ d f_i / d u_k`` with step sizes
    ``state_steps`` and ``action_steps``; ``error_A`` and ``error_B`` bound their absolute
    errors entry by entry (:func:`linearise_env`). ``precision`` is the machine epsilon of the
    state the env computes; ``action_low`` and ``action_high`` are its action space's bounds.
    """

    A_d: np.ndarray  # (S, S)
    B_d: np.ndarray  # (S, F)
    state: np.ndarray  # (S,)
    action: np.ndarray  # (F,)
    state_steps: np.ndarray  # (S,)
    action_steps: np.ndarray  # (F,)
    error_A: np.ndarray  # (S, S)
    error_B: np.ndarray  # (S, F)
    precision: float
    action_low: np.ndarray  # (F,)
    action_high: np.ndarray  # (F,)


class EnvIdentification(NamedTuple):
    """The least-squares fit ``x' ~ c + A_d (x - state) + B_d (u - action)`` of an env's steps.

    ``residual`` is the root-mean-square residual of each output row of the returned fit (in
    the state's units); ``samples`` is the number of steps per fit; ``offset`` is ``c``, the
    fitted ``f(state, action)``. ``error_A`` and ``error_B`` bound the absolute errors of the
    entries (:func:`identify_linear` fits at the scales ``s`` and ``s/2`` and returns the
    second),

    .. math::

        e = |\\Theta_s - \\Theta_{s/2}| + z \\, \\mathrm{se}(\\Theta_{s/2}),

    ``z = STANDARD_ERRORS``: the change between the scales bounds the curvature bias of the
    finer fit (a bias growing like ``s`` or ``s^2``), the standard errors (ordinary least
    squares, from the residual) its scatter. Exact for a linear map; a kink inside the sampled
    region shows as a large residual and a large bound.
    """

    A_d: np.ndarray  # (S, S)
    B_d: np.ndarray  # (S, F)
    state: np.ndarray  # (S,)
    action: np.ndarray  # (F,)
    offset: np.ndarray  # (S,)
    residual: np.ndarray  # (S,)
    error_A: np.ndarray  # (S, S)
    error_B: np.ndarray  # (S, F)
    samples: int
    action_low: np.ndarray  # (F,)
    action_high: np.ndarray  # (F,)


class EnvLQR(NamedTuple):
    """A discrete LQR about an env's operating point (:func:`design_env_lqr`).

    The action is ``u = clip(W x + b, action_low, action_high)`` with ``W = -K`` and
    ``b = action + K state`` (leoc's ``G(x) = W x + b`` convention, on the state), that is
    ``u = clip(action - K (x - state))``.
    """

    K: np.ndarray  # (F, S)
    P: np.ndarray  # (S, S), the Riccati solution
    W: np.ndarray  # (F, S)
    b: np.ndarray  # (F,)
    closed_loop_eigenvalues: np.ndarray  # (S,), of A_d - B_d K
    state: np.ndarray  # (S,)
    action: np.ndarray  # (F,)
    action_low: np.ndarray  # (F,)
    action_high: np.ndarray  # (F,)
    Q: np.ndarray  # (S, S)
    R: np.ndarray  # (F, F)


def state_access(
    env: Any, set_state: StateSetter | None = None, get_state: StateGetter | None = None
) -> StateAccess:
    """How to read and write the state of ``env`` (its ``env.unwrapped``).

    Parameters
    ----------
    env : gymnasium.Env
        Reset already (a classic-control env has no ``state`` before its first reset).
    set_state, get_state : callable, optional
        User hooks ``set_state(env.unwrapped, state)`` and ``get_state(env.unwrapped) -> (S,)``;
        give both or neither. Without them: a MuJoCo env (``set_state`` and ``data``) has the
        state ``concat(data.qpos, data.qvel)``, written by ``set_state(qpos, qvel)``; an env
        with a ``state`` attribute (classic control) has that attribute, written in the
        dtype the env keeps it in.

    Raises
    ------
    ValueError
        Only one hook, a MuJoCo model with actuator activations (its state is more than qpos
        and qvel), or no route at all.
    """
    base = env.unwrapped
    if (set_state is None) != (get_state is None):
        raise ValueError(
            "set_state, get_state: expected both hooks or neither, found only "
            + ("set_state" if get_state is None else "get_state")
        )
    if set_state is not None and get_state is not None:
        return StateAccess(
            lambda: np.asarray(get_state(base)), lambda x: set_state(base, x), "hooks"
        )
    if hasattr(base, "set_state") and hasattr(base, "data") and hasattr(base, "model"):
        if getattr(base.model, "na", 0):
            raise ValueError(
                f"env: expected a MuJoCo model without actuator activations (state = qpos, "
                f"qvel), found na = {base.model.na}; give set_state and get_state hooks"
            )
        nq = base.model.nq
        return StateAccess(
            lambda: np.concatenate([base.data.qpos, base.data.qvel]),
            lambda x: base.set_state(np.array(x[:nq]), np.array(x[nq:])),
            "mujoco",
        )
    if hasattr(base, "state"):

        def write(x: np.ndarray) -> None:
            dtype = np.asarray(base.state).dtype if base.state is not None else float
            base.state = np.array(x, dtype=dtype)

        return StateAccess(lambda: np.asarray(base.state), write, "attribute")
    raise ValueError(
        f"env: expected a MuJoCo env (set_state) or an env with a 'state' attribute, found "
        f"{type(base).__name__} with neither; give set_state and get_state hooks"
    )


def _action_bounds(env: Any) -> tuple[np.ndarray, np.ndarray]:
    """The env's Box action space bounds as float64 arrays, or a one-line error."""
    space = env.action_space
    low, high = getattr(space, "low", None), getattr(space, "high", None)
    if low is None or high is None or len(space.shape) != 1:
        raise ValueError(
            f"env: expected a 1-D Box action space, found {type(space).__name__} {space}"
        )
    return np.asarray(low, dtype=float), np.asarray(high, dtype=float)


def _check_point(
    state: Any, action: Any, state_size: int, low: np.ndarray, high: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Convert the operating point once and check it against the env's sizes and bounds."""
    state_np = np.asarray(state, dtype=float)
    action_np = np.asarray(action, dtype=float)
    if state_np.shape != (state_size,) or not np.all(np.isfinite(state_np)):
        raise ValueError(
            f"state: expected {state_size} finite values (the env's state), "
            f"found shape {state_np.shape}: {state_np.tolist()}"
        )
    if action_np.shape != low.shape or not np.all(np.isfinite(action_np)):
        raise ValueError(
            f"action: expected shape {low.shape} (the env's action space), "
            f"found shape {action_np.shape}: {action_np.tolist()}"
        )
    if np.any(action_np < low) or np.any(action_np > high):
        raise ValueError(
            f"action: expected inside the action space [{low.tolist()}, {high.tolist()}], "
            f"found {action_np.tolist()}"
        )
    return state_np, action_np


def _step_map(env: Any, access: StateAccess) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """``f(x, u)``: set the state, take one step of ``env.unwrapped``, read the state back.

    The unwrapped env is stepped, so no time limit, order check or termination of a wrapper
    touches the map; the state is written afresh before every step. The action is passed as
    float64 so that a perturbation smaller than float32 resolution is not rounded away.
    """
    base = env.unwrapped

    def step(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        access.set(x)
        base.step(np.array(u, dtype=np.float64))
        return np.array(access.get(), dtype=float)

    return step


def _prepare(
    env: Any,
    state: Any,
    action: Any,
    access: StateAccess,
) -> tuple[np.ndarray, np.ndarray, Callable, np.dtype]:
    """Check the point and the map (it must be deterministic and the
    state must read back as written); return the point, the map and the state's epsilon."""
    low, high = _action_bounds(env)
    size = np.asarray(access.get()).size
    state_np, action_np = _check_point(state, action, size, low, high)
    step = _step_map(env, access)
    first = step(state_np, action_np)
    raw = access.get()
    dtype = raw.dtype if np.issubdtype(raw.dtype, np.floating) else np.dtype(float)
    precision = float(np.finfo(dtype).eps)
    access.set(state_np)
    written = np.array(access.get(), dtype=float)
    tolerance = 2.0 * precision * np.maximum(1.0, np.abs(state_np))
    if np.any(np.abs(written - state_np) > tolerance):
        raise ValueError(
            f"set_state: expected the state to read back as written, wrote "
            f"{state_np.tolist()}, read {written.tolist()}"
        )
    second = step(state_np, action_np)
    if not np.array_equal(first, second):
        raise ValueError(
            f"env: expected a deterministic step from a set state, found two steps from "
            f"{state_np.tolist()} giving {first.tolist()} and {second.tolist()}"
        )
    return state_np, action_np, step, dtype


def default_steps(point: np.ndarray, precision: float) -> np.ndarray:
    """Central-difference step sizes ``h_j = precision^(1/3) * max(1, |z_j|)``.

    With third derivative M and outputs of size F computed to ``k eps |F|``, the central
    difference errs by at most ``h^2 M / 6 + k eps |F| / h``, smallest near
    ``h ~ (3 k eps |F| / M)^(1/3)``: ``eps^(1/3)`` per unit of scale, which leaves an error of
    order ``eps^(2/3)`` (about 4e-11 in float64, 2e-5 in float32). The scale is the
    coordinate's magnitude, at least 1.
    """
    return precision ** (1.0 / 3.0) * np.maximum(1.0, np.abs(point))


def _central(
    step: Callable, point: tuple[np.ndarray, np.ndarray], index: int, h: float, dtype: np.dtype
) -> tuple[np.ndarray, np.ndarray]:
    """Central difference of ``f`` along coordinate ``index`` of ``(x, u)`` with step ``h``;
    also the larger magnitude of the two outputs (for the rounding term).

    The perturbed states are rounded to the env's state dtype *before* the difference quotient
    is formed, so that its denominator is the step the env actually takes (``z + h`` rounds,
    in float32 noticeably); actions are passed as float64.
    """
    state, action = point
    size = state.size
    plus, minus = np.concatenate(point), np.concatenate(point)
    plus[index] += h
    minus[index] -= h
    plus[:size] = plus[:size].astype(dtype)
    minus[:size] = minus[:size].astype(dtype)
    f_plus = step(plus[:size], plus[size:])
    f_minus = step(minus[:size], minus[size:])
    width = plus[index] - minus[index]
    return (f_plus - f_minus) / width, np.maximum(np.abs(f_plus), np.abs(f_minus))


def _differences(
    step: Callable, point: tuple[np.ndarray, np.ndarray], steps: np.ndarray, dtype: np.dtype
) -> tuple[np.ndarray, np.ndarray]:
    """The Jacobian ``[A_d | B_d]`` from steps ``h`` and its error bound (:func:`linearise_env`):
    the Richardson term from the steps ``h`` and ``h / RICHARDSON_RATIO`` plus the rounding
    term."""
    columns, errors = [], []
    for index, h in enumerate(steps):
        coarse, magnitude = _central(step, point, index, h, dtype)
        fine, _ = _central(step, point, index, h / RICHARDSON_RATIO, dtype)
        # D_h - D_{h/r} = (1 - r^-2) c h^2 + (rho_h - rho_{h/r}) for a truncation error c h^2
        # and rounding errors |rho_h| <= R, |rho_{h/r}| <= r R: the error of D_h is at most
        # |D_h - D_{h/r}| / (1 - r^-2) + (1 + (1 + r) / (1 - r^-2)) R
        shrink = 1.0 - RICHARDSON_RATIO**-2
        rounding = ROUNDING_ULPS * float(np.finfo(dtype).eps) * magnitude / h
        columns.append(coarse)
        errors.append(
            np.abs(coarse - fine) / shrink + (1.0 + (1.0 + RICHARDSON_RATIO) / shrink) * rounding
        )
    return np.stack(columns, axis=1), np.stack(errors, axis=1)


def linearise_env(
    env: Any,
    state: Any,
    action: Any,
    set_state: StateSetter | None = None,
    step_sizes: Any | None = None,
    get_state: StateGetter | None = None,
    seed: int = DEFAULT_SEED,
) -> EnvLinearisation:
    """Linearise the env's own step map ``x' = f(x, u)`` at ``(state, action)``.

    Parameters
    ----------
    env : gymnasium.Env
        An env with a 1-D Box action space whose state can be set (:func:`state_access`). It
        is reset once with ``seed``; afterwards its state is unspecified: reset it before use.
    state : array (S,)
        The operating state, in the env's state coordinates (MuJoCo: ``concat(qpos, qvel)``).
    action : array (F,)
        The operating action, inside the action space (and, for the derivative to mean
        anything, further than the step size from its bounds if the env clips there).
    set_state, get_state : callable, optional
        Hooks ``set_state(env.unwrapped, state)``, ``get_state(env.unwrapped)``.
    step_sizes : array (S + F,), optional
        Step ``h`` per coordinate of ``(x, u)``; default :func:`default_steps` at the
        precision of the state the env computes.
    seed : int
        Seed of the env's reset.

    Returns
    -------
    EnvLinearisation
        ``A_d, B_d`` from the steps ``h``, with the error bound of the module docstring.

    Raises
    ------
    ValueError
        A state of the wrong length, an action outside the action space, an env whose state
        cannot be set (and no hooks), a state that does not read back, or a random step.
    """
    env.reset(seed=seed)
    access = state_access(env, set_state, get_state)
    state_np, action_np, step, dtype = _prepare(env, state, action, access)
    precision = float(np.finfo(dtype).eps)
    point = np.concatenate([state_np, action_np])
    steps = default_steps(point, precision) if step_sizes is None else step_sizes
    steps = np.asarray(steps, dtype=float)
    if steps.shape != point.shape or not np.all(steps > 0.0):
        raise ValueError(
            f"step_sizes: expected {point.size} positive values, found {np.ravel(steps).tolist()}"
        )
    jacobian, bound = _differences(step, (state_np, action_np), steps, dtype)
    size = state_np.size
    fields = (jacobian[:, :size], jacobian[:, size:], state_np, action_np, steps[:size])
    tail = (steps[size:], bound[:, :size], bound[:, size:], precision, *_action_bounds(env))
    return EnvLinearisation(*fields, *tail)


def _identify_access(
    env: Any, reset_to: StateSetter | None, get_state: StateGetter | None
) -> tuple[Callable[[np.ndarray], None], Callable[[], np.ndarray]]:
    """How :func:`identify_linear` starts the env near a state and reads its state."""
    base = env.unwrapped
    if reset_to is not None and get_state is not None:
        return (lambda x: reset_to(base, x)), (lambda: np.asarray(get_state(base)))
    try:
        access = state_access(env)
    except ValueError as error:
        raise ValueError(
            "reset_to, get_state: expected hooks for an env whose state cannot be set or read "
            f"({error})"
        ) from None
    start = access.set if reset_to is None else (lambda x: reset_to(base, x))
    read = access.get if get_state is None else (lambda: np.asarray(get_state(base)))
    return start, read


class _Fit(NamedTuple):
    """One least-squares fit: coefficients ``[A_d | B_d]``, offset, rms residual per row and
    standard errors of the coefficients."""

    coefficients: np.ndarray  # (S, S + F)
    offset: np.ndarray  # (S,)
    residual: np.ndarray  # (S,)
    standard_errors: np.ndarray  # (S, S + F)


def _fit(
    env: Any,
    access: tuple[Callable, Callable],
    point: tuple[np.ndarray, np.ndarray],
    scales: np.ndarray,
    samples: int,
    rng: np.random.Generator,
) -> _Fit:
    """Fit ``x' = c + A_d (x - x_eq) + B_d (u - u_eq)`` to ``samples`` single steps from starts
    and actions drawn around the point with standard deviations ``scales`` (S + F).

    The regressors are the *measured* deviations divided by ``scales`` (a well-conditioned
    design), and the standard errors are those of ordinary least squares,
    ``sigma_i^2 diag((X^T X)^-1)`` with ``sigma_i^2`` the residual variance of row i.
    """
    start, read = access
    state, action = point
    low, high = _action_bounds(env)
    regressors, outputs = [], []
    for _ in range(samples):
        start(state + scales[: state.size] * rng.standard_normal(state.size))
        began = np.array(read(), dtype=float)
        u = np.clip(action + scales[state.size :] * rng.standard_normal(action.size), low, high)
        env.unwrapped.step(np.array(u, dtype=np.float64))
        outputs.append(np.array(read(), dtype=float))
        regressors.append(np.concatenate([began - state, u - action]) / scales)
    design = np.column_stack([np.vstack(regressors), np.ones(samples)])
    targets = np.vstack(outputs)
    solution, *_ = np.linalg.lstsq(design, targets, rcond=None)
    residual = targets - design @ solution
    variance = np.sum(residual**2, axis=0) / (samples - design.shape[1])
    spread = np.sqrt(np.outer(variance, np.diag(np.linalg.inv(design.T @ design))))
    return _Fit(
        solution[:-1].T / scales,
        solution[-1],
        np.sqrt(np.mean(residual**2, axis=0)),
        spread[:, :-1] / scales,
    )


def identify_linear(
    env: Any,
    state: Any,
    action: Any,
    reset_to: StateSetter | None = None,
    get_state: StateGetter | None = None,
    scale: float = IDENTIFY_SCALE,
    samples: int | None = None,
    seed: int = DEFAULT_SEED,
) -> EnvIdentification:
    """Identify ``A_d, B_d`` of the env's step map by least squares around ``(state, action)``.

    Each sample starts the env near ``state + scale * max(1, |x|) * N(0, I)`` (by
    ``reset_to(env.unwrapped, target)``, or by the state setter where the env has one), reads
    the start actually reached, takes one step of ``env.unwrapped`` with ``action`` perturbed
    the same way (clipped to the action space) and reads the next state. The fit is done twice,
    at ``scale`` and at ``scale / RICHARDSON_RATIO``; the second is returned, with the error
    bound of :class:`EnvIdentification`.

    Parameters
    ----------
    env : gymnasium.Env
        A 1-D Box action space; reset once with ``seed``, left in an unspecified state.
    state : array (S,)
        The operating state.
    action : array (F,)
        The operating action, inside the action space.
    reset_to : callable, optional
        ``reset_to(env.unwrapped, target)`` starts the env at ``target``. A hook that cannot
        aim (the env's own ``reset``; the start is read back by ``get_state``) still gives a
        fit, but not the bound: its two scales then differ in the actions only.
    get_state : callable, optional
        ``get_state(env.unwrapped) -> (S,)``; default the MuJoCo or ``state`` route.
    scale : float
        Relative size of the perturbations (:data:`IDENTIFY_SCALE`).
    samples : int, optional
        Steps per fit; default ``SAMPLES_PER_PARAMETER * (S + F + 1)``.
    seed : int
        Seeds the env's reset and every draw.

    Returns
    -------
    EnvIdentification
    """
    env.reset(seed=seed)
    access = _identify_access(env, reset_to, get_state)
    low, high = _action_bounds(env)
    state_np, action_np = _check_point(state, action, np.asarray(access[1]()).size, low, high)
    spread, count = _sampling(np.concatenate([state_np, action_np]), scale, samples)
    rng = np.random.default_rng(seed)
    coarse = _fit(env, access, (state_np, action_np), spread, count, rng)
    fine = _fit(env, access, (state_np, action_np), spread / RICHARDSON_RATIO, count, rng)
    change = np.abs(coarse.coefficients - fine.coefficients)
    bound = change + STANDARD_ERRORS * fine.standard_errors
    size = state_np.size
    fields = (fine.coefficients[:, :size], fine.coefficients[:, size:], state_np, action_np)
    tail = (fine.offset, fine.residual, bound[:, :size], bound[:, size:], count, low, high)
    return EnvIdentification(*fields, *tail)


def _sampling(point: np.ndarray, scale: float, samples: int | None) -> tuple[np.ndarray, int]:
    """Standard deviations ``scale * max(1, |z|)`` of the draws and the samples per fit."""
    count = SAMPLES_PER_PARAMETER * (point.size + 1) if samples is None else int(samples)
    if count <= point.size + 1 or not scale > 0.0:
        raise ValueError(
            f"samples, scale: expected more than {point.size + 1} samples and a positive "
            f"scale, found {count} and {scale}"
        )
    return scale * np.maximum(1.0, np.abs(point)), count


def design_env_lqr(
    linearisation: EnvLinearisation | EnvIdentification, Q: Any = None, R: Any = None
) -> EnvLQR:
    """The discrete LQR of a linearised env: ``u = clip(u_eq - K (x - x_eq), low, high)``.

    ``K = (R + B_d^T P B_d)^{-1} B_d^T P A_d`` with ``P`` the solution of the discrete
    algebraic Riccati equation (:func:`scipy.linalg.solve_discrete_are`), which minimises
    ``sum_t dx_t^T Q dx_t + du_t^T R du_t`` for the linear model (the clip is outside it).

    Parameters
    ----------
    linearisation : EnvLinearisation or EnvIdentification
    Q : array (S, S) or (S,), optional
        State weight, symmetric PSD; default the identity.
    R : array (F, F) or (F,), optional
        Action weight, symmetric PD; default the identity.

    Raises
    ------
    ValueError
        Bad weights, or an unstabilisable ``(A_d, B_d)``.
    """
    from scipy.linalg import solve_discrete_are

    a_matrix, b_matrix = linearisation.A_d, linearisation.B_d
    size, inputs = b_matrix.shape
    q_matrix = _weight_matrix(np.ones(size) if Q is None else Q, size, "Q", False)
    r_matrix = _weight_matrix(np.ones(inputs) if R is None else R, inputs, "R", True)
    check_stabilisable(a_matrix, b_matrix, discrete=True)
    P = solve_discrete_are(a_matrix, b_matrix, q_matrix, r_matrix)
    K = np.linalg.solve(r_matrix + b_matrix.T @ P @ b_matrix, b_matrix.T @ P @ a_matrix)
    return EnvLQR(
        K,
        P,
        -K,
        linearisation.action + K @ linearisation.state,
        np.linalg.eigvals(a_matrix - b_matrix @ K),
        linearisation.state,
        linearisation.action,
        linearisation.action_low,
        linearisation.action_high,
        q_matrix,
        r_matrix,
    )


class LQRPolicy:
    """The clipped LQR of :func:`design_env_lqr` as a callable ``observation -> action``.

    Parameters
    ----------
    design : EnvLQR
    state_of : callable, optional
        ``state_of(observation) -> (S,)``, the state the gain acts on. Default: the observation
        *is* the state (MuJoCo ``InvertedPendulum-v5``: ``[cart x, pole angle, cart x_dot,
        pole angle_dot]`` = ``concat(qpos, qvel)``). For an observation that is not the state
        (``InvertedDoublePendulum-v5`` shows sines, cosines and a constraint force) give the
        map back, e.g. angles by ``arctan2(sin, cos)``.
    """

    def __init__(
        self, design: EnvLQR, state_of: Callable[[np.ndarray], np.ndarray] | None = None
    ) -> None:
        self.design = design
        self.state_of = state_of

    def __call__(self, observation: Any) -> np.ndarray:
        """The action ``clip(W x + b, low, high)`` for the state ``x`` of ``observation``."""
        values = np.asarray(observation, dtype=float)
        state = values if self.state_of is None else np.asarray(self.state_of(values), float)
        if state.shape != self.design.state.shape:
            raise ValueError(
                f"observation: expected a state of shape {self.design.state.shape} "
                f"(give state_of when the observation is not the state), found {state.shape}"
            )
        action = self.design.W @ state + self.design.b
        return np.clip(action, self.design.action_low, self.design.action_high)
