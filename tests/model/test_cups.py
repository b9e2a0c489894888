"""Tests of saucerfab.model.cups: every shape of CUP_CLASSES through its CLI spec, TOML table and scene.json fields.

The reflection each cup hands to :mod:`saucerfab.model.reflection` is held by
``tests/model/test_mirror.py`` and ``tests/model/test_reflection.py``; the presets and
the scene's overlap rules by ``tests/model/test_scene.py``. Here: what a cup
says about itself (widths, radii, outline, wall pieces, inside) and the
three forms it is written in, for every class the table holds.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import fields

import numpy as np
import pytest

from saucerfab.errors import ConfigError
from saucerfab.model.cups import (
    CUP_CLASSES,
    CUP_SPEC_USAGE,
    CircleCup,
    Cup,
    EllipseCup,
    PrismCup,
    cup_from_dict,
    cup_to_dict,
    parse_cup_spec,
)

#: one cup per shape with no field at its default (so a dropped field shows), lengths exact in binary
EXAMPLES: dict[str, Cup] = {
    "circle": CircleCup(0.375, 1.25),
    "ellipse": EllipseCup((0.5, 0.3125), 25.0, 1.25),
    "prism": PrismCup(5, 0.4375, 12.0, 1.25),
}
#: the same cups at 80 mm per model unit, as scene.json holds them (angles and counts unscaled)
IN_MM: dict[str, Cup] = {
    "circle": CircleCup(30.0, 100.0),
    "ellipse": EllipseCup((40.0, 25.0), 25.0, 100.0),
    "prism": PrismCup(5, 35.0, 12.0, 100.0),
}
MM_PER_UNIT = 80.0


def init_names(cls: type) -> list[str]:
    """The dataclass fields a caller sets, in order (``kind`` is not one)."""
    return [f.name for f in fields(cls) if f.init]  # type: ignore[arg-type]


def test_every_shape_of_the_table_has_an_example() -> None:
    # a new shape added to CUP_CLASSES must get an example here, or the tests below skip it silently
    assert sorted(CUP_CLASSES) == sorted(EXAMPLES) == sorted(IN_MM)
    for kind, cls in CUP_CLASSES.items():
        assert cls.kind == kind and isinstance(EXAMPLES[kind], cls)
        assert cls.spec_usage.startswith(kind) and cls.spec_usage in CUP_SPEC_USAGE
    assert [CUP_CLASSES[k].faceted for k in ("circle", "ellipse", "prism")] == [False, False, True]


@pytest.mark.parametrize("kind", sorted(EXAMPLES))
def test_the_cli_spec_lists_the_fields_but_height_in_order(kind: str) -> None:
    """``kind:N1,N2,...`` with the most numbers the spec takes is the cup's own fields (height excepted)."""
    cup = EXAMPLES[kind]
    nums: list[float] = []
    for name in init_names(type(cup)):
        if name != "height":
            v = getattr(cup, name)
            nums += list(v) if isinstance(v, tuple) else [v]
    assert len(nums) == type(cup).spec_arity[1]
    spec = f"{kind}:" + ",".join(f"{v:g}" for v in nums)
    back = parse_cup_spec(spec)
    # the spec cannot say the height: everything else comes back, the height is the class default
    assert back == type(back)(**{n: getattr(cup, n) for n in init_names(type(cup)) if n != "height"})
    assert back.height == 1.0 and type(back) is type(cup)


@pytest.mark.parametrize("kind", sorted(EXAMPLES))
def test_a_spec_with_one_number_too_many_or_too_few_names_every_form(kind: str) -> None:
    least, most = CUP_CLASSES[kind].spec_arity
    counts = [most + 1] + ([least - 1] if least > 0 else [])
    for count in counts:
        spec = f"{kind}:" + ",".join(["3"] * count)
        with pytest.raises(ConfigError) as exc:
            parse_cup_spec(spec)
        msg = str(exc.value)
        assert f"unknown cup spec {spec!r}" in msg
        for cls in CUP_CLASSES.values():  # the fix: every form the spec may take
            assert f"'{cls.spec_usage}'" in msg


