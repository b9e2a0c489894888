"""saucerfab's own exports are checked within limits raised to their size, not the hostile-file budgets (issue 16).

The checker's default :class:`~saucerfab.check.Limits` bound a stranger's
file (500,000 triangles, one 8192 x 8192 texture); a design at the largest
grid exports millions of triangles. ``export``, ``batch`` and ``verify``
read their own files with the limits raised to what the export wrote. The
tests lower the default below a tiny export instead of exporting millions of
triangles.
"""

from __future__ import annotations

from pathlib import Path

import pytest

import saucerfab.check as chk
import saucerfab.check.limits as limits_mod
from saucerfab.check import Limits, check_mesh
from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.pipeline import ExportResult, export_design
from saucerfab.model.design_folder import save_design, synthetic_design
from saucerfab.workflow import export_limits, finish_print


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> ExportResult:
    base = tmp_path_factory.mktemp("own")
    design_dir = save_design(synthetic_design(resolution=16, texture_size=64, seed=1), base / "design")
    return export_design(design_dir, base / "print", printer="j55", cup_diameter_mm=80.0,
                         formats=["3mf", "obj", "stl", "glb"], options=FabOptions(texture_px=64))


@pytest.fixture
def low_default(monkeypatch: pytest.MonkeyPatch, exported: ExportResult) -> Limits:
    """A default triangle cap (and vertex and texture caps) under what the export holds."""
    low = Limits(max_triangles=exported.triangles // 2, max_vertices=exported.triangles // 2,
                 max_texture_pixels=32 * 32, max_total_texture_pixels=32 * 32)
    monkeypatch.setattr(chk, "DEFAULT_LIMITS", low)  # what check_mesh uses when given none
    monkeypatch.setattr(limits_mod, "DEFAULT_LIMITS", low)
    return low


def test_a_stranger_file_of_that_size_is_refused_by_the_lowered_default(exported: ExportResult,
                                                                        low_default: Limits) -> None:
    stl = next(p for p in exported.files["stl"] if p.suffix == ".stl")
    r = check_mesh(stl)
    assert r.exit_code == 2 and r.codes == {"over_check_limit"}, r.reason()
    assert "--max-triangles" in r.reason()


def test_finish_print_checks_its_own_export_over_the_default_caps(exported: ExportResult,
                                                                  low_default: Limits) -> None:
    """Before: finish_print checked with the defaults, and refused its own files as too large to check."""
    lim = export_limits(exported)
    assert lim.max_triangles >= exported.triangles > low_default.max_triangles
    assert lim.max_vertices >= 3 * exported.triangles and lim.max_texture_pixels >= exported.texture_px**2
    done = finish_print(exported, "j55", check=True, verify=False)
    assert len(done.checks) == 4
    for c in done.checks:
        r = c.report
        assert r is not None and r.exit_code == 0, (c.name, r.reason())
        assert r.stats["triangles"] <= lim.max_triangles


def test_verify_reads_its_own_export_over_the_default_caps(exported: ExportResult, low_default: Limits) -> None:
    from saucerfab.verify.printfolder import VerifyInputError, folder_limits, load_print_scene, read_surface

    folder = Path(exported.out)
    obj = next(p for p in exported.files["obj"] if p.suffix == ".obj")
    scene = load_print_scene(folder)
    with pytest.raises(VerifyInputError, match="over_check_limit"):
        read_surface(obj, "obj", scene)  # the stranger's-file defaults
    lim = folder_limits(folder)
    assert lim.max_triangles >= exported.triangles
    assert len(read_surface(obj, "obj", scene, lim).faces) <= lim.max_triangles


def test_verify_trusts_a_folder_summary_only_up_to_what_saucerfab_exports(tmp_path: Path) -> None:
    """A folder's export.json claiming a billion triangles raises the caps no further than a real export needs."""
    import json

    from saucerfab.verify.printfolder import MAX_OWN_TRIANGLES, folder_limits

    (tmp_path / "export.json").write_text(json.dumps({"triangles": 10**9, "texture_px": 10**6}))
    lim = folder_limits(tmp_path)
    assert lim.max_triangles == MAX_OWN_TRIANGLES and lim.max_texture_pixels == 16384**2
    (tmp_path / "export.json").write_text("[not a summary")
    assert folder_limits(tmp_path).max_triangles == Limits().max_triangles
