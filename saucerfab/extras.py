"""The install's optional parts (pip extras), and the error that names the one to install.

``pip install saucerfab`` is the checker: ``saucerfab check`` and the light
commands (``printers``, ``shapes``, ``scene``, ``batch --dry-run``, ``--help``)
need only the base dependencies (numpy, Pillow, defusedxml, rich, lib3mf,
DracoPy: about 130 MiB). The other commands need an extra,
``pip install 'saucerfab[design,verify]'`` or ``'saucerfab[all]'`` for every
command; :data:`EXTRAS` says what each one brings. A command whose extra is
missing stops before any work with :class:`MissingExtraError` (exit 2), which
names the extra and the ``pip install`` line, instead of a traceback from an
import deep inside.

:data:`EXTRAS` and ``pyproject.toml``'s ``[project.optional-dependencies]``
list the same names (``tests/test_extras.py`` holds them together); the
version bounds are pyproject's alone.
"""

from __future__ import annotations

import importlib.util

from saucerfab.errors import SaucerfabError

#: pip extra -> the modules it installs (each module's import name is its distribution's name on PyPI)
EXTRAS: dict[str, tuple[str, ...]] = {
    # design and export: the optimizer (torch), the relief and fabrication kernels (numba), filters and
    # masks (scipy), the solid and its seat (manifold3d), the texture atlas (xatlas)
    "design": ("torch", "numba", "scipy", "manifold3d", "xatlas"),
    # verify (and the quick verify of design and export): the Mitsuba 3 ray tracer; scipy for the scores
    "verify": ("mitsuba", "scipy"),
    # the studio's local web server
    "studio": ("starlette", "uvicorn"),
    # batch --scheduler: jobs on a Dask distributed cluster
    "cluster": ("dask", "distributed"),
    # MeshLab's reader, an independent second opinion on exported meshes (the tests use it)
    "validate": ("pymeshlab",),
}

#: the extra that brings every command (``pip install 'saucerfab[all]'``): these extras together
ALL_EXTRAS: tuple[str, ...] = ("design", "verify", "studio", "cluster")


class MissingExtraError(SaucerfabError):
    """A command needs an extra that is not installed; the message names it and the ``pip install`` line."""


def installed(module: str) -> bool:
    """Whether ``module`` can be imported, found without importing it (importing numba alone takes ~0.7 s)."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a parent package that fails to import, or a module without a spec
        return False


def missing_modules(extra: str) -> list[str]:
    """The modules of ``extra`` (a key of :data:`EXTRAS`) that are not installed, in the table's order."""
    return [m for m in EXTRAS[extra] if not installed(m)]


def pip_line(*extras: str) -> str:
    """The command that installs ``extras``: ``pip install 'saucerfab[design,verify]'``."""
    return f"pip install 'saucerfab[{','.join(extras)}]'"


def require(*extras: str, subject: str = "this command", instead: str | None = None) -> None:
    """Raise :class:`MissingExtraError` unless every module of every one of ``extras`` is installed.

    Called first thing in a command's ``run``, so that a missing extra is said
    before any work is done. The CLI puts ``saucerfab COMMAND: error:`` before
    the message, so it names the command already.

    Args:
        extras: keys of :data:`EXTRAS`.
        subject: what needs them, as the message's subject (``"--scheduler"``).
        instead: another way out, appended to the message (``"add --no-verify to skip it"``).

    Raises:
        MissingExtraError: a module of one of ``extras`` is not installed; the message names the
            extras, their missing modules and the ``pip install`` line.
    """
    absent = {extra: missing_modules(extra) for extra in extras}
    names = [extra for extra, mods in absent.items() if mods]
    if not names:
        return
    what = (f"the '{names[0]}' extra, which is" if len(names) == 1
            else "the " + ", ".join(f"'{n}'" for n in names[:-1]) + f" and '{names[-1]}' extras, which are")
    mods = ", ".join(dict.fromkeys(m for n in names for m in absent[n]))  # scipy is in two extras: named once
    fix = pip_line(*names) + (f", or {instead}" if instead else "")
    raise MissingExtraError(f"{subject} needs {what} not installed ({mods} missing): {fix}")


def require_verify(skipped: bool) -> None:
    """The 'verify' extra, for a command that verifies its result unless ``--no-verify`` (``skipped``).

    Asked before the command's work (a design runs for minutes before its verify).

    Raises:
        MissingExtraError: the verify is not skipped and its extra is not installed.
    """
    if not skipped:
        require("verify", subject="its verify", instead="add --no-verify to skip it")
