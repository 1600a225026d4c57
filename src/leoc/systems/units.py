"""Units of the state variables, for axis labels.

A system may declare ``state_units`` (one unit string per state, "" for a dimensionless one);
otherwise the unit follows from the state's name, by the naming habit of leoc's systems: an
angle (``theta``, ``theta1``, ``phi``, ``alpha``) is in rad, a position (``x``, ``y``, ``z``) in
m, and ``NAME_dot`` has the unit of ``NAME`` per second.
"""

from __future__ import annotations

import re
from typing import Any

RATE_SUFFIX = "_dot"
_ANGLE = re.compile(r"^(theta|phi|psi|alpha|beta|angle)\d*$")
_POSITION = re.compile(r"^(x|y|z|position)\d*$")


def unit_of(name: str) -> str:
    """The unit of a state named ``name`` ("" when the name does not tell)."""
    if name.endswith(RATE_SUFFIX):
        base = unit_of(name[: -len(RATE_SUFFIX)])
        return f"{base}/s" if base else ""
    if _ANGLE.match(name):
        return "rad"
    if _POSITION.match(name):
        return "m"
    return ""


def state_units(system: Any) -> tuple[str, ...]:
    """One unit per state: the system's ``state_units`` if it declares them, else by name."""
    declared = getattr(system, "state_units", None)
    if declared is not None:
        return tuple(declared)
    return tuple(unit_of(name) for name in system.state_names)


def state_axis_label(system: Any, index: int) -> str:
    """``theta [rad]``, ``x_dot [m/s]``; the bare name when its unit is unknown."""
    unit = state_units(system)[index]
    name = system.state_names[index]
    return f"{name} [{unit}]" if unit else name
