"""Checks of user-given numbers and tables, shared by the scene and its cups.

Each check raises :class:`saucerfab.errors.ConfigError` naming the value, so
a wrong scene file or CLI spec stops with a sentence, never a traceback.
"""

from __future__ import annotations

import math
from typing import Any

from saucerfab.errors import ConfigError


def check_finite(name: str, *values: float) -> None:
    """Refuse anything but finite ints and floats (bools too: they are ints to Python)."""
    for v in values:
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
            raise ConfigError(f"{name} must be a finite number, got {v!r}")


def check_positive(name: str, v: float) -> None:
    """Refuse anything but a finite number above zero."""
    check_finite(name, v)
    if v <= 0:
        raise ConfigError(f"{name} must be positive, got {v!r}")


def as_vector(name: str, v: Any, n: int) -> tuple[float, ...]:
    """``v`` as a tuple of ``n`` finite floats."""
    try:
        t = tuple(float(x) for x in v)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a list of {n} numbers, got {v!r}") from None
    if len(t) != n:
        raise ConfigError(f"{name} must have {n} components, got {len(t)}: {v!r}")
    check_finite(name, *t)
    return t


def check_keys(where: str, d: dict[str, Any], allowed: set[str]) -> None:
    """Refuse keys of the table ``d`` outside ``allowed`` (a typo would otherwise be ignored)."""
    unknown = set(d) - allowed
    if unknown:
        raise ConfigError(
            f"unknown key(s) {sorted(unknown)} in {where}; allowed: {sorted(allowed)}"
        )
