"""Tests of saucerfab.model.scene: the paper preset, validation, TOML round trips, cup specs."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from saucerfab.errors import ConfigError, GeometryError, SaucerfabError
from saucerfab.model.cups import CircleCup, EllipseCup, PrismCup, parse_cup_spec
from saucerfab.model.scene import (
    Saucer,
    Scene,
    ViewFrame,
    load_scene,
    paper_scene,
    scene_from_dict,
    scene_to_dict,
    scene_to_toml,
)


def test_paper_preset_has_the_papers_values() -> None:
    s = paper_scene()
    assert s.camera == (0.0, -5.5, 5.0)
    assert s.direct.target == (0.0, 0.0, -0.8) and s.direct.viewing_angle_deg == 4.5
    assert s.reflected.target == (0.0, 0.0, 0.1) and s.reflected.viewing_angle_deg == 3.0
    assert s.direct.image_size == s.reflected.image_size == 512
    assert isinstance(s.cup, CircleCup) and s.cup.radius == 0.4
    assert s.saucer.x_range == (-0.5, 0.5) and s.saucer.y_range == (-1.5, -0.5)
    assert s.saucer.resolution == 150 and s.saucer.delta == 0.05
    assert load_scene("paper") == s
    # 80 mm across a cup of diameter 0.8 units: 100 mm per unit
    assert math.isclose(s.mm_per_unit, 100.0)


def test_cup_geometry() -> None:
    c = CircleCup(0.4)
    assert c.contains(np.array([[0.0, 0.0], [0.39, 0.0], [0.41, 0.0]])).tolist() == [True, True, False]
    np.testing.assert_allclose(np.linalg.norm(c.boundary(64), axis=1), 0.4)
    e = EllipseCup((0.5, 0.2), 90.0)  # the long axis along y after rotation
    assert e.contains(np.array([[0.0, 0.45], [0.45, 0.0], [0.15, 0.0]])).tolist() == [True, False, True]
    assert (e.circumradius, e.inradius) == (0.5, 0.2)
    b = e.boundary(100)
    np.testing.assert_allclose(b[:, 1] ** 2 / 0.25 + b[:, 0] ** 2 / 0.04, 1.0, atol=1e-12)
    p = PrismCup(4, 1.0, 45.0)  # axis-aligned square of half side sqrt(1/2)
    h = math.sqrt(0.5)
    np.testing.assert_allclose(np.abs(p.boundary()), h, atol=1e-12)
    assert math.isclose(p.inradius, h)
    assert p.contains(np.array([[0.7, 0.0], [0.71, 0.0], [0.0, -0.7]])).tolist() == [True, False, True]
    # counter-clockwise outlines (positive signed area)
    for cup in (c, e, p, PrismCup(6)):
        v = cup.boundary()
        area = 0.5 * np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1])
        assert area > 0


@pytest.mark.parametrize(
    "scene",
    [
        paper_scene(),
        Scene(cup=EllipseCup((0.45, 0.3), 15.0, 0.8), cup_diameter_mm=95.5),
        Scene(
            camera=(0.3, -6.0, 4.25),
            direct=ViewFrame((0.0, -0.1, -0.7), 5.0, 256),
            reflected=ViewFrame((0.0, 0.0, 0.2), 2.5, 128),
            cup=PrismCup(6, 0.45, 30.0, 1.2),
            saucer=Saucer((-0.6, 0.6), (-1.7, -0.55), 64, 0.03),
            cup_diameter_mm=100,
        ),
        Scene(cup=CircleCup(0.1 + 0.2, 1e-5)),  # floats whose repr is not "short"
    ],
)
def test_toml_round_trip(scene: Scene, tmp_path: Path) -> None:
    path = tmp_path / "scene.toml"
    path.write_text(scene_to_toml(scene), encoding="utf-8")
    back = load_scene(path)
    assert back == scene
    assert scene_from_dict(scene_to_dict(scene)) == scene


def test_partial_tables_keep_the_preset_values(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    path.write_text('preset = "paper"\n[cup]\nshape = "prism"\nsides = 8\n[saucer]\nresolution = 64\n')
    s = load_scene(path)
    assert s.cup == PrismCup(sides=8) and s.saucer.resolution == 64
    assert s.camera == paper_scene().camera and s.saucer.delta == 0.05
    # without a shape the cup keeps the base's kind
    assert scene_from_dict({"cup": {"radius": 0.3}}).cup == CircleCup(0.3)


def test_geometry_errors() -> None:
    with pytest.raises(GeometryError, match="inside the cup"):
        Scene(camera=(0.1, 0.1, 3.0))
    with pytest.raises(GeometryError, match="overlaps"):
        Scene(cup=CircleCup(0.6))  # reaches y = -0.6, past the saucer's edge at -0.5
    with pytest.raises(GeometryError, match="overlaps"):
        Scene(saucer=Saucer((-0.5, 0.5), (-1.0, 0.0)))  # the saucer runs under the cup
    with pytest.raises(GeometryError, match="overlaps"):
        Scene(cup=PrismCup(4, 0.52, -90.0))  # a corner pokes into the saucer at (0, -0.52)
    with pytest.raises(GeometryError, match="overlaps"):
        Scene(cup=EllipseCup((0.3, 0.52)))
    Scene(cup=EllipseCup((0.3, 0.49)))  # clear of it: fine
    with pytest.raises(ConfigError, match="coincides"):
        Scene(direct=ViewFrame((0.0, -5.5, 5.0), 4.5))
    # GeometryError is a user error with the CLI's exit code
    assert issubclass(GeometryError, SaucerfabError) and GeometryError.exit_code == 2


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: CircleCup(0.0), "cup radius must be positive"),
        (lambda: CircleCup(-0.4), "cup radius must be positive"),
        (lambda: CircleCup(0.4, 0.0), "cup height must be positive"),
        (lambda: EllipseCup((0.4, -0.1)), "semi-axis b must be positive"),
        (lambda: EllipseCup((0.4,)), "2 components"),
        (lambda: PrismCup(2), r"sides must be an integer in \[3, 64\]"),
        (lambda: PrismCup(65), "sides"),
        (lambda: PrismCup(6.0), "sides"),  # type: ignore[arg-type]
        (lambda: PrismCup(6, -1.0), "circumradius must be positive"),
        (lambda: Saucer(delta=0.0), "delta must be positive"),
        (lambda: Saucer((0.5, -0.5)), "increasing"),
        (lambda: Saucer(resolution=3), r"resolution must be an integer in \[4, 1024\]"),
        (lambda: Saucer(resolution=1025), "resolution"),
        (lambda: Saucer(resolution=150.0), "resolution"),  # type: ignore[arg-type]
        (lambda: ViewFrame((0, 0, 0), 0.0), "viewing_angle_deg must be positive"),
        (lambda: ViewFrame((0, 0, 0), 89.5), "below 89"),
        (lambda: ViewFrame((0, 0, 0), 3.0, 7), r"image_size must be an integer in \[8, 4096\]"),
        (lambda: ViewFrame((0, 0, 0), 3.0, 5000), "image_size"),
        (lambda: ViewFrame((0, 0), 3.0), "3 components"),
        (lambda: Scene(cup_diameter_mm=0.0), "cup_diameter_mm must be positive"),
        (lambda: Scene(camera=(0.0, float("nan"), 5.0)), "finite"),
        (lambda: Scene(camera=(0.0, -5.5, math.inf)), "finite"),
        (lambda: Scene(camera=("a", 1, 2)), "list of 3 numbers"),  # type: ignore[arg-type]
        (lambda: CircleCup(float("nan")), "finite"),
        (lambda: Saucer(delta=float("nan")), "finite"),
        (lambda: ViewFrame((0, 0, 0), float("nan")), "finite"),
    ],
)
def test_bad_values_raise_config_error(make, match: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ConfigError, match=match):
        make()


@pytest.mark.parametrize(
    "table, match",
    [
        ({"camra": [0, -5, 5]}, r"unknown key\(s\) \['camra'\]"),
        ({"cup": {"shape": "circle", "radius": 0.4, "sides": 6}}, r"unknown key\(s\) \['sides'\]"),
        ({"cup": {"shape": "cone"}}, "unknown cup shape 'cone'"),
        ({"cup": "circle"}, r"\[cup\] must be a table"),
        ({"saucer": {"resolutoin": 64}}, "resolutoin"),
        ({"direct": {"fov": 3}}, "fov"),
        ({"preset": "siggraph"}, "unknown scene preset 'siggraph'"),
        ({"preset": ["paper"]}, "unknown scene preset"),
        ({"saucer": {"resolution": 2}}, "resolution"),
        ({"direct": {"image_size": 4097}}, "image_size"),
        ({"saucer": {"delta": float("nan")}}, "finite"),
        ({"camera": [0, -5.5]}, "3 components"),
        ({"saucer": 5}, "invalid scene description|unknown key"),
    ],
)
def test_bad_tables_raise_config_error(table: dict, match: str) -> None:  # type: ignore[type-arg]
    with pytest.raises(ConfigError, match=match):
        scene_from_dict(table)


def test_load_scene_file_errors(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not found"):
        load_scene(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("camera = [0, -5.5, 5\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_scene(bad)
    binary = tmp_path / "bin.toml"
    binary.write_bytes(b"\xff\xfe\x00camera")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_scene(binary)
    nan = tmp_path / "nan.toml"
    nan.write_text("[cup]\nradius = nan\n")
    with pytest.raises(ConfigError, match="finite"):
        load_scene(nan)
    inside = tmp_path / "inside.toml"
    inside.write_text("camera = [0.0, 0.0, 5.0]\n")
    with pytest.raises(GeometryError, match="inside"):
        load_scene(inside)
    big = tmp_path / "big.toml"
    big.write_text("# x\n" * 300_000)
    with pytest.raises(ConfigError, match="over 1 MB"):
        load_scene(big)


@pytest.mark.parametrize(
    "spec, cup",
    [
        ("circle", CircleCup()),
        ("circle:0.3", CircleCup(0.3)),
        ("ellipse:0.45,0.3", EllipseCup((0.45, 0.3))),
        ("ellipse:0.45,0.3,20", EllipseCup((0.45, 0.3), 20.0)),
        ("prism:6", PrismCup(6)),
        ("prism:8,0.5", PrismCup(8, 0.5)),
        (" prism:5,0.42,36 ", PrismCup(5, 0.42, 36.0)),
    ],
)
def test_parse_cup_spec(spec: str, cup: object) -> None:
    assert parse_cup_spec(spec) == cup


@pytest.mark.parametrize(
    "spec, match",
    [
        ("cone", "unknown cup spec"),
        ("circle:0.3,0.2", "unknown cup spec"),
        ("ellipse:0.4", "unknown cup spec"),
        ("prism", "unknown cup spec"),
        ("prism:6.5", "must be whole"),
        ("prism:nan", "must be whole"),
        ("prism:inf", "must be whole"),
        ("prism:2", "sides"),
        ("prism:six", "must be numbers"),
        ("circle:-0.4", "positive"),
        ("circle:nan", "finite"),
    ],
)
def test_parse_cup_spec_errors(spec: str, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        parse_cup_spec(spec)


def test_with_changes_validates_again() -> None:
    s = paper_scene()
    assert s.with_changes(cup_diameter_mm=120.0).mm_per_unit == pytest.approx(150.0)
    with pytest.raises(GeometryError):
        s.with_changes(camera=(0.0, 0.0, 2.0))
    assert replace(s, cup=PrismCup(6, 0.45)).cup_width_units == pytest.approx(0.9)
    assert replace(s, cup=EllipseCup((0.45, 0.3))).cup_width_units == pytest.approx(0.9)


# --------------------------------------------------------------------------- issue 16: view axes, deep files


@pytest.mark.parametrize("view", ["direct", "reflected", "reflected2"])
def test_a_vertical_view_axis_is_a_config_error_when_the_scene_loads(tmp_path: Path, view: str) -> None:
    """A target straight below (or above) the camera leaves the view's up direction
    undefined; it used to load and fail later as a ValueError deep in a render."""
    path = tmp_path / "vertical.toml"
    path.write_text(f"camera = [0.0, -5.5, 5.0]\n\n[{view}]\ntarget = [0.0, -5.5, -0.8]\nviewing_angle_deg = 3.0\n")
    with pytest.raises(ConfigError, match=f"the {view} view axis.*is vertical") as exc:
        load_scene(path)
    assert "Move the target" in str(exc.value)
    with pytest.raises(ConfigError, match="vertical"):
        replace(paper_scene(), camera=(0.0, -5.5, 5.0), direct=ViewFrame((0.0, -5.5, 9.0), 4.5, 64))
    # a hair off the vertical is a valid (if odd) view, as the renderer sees it
    from saucerfab.model.camera import Camera

    tilted = replace(paper_scene(), direct=ViewFrame((1e-6, -5.5, -0.8), 4.5, 64))
    Camera.from_scene(tilted, "direct").axes()


def test_a_deeply_nested_scene_file_is_a_config_error(tmp_path: Path) -> None:
    path = tmp_path / "deep.toml"
    path.write_text("camera = " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(ConfigError, match="too deeply"):
        load_scene(path)


def test_the_named_scenes_and_the_default() -> None:
    """`paper` is the paper's section 4 setup; `wide`, the default, the same eye and cup over a 185 mm saucer."""
    from saucerfab.model.scene import DEFAULT_PRESET, PRESETS, WIDE_X_RANGE
    from saucerfab.optimize.request import DesignRequest

    assert DEFAULT_PRESET == "wide" == DesignRequest.default("scene") and set(PRESETS) == {"paper", "wide", "round"}
    wide, paper = load_scene("wide"), load_scene("paper")
    assert wide.saucer.x_range == WIDE_X_RANGE and wide.saucer.size[0] * wide.mm_per_unit == pytest.approx(185.0)
    assert (wide.camera, wide.cup, wide.saucer.y_range) == (paper.camera, paper.cup, paper.saucer.y_range)
    assert scene_from_dict({"preset": "wide", "saucer": {"resolution": 60}}).saucer.x_range == WIDE_X_RANGE
