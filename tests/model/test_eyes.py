"""Tests of saucerfab.model.eyes: the ``--eyes`` words, where each eye stands, and their weights.

How the optimizer and verify use the eyes is ``tests/optimize/test_viewpoints.py``'s;
here the module's own contract: one word per mode, errors that show the
form to use, the design eye first, the two eyes an IPD apart along the
view's right axis, an eye box as a grid centred on the design eye, the
same eyes in mm and in model units, and weights that sum to 1.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from saucerfab.errors import ConfigError
from saucerfab.model.eyes import (
    DEFAULT_BOX_STEPS,
    DEFAULT_IPD_MM,
    EYE_MODES,
    EYES_USAGE,
    EyeSpec,
    eye_positions,
    eye_weights,
    parse_eyes,
    view_axes,
)

#: the paper's design eye and direct-view target, in mm (100 mm per model unit)
EYE = (0.0, -550.0, 500.0)
TARGET = (0.0, 0.0, -80.0)
#: an eye off to one side, for a right axis that is not a model axis
SIDE_EYE = (300.0, -420.0, 380.0)


@pytest.mark.parametrize(
    "text, spec",
    [
        ("design", EyeSpec("design", DEFAULT_IPD_MM)),
        ("  POINT ", EyeSpec("design", DEFAULT_IPD_MM)),  # the older name, any case
        ("Both", EyeSpec("both", DEFAULT_IPD_MM)),
        ("box:40,20", EyeSpec("box", DEFAULT_IPD_MM, (40.0, 20.0), DEFAULT_BOX_STEPS)),
        ("box:40,20,5", EyeSpec("box", DEFAULT_IPD_MM, (40.0, 20.0), 5)),
        ("box:0,10,2.0", EyeSpec("box", DEFAULT_IPD_MM, (0.0, 10.0), 2)),
        ("box:1000,1000,9", EyeSpec("box", DEFAULT_IPD_MM, (1000.0, 1000.0), 9)),
    ],
)
def test_parse_eyes_reads_each_word(text: str, spec: EyeSpec) -> None:
    got = parse_eyes(text)
    assert got == spec and got.mode in EYE_MODES and type(got.ipd_mm) is float


def test_every_mode_is_in_the_usage_text() -> None:
    assert all(mode in EYES_USAGE for mode in EYE_MODES)
    assert parse_eyes("both", 58).ipd_mm == 58.0


@pytest.mark.parametrize(
    "text, match",
    [
        ("stereo", r"--eyes must be one of design, both, box:W,H\[,N\]; got 'stereo'"),
        ("box", "--eyes must be one of"),
        ("box:40", r"an eye box is box:W,H or box:W,H,N \(mm, N positions per side\)"),
        ("box:40,20,3,3", "an eye box is box:W,H"),
        ("box:wide,20", "an eye box is box:W,H"),
        ("box:-1,20", "an eye box is box:W,H"),
        ("box:nan,20", "an eye box is box:W,H"),
        ("box:inf,20", "an eye box is box:W,H"),
        ("box:40,20,1", r"N must be an integer in \[2, 9\]"),
        ("box:40,20,10", r"N must be an integer in \[2, 9\]"),
        ("box:40,20,2.5", r"N must be an integer in \[2, 9\]"),
        ("box:1001,20", "wider than 1000 mm is not a viewing region"),
        ("box:20,1001", "wider than 1000 mm"),
    ],
)
def test_parse_eyes_refuses_with_the_form_to_use(text: str, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        parse_eyes(text)


@pytest.mark.parametrize("ipd", [0.0, -64.0, 200.5, math.nan, math.inf, "64"])
def test_parse_eyes_refuses_an_ipd_that_is_not_a_distance(ipd: object) -> None:
    with pytest.raises(ConfigError, match=r"--ipd-mm must be a distance in \(0, 200\] mm"):
        parse_eyes("both", ipd)  # type: ignore[arg-type]


@pytest.mark.parametrize("eye", [EYE, SIDE_EYE])
def test_view_axes_are_a_level_right_and_an_up_facing_the_target(eye: tuple[float, float, float]) -> None:
    right, up = view_axes(eye, TARGET)
    fwd = np.subtract(TARGET, eye) / np.linalg.norm(np.subtract(TARGET, eye))
    np.testing.assert_allclose([np.linalg.norm(right), np.linalg.norm(up)], 1.0, atol=1e-15)
    np.testing.assert_allclose([right @ up, right @ fwd, up @ fwd, right[2]], 0.0, atol=1e-15)
    assert up[2] > 0
    np.testing.assert_allclose(np.cross(right, up), -fwd, atol=1e-15)  # right-handed: x right, y up, looking along -z


def test_the_paper_eye_looks_along_y_so_right_is_plus_x() -> None:
    eyes = eye_positions(EyeSpec("both", 64.0), EYE, TARGET)
    assert [e.name for e in eyes] == ["design", "left", "right"]
    assert eyes[0].position == EYE and eyes[0].offset_mm == (0.0, 0.0)
    np.testing.assert_allclose(eyes[1].position, (-32.0, -550.0, 500.0), atol=1e-12)
    np.testing.assert_allclose(eyes[2].position, (32.0, -550.0, 500.0), atol=1e-12)
    assert (eyes[1].offset_mm, eyes[2].offset_mm) == ((-32.0, 0.0), (32.0, 0.0))
    assert eye_positions(EyeSpec("design"), EYE, TARGET)[0].position == EYE
    assert len(eye_positions(EyeSpec("design"), EYE, TARGET)) == 1


def test_the_two_eyes_stand_an_ipd_apart_along_the_right_axis() -> None:
    left, right_eye = eye_positions(EyeSpec("both", 58.0), SIDE_EYE, TARGET)[1:]
    right, _ = view_axes(SIDE_EYE, TARGET)
    gap = np.subtract(right_eye.position, left.position)
    np.testing.assert_allclose(gap, 58.0 * right, atol=1e-12)
    np.testing.assert_allclose(np.add(left.position, right_eye.position) / 2, SIDE_EYE, atol=1e-12)


@pytest.mark.parametrize("steps, count", [(2, 5), (3, 9), (4, 17)])
def test_an_eye_box_is_a_grid_centred_on_the_design_eye(steps: int, count: int) -> None:
    eyes = eye_positions(EyeSpec("box", box_mm=(40.0, 20.0), box_steps=steps), SIDE_EYE, TARGET)
    assert len(eyes) == count and eyes[0].name == "design"  # an odd grid's centre is the design eye, not twice
    right, up = view_axes(SIDE_EYE, TARGET)
    offsets = [e.offset_mm for e in eyes[1:]]
    xs, ys = np.linspace(-20.0, 20.0, steps), np.linspace(10.0, -10.0, steps)
    # rows from the top, each left to right
    assert offsets == [(float(x), float(y)) for y in ys for x in xs if not (x == 0 and y == 0)]
    for e in eyes:
        np.testing.assert_allclose(e.position, np.add(SIDE_EYE, e.offset_mm[0] * right + e.offset_mm[1] * up),
                                   atol=1e-12)
    grid = np.array([e.position for e in eyes[1:]] + ([list(SIDE_EYE)] if steps % 2 else []))
    np.testing.assert_allclose(grid.mean(axis=0), SIDE_EYE, atol=1e-12)
    if steps == 3:
        assert [e.name for e in eyes[1:4]] == ["box(-20,+10)", "box(+0,+10)", "box(+20,+10)"]


def test_model_units_give_the_same_eyes_as_millimetres() -> None:
    spec = EyeSpec("box", box_mm=(40.0, 20.0), box_steps=3)
    s = 100.0  # mm per model unit
    mm = eye_positions(spec, SIDE_EYE, TARGET)
    units = eye_positions(spec, tuple(np.divide(SIDE_EYE, s)), tuple(np.divide(TARGET, s)), mm_per_unit=s)
    for a, b in zip(mm, units, strict=True):
        assert (a.name, a.offset_mm) == (b.name, b.offset_mm)  # offsets stay millimetres
        np.testing.assert_allclose(np.divide(a.position, s), b.position, atol=1e-12)


def test_eye_names_are_unique_for_a_box() -> None:
    eyes = eye_positions(EyeSpec("box", box_mm=(40.0, 20.0), box_steps=9), EYE, TARGET)
    assert len({e.name for e in eyes}) == len(eyes) == 81


def test_eye_names_are_unique_for_every_box_parse_eyes_accepts() -> None:
    eyes = eye_positions(parse_eyes("box:1,1"), EYE, TARGET)
    assert len({e.name for e in eyes}) == len(eyes)


@pytest.mark.parametrize(
    "spec, weights",
    [
        (EyeSpec("design"), [1.0]),
        (EyeSpec("both"), [0.5, 0.25, 0.25]),
        (EyeSpec("box", box_mm=(40.0, 20.0), box_steps=3), [0.5] + [0.0625] * 8),
        (EyeSpec("box", box_mm=(40.0, 20.0), box_steps=2), [0.5] + [0.125] * 4),
    ],
)
def test_the_design_eye_keeps_half_the_weight(spec: EyeSpec, weights: list[float]) -> None:
    got = eye_weights(eye_positions(spec, EYE, TARGET))
    assert got == weights and math.fsum(got) == 1.0
    assert math.fsum(eye_weights(eye_positions(EyeSpec("box", box_mm=(40.0, 20.0), box_steps=4), EYE, TARGET))) \
        == pytest.approx(1.0, abs=1e-15)
