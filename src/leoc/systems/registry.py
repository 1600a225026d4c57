"""The system registry: names resolved once, at the edge (CLI, configs, ``gymnasium.make``).

Below the edge every function takes a :class:`~leoc.systems.base.System` object. A user adds a
plant with :func:`register_system` (see ``docs/user_guide/custom_system.md``)::

    from leoc.systems import register_system
    register_system("damped_cart", DampedCart)

after which ``make_system("damped_cart")``, ``gymnasium.make("leoc/DampedCart-v0")`` and every
``leoc`` command accept it. Registration builds the system once and validates it
(:meth:`~leoc.systems.base.System.validate`), so an inconsistent system fails here, with a
message that names it, and not deep inside a training run.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import NamedTuple

from leoc.systems.base import DEFAULT_EPISODE_STEPS, PhysicalParams, System

#: Anything that builds a :class:`System` from keyword parameters (usually the class).
SystemFactory = Callable[..., System]
_NAME_PATTERN = re.compile(r"^[a-z][a-z0-9_]*$")
GENERIC_ENTRY_POINT = "leoc.systems.envs:LeocEnv"


class Registration(NamedTuple):
    """A registered system: its factory (called as ``factory(params)``) and gymnasium id."""

    name: str
    factory: SystemFactory
    env_id: str


_REGISTRY: dict[str, Registration] = {}


def default_env_id(name: str) -> str:
    """``leoc/<CamelCase name>-v0`` (``damped_cart`` -> ``leoc/DampedCart-v0``)."""
    return "leoc/" + "".join(part.capitalize() for part in name.split("_")) + "-v0"


def register_system(
    name: str,
    factory: SystemFactory,
    env_id: str | None = None,
    *,
    entry_point: str = GENERIC_ENTRY_POINT,
    replace: bool = False,
) -> Registration:
    """Register a system under ``name`` (and its gymnasium environment under ``env_id``).

    Parameters
    ----------
    name : str
        Lower-case identifier (letters, digits, ``_``); must equal ``factory().name``.
    factory : callable
        ``factory(params=None) -> System``; usually the ``System`` subclass itself.
    env_id : str, optional
        Gymnasium id; default :func:`default_env_id`.
    entry_point : str
        Gymnasium entry point; the generic :class:`~leoc.systems.envs.LeocEnv` by default.
    replace : bool
        Allow replacing an existing registration of ``name`` (else a ``ValueError``).

    Raises
    ------
    ValueError
        On a malformed or taken name, a system whose ``name`` differs, or a system that fails
        :meth:`~leoc.systems.base.System.validate`.
    """
    import gymnasium as gym

    if name in _REGISTRY and not replace and isinstance(name, str):
        raise ValueError(f"name: {name!r} is already registered (pass replace=True to replace)")
    system = _checked_system(name, factory)
    env_id = default_env_id(name) if env_id is None else env_id
    registration = Registration(name, factory, env_id)
    _REGISTRY[name] = registration
    if env_id in gym.registry:
        del gym.registry[env_id]
    kwargs = {"system": name} if entry_point == GENERIC_ENTRY_POINT else {}
    gym.register(
        id=env_id,
        entry_point=entry_point,
        max_episode_steps=system.episode_steps,
        kwargs=kwargs,
    )
    return registration


def _checked_system(name: object, factory: object) -> System:
    """``factory()``, checked: a well-formed ``name`` it carries, and a valid system."""
    if not isinstance(name, str) or not _NAME_PATTERN.match(name):
        raise ValueError(
            f"name: expected a lower-case identifier (letters, digits, _), found {name!r}"
        )
    if not callable(factory):
        raise TypeError(f"factory: expected a callable returning a System, found {factory!r}")
    system = factory()
    if not isinstance(system, System):
        raise TypeError(f"factory: expected a System, found {type(system).__name__}")
    if getattr(system, "name", None) != name:
        raise ValueError(
            f"factory: expected a system named {name!r}, found {getattr(system, 'name', None)!r}"
        )
    system.validate()
    return system


def unregister_system(name: str) -> None:
    """Remove a registration (and its gymnasium id); for tests and notebooks."""
    import gymnasium as gym

    registration = _REGISTRY.pop(_check_name(name))
    if registration.env_id in gym.registry:
        del gym.registry[registration.env_id]


def system_names() -> tuple[str, ...]:
    """Names of the registered systems, in registration order."""
    return tuple(_REGISTRY)


def _check_name(name: str) -> str:
    if name not in _REGISTRY:
        raise ValueError(
            f"system: unknown name {name!r}; expected one of {', '.join(_REGISTRY)} "
            "(or register it with leoc.systems.register_system)"
        )
    return name


def env_id(name: str) -> str:
    """The gymnasium id of a registered system."""
    return _REGISTRY[_check_name(name)].env_id


def make_system(
    name: str | System, params: PhysicalParams | None = None, **scales: float
) -> System:
    """Build a registered system, optionally with parameters scaled (``mass=2.0``).

    A ``System`` passed as ``name`` is returned as is (scaled if ``scales`` are given), so edge
    code may accept either.

    Raises
    ------
    ValueError
        If ``name`` is not registered, or a scale names no parameter.
    """
    if isinstance(name, System):
        if params is not None:
            raise ValueError("params: only with a system name, found a System object as well")
        return name.with_params(**scales) if scales else name
    system = _REGISTRY[_check_name(name)].factory(params)
    return system.with_params(**scales) if scales else system


__all__ = [
    "DEFAULT_EPISODE_STEPS",
    "Registration",
    "default_env_id",
    "env_id",
    "make_system",
    "register_system",
    "system_names",
    "unregister_system",
]
