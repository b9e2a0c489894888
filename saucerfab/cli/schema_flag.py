"""``--schema`` and the missing-input error that the reporting commands (``check``, ``verify``) share.

Both print a JSON document with ``--json`` and its JSON Schema with
``--schema``; both need an input unless ``--schema`` is given::

    def add_arguments(p):
        ...
        add_schema_flag(p)

    def run(args):
        if schema_asked(args, JSON_SCHEMA, args.folder, "give the print folder to verify: ..."):
            return 0

Light on purpose: ``saucerfab --help`` imports every command's module.
"""

from __future__ import annotations

import argparse
import json
from typing import Any

from saucerfab.errors import ConfigError


def add_schema_flag(p: argparse.ArgumentParser) -> None:
    """The ``--schema`` option (prints the JSON Schema of ``--json`` output and exits)."""
    p.add_argument("--schema", action="store_true", help="print the JSON Schema of --json output and exit")


def schema_asked(args: argparse.Namespace, schema: dict[str, Any], given: object, missing: str) -> bool:
    """True after printing ``schema`` when ``--schema`` was given.

    Otherwise raises :class:`~saucerfab.errors.ConfigError` with ``missing``
    when ``given`` (the command's input: files, a folder) is empty, and
    returns False.
    """
    if args.schema:
        print(json.dumps(schema, indent=2))
        return True
    if not given:
        raise ConfigError(missing)
    return False
