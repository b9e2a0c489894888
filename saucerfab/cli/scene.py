"""``saucerfab scene``: print a scene (preset or TOML) as validated TOML."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from saucerfab.model.scene import Scene

HELP = "validate a scene TOML (or print a preset, the default one unless named) as TOML"


def add_arguments(p: argparse.ArgumentParser) -> None:
    from saucerfab.model.scene import DEFAULT_PRESET, PRESETS

    presets = "; ".join(f"{name} ({preset_words(factory())})" for name, factory in PRESETS.items())
    p.add_argument("source", nargs="?", default=DEFAULT_PRESET,
                   help=f"scene TOML file or preset: {presets} (default: {DEFAULT_PRESET})")
    p.add_argument("-o", "--out", help="write the TOML here instead of printing it")
    p.add_argument("--force", action="store_true", help="replace an existing --out file")
    p.add_argument("--json", action="store_true", help="print the validated scene as JSON instead of TOML")
    p.add_argument("-q", "--quiet", action="store_true", help="no 'wrote' line (the exit code says it is valid)")


def preset_words(scene: Scene) -> str:
    """What a scene's saucer is, in a few words with its size in mm (``a 200 mm round saucer, the cup at its centre``)."""
    s, mm = scene.saucer, scene.mm_per_unit
    if s.is_disc:
        return f"a {2.0 * s.radius * mm:g} mm round saucer, the cup at its centre"
    width, depth = s.size
    return f"a {width * mm:g} x {depth * mm:g} mm rectangle in front of the cup"


def run(args: argparse.Namespace) -> int:
    import json
    import tomllib

    from saucerfab.cli.outputs import refuse_existing
    from saucerfab.files.fileio import write_text_atomic
    from saucerfab.model.scene import load_scene, scene_to_toml

    text = scene_to_toml(load_scene(args.source))
    if args.json:  # the same validated scene, as JSON (the TOML's tables and keys)
        text = json.dumps(tomllib.loads(text), indent=2) + "\n"
    if args.out:
        refuse_existing("--out", args.out, args.force)
        write_text_atomic(args.out, text)
        if not args.quiet:
            print(f"wrote {args.out}")
    elif not args.quiet:
        print(text, end="")
    return 0
