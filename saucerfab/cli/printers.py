"""``saucerfab printers``: list the printer profiles (shipped and the user's own)."""

from __future__ import annotations

import argparse

HELP = "list printer profiles (build volume, minimum wall, dpi, formats)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print as JSON")
    p.add_argument("-q", "--quiet", action="store_true", help="print only the keys, one a line")


def run(args: argparse.Namespace) -> int:
    import json
    from dataclasses import asdict

    from saucerfab.model.profiles import list_profiles

    profiles = list_profiles()
    if args.json:
        print(json.dumps({k: asdict(v) for k, v in profiles.items()}, indent=2))
        return 0
    if args.quiet:
        print("\n".join(profiles))
        return 0
    print(f"{'key':16s} {'name':28s} {'build volume mm':20s} {'wall':>5s} {'dpi':>5s}  formats (preferred first)")
    for k, p in profiles.items():
        vol = "x".join(f"{v:g}" for v in p.build_volume_mm)
        fmts = [p.preferred_format] + [f for f in p.accepted_formats if f != p.preferred_format]
        print(f"{k:16s} {p.name:28s} {vol:20s} {p.min_wall_mm:5.1f} {p.dpi:5g}  {','.join(fmts)}")
    print("add your own: a TOML like printers/j55.toml in $SAUCERFAB_PRINTERS, or pass its path")
    return 0
