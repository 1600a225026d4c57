"""leoc: Locally Enforced Optimal Controllers.

A hybrid controller pi(x) = r(x) G(x) + (1 - r(x)) H(x) that equals an LQR design G near an
operating point and a learned policy H elsewhere (Zhang & Capel, L4DC 2021).
"""

__version__ = "0.1.0"

# gymnasium convention: importing the package registers its environments (leoc/...-v0); the
# systems package registers every built-in system (and its env) on import.
import leoc.systems  # noqa: E402, F401
