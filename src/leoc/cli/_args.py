"""Argument types and the parser class shared by the commands (no heavy imports here)."""

from __future__ import annotations

import argparse
from pathlib import Path

from leoc.names import BUILTIN_SYSTEM_NAMES, RELEVANCE_NAMES

SYSTEM_HELP = (
    f"system name: {', '.join(BUILTIN_SYSTEM_NAMES)}, or a system registered by a module "
    "imported first (docs/user_guide/custom_system.md)"
)


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line on stderr (exit status 2)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _integer(text: str, expected: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {expected}, found {text!r}") from None


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1."""
    value = _integer(text, "a positive integer")
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, found {value}")
    return value


def non_negative_int(text: str) -> int:
    """argparse type: an integer >= 0."""
    value = _integer(text, "a non-negative integer")
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a non-negative integer, found {value}")
    return value


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, found {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number, found {text}")
    return value


def registered_names() -> tuple[str, ...]:
    """Every registered system name (imports the systems, hence torch: only when needed)."""
    from leoc.systems import system_names

    return system_names()


def system_name(text: str) -> str:
    """argparse type: a registered system name; built-in names resolve without importing the
    systems (so parsing stays instant), others look the registry up."""
    if text in BUILTIN_SYSTEM_NAMES or text in registered_names():
        return text
    raise argparse.ArgumentTypeError(
        f"invalid choice: {text!r} (expected one of {', '.join(registered_names())})"
    )


def system_or_run_dir(text: str) -> str | Path:
    """argparse type: a registered system name, or an existing run folder (a :class:`Path`)."""
    if text in BUILTIN_SYSTEM_NAMES:
        return text
    if Path(text).is_dir():
        return Path(text)
    if text in registered_names():
        return text
    raise argparse.ArgumentTypeError(
        f"invalid choice: {text!r} (expected a run folder or one of "
        f"{', '.join(registered_names())})"
    )


def registered_relevance_names() -> tuple[str, ...]:
    """Every relevance design's name (``leoc.policies.RELEVANCE_DESIGNS``; imports torch: only
    when needed)."""
    from leoc.policies.spec import RELEVANCE_DESIGNS

    return tuple(RELEVANCE_DESIGNS)


def relevance_name(text: str) -> str:
    """argparse type: a relevance design's name; the names of :data:`leoc.names.RELEVANCE_NAMES`
    resolve without importing torch, others look ``leoc.policies.RELEVANCE_DESIGNS`` up (so a
    design added there is a choice at once)."""
    if text in RELEVANCE_NAMES or text in registered_relevance_names():
        return text
    raise argparse.ArgumentTypeError(
        f"invalid choice: {text!r} (expected one of {', '.join(registered_relevance_names())})"
    )


def numbers(text: str) -> float | tuple[float, ...]:
    """argparse type: one number, or several separated by commas (a tuple); their range is
    checked by whatever takes them (``HybridSpec``)."""
    try:
        values = tuple(float(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a number or comma-separated numbers, found {text!r}"
        ) from None
    return values[0] if len(values) == 1 else values


def category_level(text: str) -> tuple[str, float]:
    """argparse type: ``KEY=NUMBER``, a perturbation category (``parameter_error.CONSTANT`` for
    a parameter error) and its level, as ``(key, number)``; which keys and levels are valid is
    :class:`leoc.systems.TrainingPerturbations`'s to say."""
    key, separator, value = text.partition("=")
    if not separator or not key.strip():
        raise argparse.ArgumentTypeError(
            f"expected CATEGORY=LEVEL (e.g. observation_noise=0.1), found {text!r}"
        )
    try:
        number = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected CATEGORY=LEVEL with LEVEL a number, found {text!r}"
        ) from None
    return key.strip(), number


def option_value(text: str) -> int | float | bool | str:
    """A ``KEY=VALUE`` option's value as Python reads it: an integer (``1000``), a number
    (``0.5``, ``1e-3``), ``true``/``false`` (any case), else the text itself."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    lowered = text.strip().lower()
    return {"true": True, "false": False}.get(lowered, text)


def env_option(text: str) -> tuple[str, int | float | bool | str]:
    """argparse type of ``--env-option``: ``KEY=VALUE``, a keyword of ``gymnasium.make`` (a
    Python name) and its value (:func:`option_value`), as ``(key, value)``."""
    key, separator, value = text.partition("=")
    if not separator or not key.strip().isidentifier() or not value.strip():
        raise argparse.ArgumentTypeError(
            f"expected KEY=VALUE with KEY a keyword of gymnasium.make (e.g. "
            f"reset_noise_scale=0.5), found {text!r}"
        )
    return key.strip(), option_value(value.strip())


def env_kwargs_of(options: list[tuple[str, object]] | None) -> dict[str, object]:
    """The ``env_kwargs`` of repeated ``--env-option`` values; a key given twice is refused."""
    found: dict[str, object] = {}
    for key, value in options or ():
        if key in found:
            raise ValueError(
                f"--env-option: expected each KEY once, found {key!r} twice ({found[key]!r}, "
                f"{value!r})"
            )
        found[key] = value
    return found


def add_env_option(parser: argparse.ArgumentParser | argparse._ArgumentGroup, scope: str) -> None:
    """Add the repeatable ``--env-option KEY=VALUE`` (:func:`env_option`) to ``parser``;
    ``scope`` leads its help (where it applies)."""
    parser.add_argument(
        "--env-option",
        action="append",
        type=env_option,
        metavar="KEY=VALUE",
        help=f"{scope}: a keyword of gymnasium.make (numbers read as numbers, e.g. "
        "reset_noise_scale=0.5 or max_episode_steps=1000); repeatable",
    )