def test_a_spec_with_words_for_numbers_shows_an_example() -> None:
    with pytest.raises(ConfigError, match=r"parameters must be numbers, e\.g\. 'prism:6,0\.45,0'"):
        parse_cup_spec("ellipse:wide,0.3")


@pytest.mark.parametrize("kind", sorted(EXAMPLES))
def test_the_toml_table_round_trips_through_json(kind: str) -> None:
    cup = EXAMPLES[kind]
    table = cup_to_dict(cup)
    # shape first, then every settable field in declaration order; vectors as lists (what TOML and JSON hold)
    assert list(table) == ["shape", *init_names(type(cup))]
    assert table["shape"] == kind
    assert not any(isinstance(v, tuple) for v in table.values())
    back = cup_from_dict(json.loads(json.dumps(table)), "circle")
    assert back == cup and type(back) is type(cup)
    # without a shape key the default shape is read
    assert cup_from_dict({k: v for k, v in table.items() if k != "shape"}, kind) == cup


@pytest.mark.parametrize("kind", sorted(EXAMPLES))
def test_scene_json_fields_rebuild_the_cup_in_millimetres(kind: str) -> None:
    """scene.json holds shape, height and ``file_fields`` (lengths in mm); verify and the viewer rebuild from them."""
    cup = EXAMPLES[kind]
    ff = cup.file_fields(lambda length: length * MM_PER_UNIT)
    # named as the dataclass fields: with the height they are all of them
    assert sorted([*ff, "height"]) == sorted(init_names(type(cup)))
    doc = json.loads(json.dumps({"shape": kind, "height": cup.height * MM_PER_UNIT, **ff}))
    assert cup_from_dict(doc, "circle") == IN_MM[kind]


@pytest.mark.parametrize("kind", sorted(EXAMPLES))
def test_radii_bound_the_outline(kind: str) -> None:
    cup = EXAMPLES[kind]
    b = cup.boundary(4096)
    r = np.linalg.norm(b, axis=1)
    assert r.max() == pytest.approx(cup.circumradius, abs=1e-12)
    if cup.faceted:  # corners only; the inradius is the distance to each facet's line
        edges = np.roll(b, -1, axis=0) - b
        dist = np.abs(b[:, 0] * edges[:, 1] - b[:, 1] * edges[:, 0]) / np.linalg.norm(edges, axis=1)
        np.testing.assert_allclose(dist, cup.inradius, atol=1e-12)
    else:
        assert r.min() == pytest.approx(cup.inradius, abs=1e-6)
    # strictly inside just within the outline, outside just beyond it (every outline is star-shaped about 0)
    assert cup.contains(0.999 * b).all() and not cup.contains(1.001 * b).any()
    assert cup.contains(np.zeros((2, 3, 2))).shape == (2, 3)


def test_widths_are_what_the_mm_scale_reads() -> None:
    """``width_units``: the diameter, the ellipse's 2a (its local x, however turned), a prism's 2 x circumradius."""
    assert CircleCup(0.375).width_units == 0.75
    turned = EllipseCup((0.25, 0.5), 90.0)  # a along the model's y, b < a is not required
    assert (turned.width_units, turned.circumradius, turned.inradius) == (0.5, 0.5, 0.25)
    for sides in (3, 4, 6, 7):
        p = PrismCup(sides, 0.5)
        # twice the circumradius whatever the parity (corner to corner only for even n): one rule for the mm scale
        assert p.width_units == 1.0 and p.circumradius == 0.5
        assert p.inradius == pytest.approx(0.5 * math.cos(math.pi / sides), abs=1e-15)
    hexagon = PrismCup(6, 0.5, 0.0)
    corners = hexagon.boundary()
    assert corners.shape == (6, 2)
    assert np.ptp(corners[:, 0]) == pytest.approx(hexagon.width_units, abs=1e-15)  # first corner on +x


