"""The designer's default path, end to end through the CLI, on every bundled sample pair:
the default design exports for every bundled printer profile with exit 0, in every
format the profile takes, and ``saucerfab check --strict`` passes on each file.

Small sizes (a 40 x 40 grid, 96 px renders, few iterations) keep this in CI. The demo's pair
exports at the printer's own atlas (8192 px for the default 185 mm part on the J55); the other pairs
at :data:`OTHER_PAIRS_ATLAS_PX`, which the checker's texel-density rules still pass on every profile
and which keeps the suite under 15 minutes on two cores (each 8192 px export takes about 3x as long); the full-size figures are in benchmarks/results/HISTORY.md, "Default path,
printable (issue 14)" (bench_verify.py).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from saucerfab.cli import main as cli
from saucerfab.model.profiles import list_profiles
from saucerfab.samples import DEMO_PAIR, PAIRS, pair_paths

SMALL = ["--resolution", "40", "--image-size", "96", "--max-iters", "25"]
MESH_SUFFIXES = (".3mf", ".obj", ".glb", ".ply", ".wrl", ".stl", ".zip")
#: the atlas side of the non-demo pairs' exports (the 100 mm part's own on the J55)
OTHER_PAIRS_ATLAS_PX = 4096
PROFILES = sorted(list_profiles())


def design(pair: str, out: Path, *extra: str) -> Path:
    direct, reflected = pair_paths(pair)
    rc = cli(["design", "--direct", str(direct), "--reflected", str(reflected), "-o", str(out),
              "--no-verify", "-q", *SMALL, *extra])
    assert rc == 0, f"design of {pair} failed"
    return out


def export_strict(folder: Path, tmp: Path, capsys: pytest.CaptureFixture[str], *, all_formats: bool = False,
                  check_cli: bool = False, profiles: list[str] | None = None,
                  texture_px: int | None = None) -> dict[str, dict]:
    """Export ``folder`` for every bundled profile; every file must pass the checker with no warning.

    The export checks what it writes (the same checker); its findings are held
    to ``--strict`` here (no error, no warning). ``check_cli`` runs
    ``saucerfab check --strict`` on the files too, as a CI pipeline would.
    ``texture_px`` pins the atlas's side (None: the printer's own).
    Returns each export's JSON summary by profile.
    """
    import json

    done: dict[str, dict] = {}
    capsys.readouterr()  # what came before (the design's own lines)
    for key, prof in list_profiles().items():
        if profiles is not None and key not in profiles:
            continue
        out = tmp / f"print_{key}"
        fmts = ["--formats", ",".join(prof.accepted_formats)] if all_formats else []  # else the profile's preferred
        atlas = [] if texture_px is None else ["--texture-px", str(texture_px)]
        rc = cli(["export", str(folder), "--printer", key, *fmts, *atlas, "--no-verify", "--json", "-o", str(out)])
        captured = capsys.readouterr()
        assert rc == 0, f"export for {key} failed: {captured.err}"
        summary = json.loads(captured.out)
        done[key] = summary
        for c in summary["checks"]:
            loud = [f for f in c["findings"] if f["severity"] in ("error", "warning")]
            assert c["verdict"] == "printable" and not loud, f"{key}: {c['path']}: {loud}"
        files = sorted(str(p) for p in out.iterdir() if p.suffix.lower() in MESH_SUFFIXES)
        assert len(files) == (len(prof.accepted_formats) if all_formats else 1)
        if check_cli:
            rc = cli(["check", "--strict", "--printer", key, *files])
            report = capsys.readouterr().out
            assert rc == 0, f"check --strict for {key} failed:\n{report}"
    return done


@pytest.mark.parametrize("pair", list(PAIRS))
def test_default_design_of_every_sample_prints_on_every_profile(
    pair: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert len(PROFILES) >= 5
    folder = design(pair, tmp_path / "design")
    # the demo's pair in every format each profile takes, checked by `saucerfab check --strict` as
    # a CI pipeline would; the others in each profile's preferred format (what export writes by default)
    demo = pair == DEMO_PAIR
    export_strict(folder, tmp_path, capsys, all_formats=demo, check_cli=demo,
                  texture_px=None if demo else OTHER_PAIRS_ATLAS_PX)


def test_a_design_fine_enough_for_thin_crests_is_kept_printable(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # a 40 mm cup on a 56 x 56 grid: 0.91 mm between vertices, under twice the bureau's 0.5 mm
    # minimum feature, so crests can be too thin there (at 80 mm and 150 x 150 it is 0.67 mm)
    import json

    fine = ["--cup-diameter-mm", "40", "--resolution", "56"]
    bureau = design("heart-star", tmp_path / "bureau", "--printer", "bureau", *fine)
    meta = json.loads((bureau / "design.json").read_text())
    assert meta["parameters"]["print_target"]["printer"] == "bureau"
    assert meta["scene"]["cup_diameter_mm"] == 40
    pm = meta["metrics"]["printable"]
    assert pm["crests_can_be_thin"] and pm["projection_calls"] > 0
    assert pm["thin_crest_vertices"] == 0 and pm["thin_wall_crest_vertices"] == 0
    done = export_strict(bureau, tmp_path / "b", capsys, profiles=["bureau", "mimaki_3duj553"])
    # made for the bureau: its export has nothing left to blunt. (The bureau's rules do not imply the
    # Mimaki's: a crest under 2 mm tall is no wall to the bureau but may be one to the Mimaki's 1.2 mm
    # wall rule, so the Mimaki's export may move a few vertices; it says so, and checks clean.)
    assert not any("relief vertices were moved" in w for w in done["bureau"]["warnings"])
    # made for the J55 (feature 0.3 mm, wall 1 mm): the bureau's export (0.5 mm, 2 mm) blunts, and says so
    j55 = design("heart-star", tmp_path / "j55", *fine)
    done = export_strict(j55, tmp_path / "j", capsys, profiles=["j55", "bureau"])
    assert not any("relief vertices were moved" in w for w in done["j55"]["warnings"])
    assert any("relief vertices were moved" in w and "--printer bureau" in w for w in done["bureau"]["warnings"])
