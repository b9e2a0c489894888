"""Reading a small, user-written TOML file (a printer profile, a scene) with every failure a user error.

A TOML file saucerfab reads holds a few lines of settings, so one that is
large, not TOML, or nested deeply enough to exhaust ``tomllib``'s recursion
is the file's fault: each is raised as a :class:`~saucerfab.errors.ConfigError`
that names the file and says what such a file looks like.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from saucerfab.errors import ConfigError


def _size_text(n_bytes: int) -> str:
    """``100 kB``, ``1 MB``: a byte limit as messages show it (SI units)."""
    return f"{n_bytes / 1e6:g} MB" if n_bytes >= 1_000_000 else f"{n_bytes / 1e3:g} kB"


def read_toml(path: Path, what: str, *, max_bytes: int, size_hint: str, nesting_hint: str) -> dict[str, Any]:
    """The TOML file ``path`` as a dict.

    Args:
        path: an existing file (the caller says what a missing one means).
        what: how messages name it, e.g. ``"printer profile"``.
        max_bytes: larger files are refused before they are read.
        size_hint: what such a file looks like, said when it is too large.
        nesting_hint: what such a file looks like, said when it nests too deeply.

    Raises:
        ConfigError: too large, not UTF-8 TOML, or nested too deeply to parse.
    """
    if path.stat().st_size > max_bytes:
        raise ConfigError(f"{what} {str(path)!r} is over {_size_text(max_bytes)}; {size_hint}")
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{what} {str(path)!r} is not valid TOML: {exc}") from None
    except RecursionError:  # tomllib parses nested arrays recursively: a hostile file exhausts the stack
        raise ConfigError(f"{what} {str(path)!r} nests arrays or tables too deeply to be read; {nesting_hint}") from None