@pytest.mark.parametrize("kind", sorted(EXAMPLES))
def test_wall_pieces_close_on_the_outline_with_outward_normals(kind: str) -> None:
    cup = EXAMPLES[kind]
    wall = cup.wall(64)
    n_pieces = cup.boundary().shape[0] if cup.faceted else 64
    assert wall.shape == (n_pieces, 2, 4) and wall.dtype == np.float64
    start, end = wall[:, 0, :2], wall[:, 1, :2]
    np.testing.assert_array_equal(end, np.roll(start, -1, axis=0))  # a closed chain, piece k ends where k + 1 starts
    np.testing.assert_allclose(start, cup.boundary(64), atol=1e-15)
    normals = wall[:, :, 2:]
    np.testing.assert_allclose(np.linalg.norm(normals, axis=2), 1.0, atol=1e-12)
    ends = wall[:, :, :2]
    step = 1e-4 * cup.inradius
    assert not cup.contains(ends + step * normals).any() and cup.contains(ends - step * normals).all()
    if cup.faceted:  # a facet's own normal at both ends, perpendicular to it
        np.testing.assert_array_equal(normals[:, 0], normals[:, 1])
        np.testing.assert_allclose(np.einsum("ij,ij->i", normals[:, 0], end - start), 0.0, atol=1e-12)


def test_the_ellipse_wall_normal_is_the_gradient() -> None:
    cup = EllipseCup((0.5, 0.25), 30.0)
    wall = cup.wall(16)
    t = math.radians(30.0)
    rot = np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])
    local = wall[:, 0, :2] @ rot  # back to the ellipse's own frame
    grad = np.stack([local[:, 0] / 0.25, local[:, 1] / 0.0625], axis=1)  # d/dx of x^2/a^2 + y^2/b^2, halved
    grad = (grad / np.linalg.norm(grad, axis=1, keepdims=True)) @ rot.T
    np.testing.assert_allclose(wall[:, 0, 2:], grad, atol=1e-12)


@pytest.mark.parametrize("kind", sorted(EXAMPLES))
def test_reflect_gives_one_piece_when_smooth_and_facets_when_faceted(kind: str) -> None:
    cup = EXAMPLES[kind]
    pieces = cup.reflect((0.0, -5.5, 5.0), np.array([[0.0, -1.0], [0.2, -0.9]]))
    facets = [pc.facet for pc in pieces]
    if cup.faceted:
        assert facets and all(0 <= k < cup.boundary().shape[0] for k in facets) and facets == sorted(facets)
    else:
        assert facets == [-1]


@pytest.mark.parametrize(
    "table, error, match",
    [
        ("circle", ConfigError, r"\[cup\] must be a table with a 'shape' key"),
        ({"shape": "cone"}, ConfigError, re.escape(f"unknown cup shape 'cone'; use one of {sorted(CUP_CLASSES)}")),
        ({"shape": "prism", "kind": "prism"}, ConfigError, r"unknown key\(s\) \['kind'\]"),
        ({"shape": "ellipse", "radius": 0.4}, ConfigError, r"unknown key\(s\) \['radius'\]"),
        ({"shape": "prism", "sides": 6.0}, ConfigError, r"sides must be an integer in \[3, 64\]"),
        ({"shape": "prism", "sides": True}, ConfigError, "sides must be an integer"),
        ({"shape": "prism", "rotation_deg": math.nan}, ConfigError, "finite"),
        ({"shape": "ellipse", "rotation_deg": math.inf}, ConfigError, "finite"),
        ({"shape": "ellipse", "semi_axes": [0.4, 0.3, 0.2]}, ConfigError, "2 components"),
        # a value of the wrong kind is a TypeError, which the scene turns into its own message (documented)
        ({"shape": "ellipse", "semi_axes": 0.4}, TypeError, "not iterable"),
    ],
)
def test_bad_tables_are_refused(table: object, error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match):
        cup_from_dict(table, "circle")
