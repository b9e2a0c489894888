"""The command line's one rule for outputs: what a command writes replaces an earlier result only with ``--force``.

Every command that writes takes ``-o/--out`` (``check``: the JSON report;
``scene``, ``shapes``: the file; ``design``, ``export``, ``verify``, ``batch``:
a folder) and ``--force``. ``design`` and ``export`` apply the rule to their
folders themselves (:func:`saucerfab.optimize.checkpoint.check_output_folder`,
:func:`saucerfab.cli.export.check_other_export`), ``verify`` to an ``--out``
it is given (its default folder inside the print is the print's own and is
refreshed), ``batch`` by reusing complete jobs unless ``--force``.
"""

from __future__ import annotations


def refuse_existing(option: str, path: str, force: bool) -> None:
    """Refuse, unless ``force``, to replace the existing file ``path`` given as ``option``.

    Raises:
        ConfigError: ``path`` exists and ``force`` is false.
    """
    from pathlib import Path

    from saucerfab.errors import ConfigError

    if Path(path).exists() and not force:
        raise ConfigError(f"{option} {path!r} exists; add --force to replace it, or give another file")
