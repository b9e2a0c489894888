"""``saucerfab scene``: print a scene (preset or TOML) as validated TOML."""

from __future__ import annotations

import argparse

HELP = "validate a scene TOML (or print a preset, the default one unless named) as TOML"


def add_arguments(p: argparse.ArgumentParser) -> None:
    from saucerfab.model.scene import DEFAULT_PRESET, PRESETS

    p.add_argument("source", nargs="?", default=DEFAULT_PRESET,
                   help=f"scene TOML file or preset: {', '.join(PRESETS)} (default: {DEFAULT_PRESET})")
    p.add_argument("-o", "--out", help="write the TOML here instead of printing it")
    p.add_argument("--force", action="store_true", help="replace an existing --out file")
    p.add_argument("--json", action="store_true", help="print the validated scene as JSON instead of TOML")
    p.add_argument("-q", "--quiet", action="store_true", help="no 'wrote' line (the exit code says it is valid)")


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
