"""A round saucer in a batch manifest (issue 44): ``scene = "round"`` and ``saucer_diameter_mm``.

The diameter is a design option (``design_options``, in TOML and in a CSV's
cell), checked when the manifest loads with the manifest's wording, as
``saucerfab design`` checks ``--saucer-diameter-mm`` before its work.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from saucerfab.batch.jobs import load_payload
from saucerfab.batch.manifest import load_manifest
from saucerfab.errors import ConfigError
from saucerfab.model.scene import CUP_RING_MM, MIN_DISC_BAND_MM, round_scene
from saucerfab.optimize.prepare import build_scene
from saucerfab.optimize.request import DesignRequest


def _folder(tmp_path: Path) -> Path:
    (tmp_path / "img").mkdir()
    (tmp_path / "img" / "a.png").write_bytes(b"a")
    (tmp_path / "img" / "b.png").write_bytes(b"b")
    return tmp_path


def _write(folder: Path, name: str, text: str) -> Path:
    p = folder / name
    p.write_text(text, encoding="utf-8")
    return p


def _job(job_id: str, scene: str, options: str) -> str:
    return f"""
[[job]]
id = "{job_id}"
direct = "img/a.png"
reflected = "img/b.png"
scene = "{scene}"
design_options = {{ {options} }}
"""


def test_a_round_job_in_toml_and_csv_takes_the_diameter(tmp_path: Path) -> None:
    folder = _folder(tmp_path)
    toml = load_manifest(_write(folder, "m.toml", _job("round", "round", "saucer_diameter_mm = 180, resolution = 40")))
    csv = load_manifest(_write(folder, "m.csv", "id,direct,reflected,scene,design_options\n"
                                                "round,img/a.png,img/b.png,round,saucer_diameter_mm=180; resolution=40\n"))
    assert toml.jobs == csv.jobs
    (job,) = toml.jobs
    assert job.scene == "round" and job.design_options == {"saucer_diameter_mm": 180, "resolution": 40}
    # the design run gets it as the request's field, and its scene the disc asked for
    request = load_payload(job, folder).request
    assert request["saucer_diameter_mm"] == 180 and request["scene"] == "round"
    scene = build_scene(DesignRequest(**{**request, "direct": Path("a.png"), "reflected": Path("b.png")}))
    assert scene.saucer.is_disc and 2 * scene.saucer.radius * scene.mm_per_unit == pytest.approx(180.0)


def test_a_round_job_without_the_diameter_is_the_presets(tmp_path: Path) -> None:
    folder = _folder(tmp_path)
    m = load_manifest(_write(folder, "m.csv", "id,direct,reflected,scene\nr,img/a.png,img/b.png,round\n"))
    assert m.jobs[0].scene == "round" and m.jobs[0].design_options == {}


def test_bad_diameters_are_refused_at_load_in_the_manifests_words(tmp_path: Path) -> None:
    folder = _folder(tmp_path)
    cup = round_scene().cup_diameter_mm
    smallest = math.ceil(cup + 2 * (CUP_RING_MM + MIN_DISC_BAND_MM))
    text = "".join([
        _job("text", "round", 'saucer_diameter_mm = "big"'),
        _job("negative", "round", "saucer_diameter_mm = -5"),
        _job("small", "round", f"saucer_diameter_mm = {smallest - 10}"),
        _job("rectangle", "paper", "saucer_diameter_mm = 180"),
        _job("fine", "round", f"saucer_diameter_mm = {smallest}"),
    ])
    with pytest.raises(ConfigError) as exc:
        load_manifest(_write(folder, "m.toml", text))
    lines = {line.split("job '")[1].split("'")[0]: line for line in str(exc.value).splitlines() if "job '" in line}
    assert "4 problem(s)" in str(exc.value), str(exc.value)
    assert "design_options: saucer_diameter_mm must be a number, got 'big'" in lines["text"]
    assert "design_options: saucer_diameter_mm must be a positive number of millimetres, got -5" in lines["negative"]
    assert "design_options: the round saucer" in lines["small"]
    assert f"give a saucer of at least {smallest} mm" in lines["small"]
    assert "design_options: --saucer-diameter-mm is for a round saucer: add --scene round" in lines["rectangle"]
    assert "fine" not in lines
    assert all(line.lstrip().startswith("m.toml:") for line in lines.values()), lines  # file and line, as every problem


def test_a_scene_file_job_leaves_the_diameter_to_its_file(tmp_path: Path) -> None:
    """The scene file is the job's input, read when the job runs: its outline judges the diameter then."""
    folder = _folder(tmp_path)
    (folder / "disc.toml").write_text('preset = "round"\n', encoding="utf-8")
    m = load_manifest(_write(folder, "m.toml", _job("file", "disc.toml", "saucer_diameter_mm = 180")))
    assert m.jobs[0].design_options == {"saucer_diameter_mm": 180} and "scene" in m.jobs[0].files
