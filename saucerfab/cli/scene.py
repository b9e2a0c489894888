"""``saucerfab scene``: print a scene (preset or TOML) as validated TOML."""

from __future__ import annotations

import argparse

HELP = "validate a scene TOML (or print the paper preset) as TOML"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("source", nargs="?", default="paper", help="scene TOML file or preset (default: paper)")
    p.add_argument("--out", help="write the TOML here instead of printing it")


def run(args: argparse.Namespace) -> int:
    from saucerfab.fileio import write_text_atomic
    from saucerfab.scene import load_scene, scene_to_toml

    text = scene_to_toml(load_scene(args.source))
    if args.out:
        write_text_atomic(args.out, text)
        print(f"wrote {args.out}")
    else:
        print(text, end="")
    return 0
