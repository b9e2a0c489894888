"""Design options from a mapping (saucerfab.optimize.request.checked_options, DesignRequest.from_options).

One conversion for every front door that takes a design run's options as a
mapping: the batch manifest's ``design_options`` and the studio's run form.
Each door keeps its own words (tests/batch and tests/studio pin them too).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

from saucerfab.batch.manifest import MANIFEST_DOOR
from saucerfab.errors import ConfigError, SaucerfabError
from saucerfab.optimize.request import DesignRequest, _fit, _request_hints, checked_options
from saucerfab.studio.options import STUDIO_DOOR

#: each front door's policy (the doors define them; the check is the request's)
_DOORS = {"manifest": MANIFEST_DOOR, "studio": STUDIO_DOOR}

DOORS = ("manifest", "studio")
#: a good value of each annotation DesignRequest uses, as TOML / JSON give it, and what it becomes
GOOD: dict[str, tuple[object, object]] = {
    "bool": (False, False),
    "int": (7, 7),
    "float": (2, 2.0),  # a whole number is a number, made a float
    "str": ("text", "text"),
    "path": ("picture.png", "picture.png"),  # kept as given: the request makes it a Path, the studio keeps its id
}


def _kind(hint: Any) -> str:
    """The kind of a field annotation (its non-None part), for :data:`GOOD`."""
    text = repr(hint)
    for word, kind in (("Path", "path"), ("bool", "bool"), ("int", "int"), ("float", "float"), ("str", "str")):
        if word in text:
            return kind
    raise AssertionError(f"an annotation this test does not know: {hint!r}")


def _refusal(options: dict[str, object], where: str, **kw: Any) -> str:
    with pytest.raises(ConfigError) as exc:
        checked_options(options, door=_DOORS[where], **kw)  # type: ignore[arg-type]
    return str(exc.value)


# --------------------------------------------------------------------------- what is taken


@pytest.mark.parametrize("where", DOORS)
def test_every_field_type_is_taken_and_converted(where: str) -> None:
    hints = _request_hints()
    options = {name: GOOD[_kind(hint)][0] for name, hint in hints.items()}
    out = checked_options(options, door=_DOORS[where])  # type: ignore[arg-type]
    assert out == {name: GOOD[_kind(hint)][1] for name, hint in hints.items()}
    assert list(out) == list(options)  # in the order given
    for name, hint in hints.items():
        if _kind(hint) == "float":
            assert type(out[name]) is float, name


def test_the_annotations_covered_are_the_requests() -> None:
    # a field of a new type needs its rule in _fit (else any value would pass its type check)
    assert {_kind(h) for h in _request_hints().values()} == set(GOOD)


@pytest.mark.parametrize("where", DOORS)
def test_none_is_taken_where_the_field_is_optional_only(where: str) -> None:
    assert checked_options({"resolution": None, "background": None}, door=_DOORS[where]) == {  # type: ignore[arg-type]
        "resolution": None,
        "background": None,
    }
    assert "seed" in _refusal({"seed": None}, where) and "whole number" in _refusal({"seed": None}, where)


def test_a_request_is_built_from_plain_values() -> None:
    options = {
        "direct": "a.png", "reflected": "b.png", "shape": "bowl", "resolution": 24, "image_size": 32,
        "seed": 3, "height_scale": 1, "max_iters": 5, "record_times": False, "w_large": 1, "ipd_mm": None,
    }
    for where in DOORS:
        r = DesignRequest.from_options(options, door=_DOORS[where])  # type: ignore[arg-type]
        assert r.direct == Path("a.png") and r.reflected == Path("b.png") and r.shape == "bowl"
        assert r.height_scale == 1.0 and type(r.height_scale) is float and r.w_large == 1.0
        assert (r.resolution, r.image_size, r.seed, r.max_iters, r.record_times) == (24, 32, 3, 5, False)


def test_inputs_are_laid_over_the_options_unchecked() -> None:
    # the studio's upload ids become the uploads' paths; the batch's images are its own keys
    r = DesignRequest.from_options(
        {"direct": "0123456789abcdef", "reflected": "fedcba9876543210"}, door=STUDIO_DOOR,
        inputs={"direct": Path("/up/a.png"), "reflected": Path("/up/b.png")},
    )
    assert (r.direct, r.reflected) == (Path("/up/a.png"), Path("/up/b.png"))
    r = DesignRequest.from_options(
        {"max_iters": 3}, door=MANIFEST_DOOR, allowed=frozenset({"max_iters"}),
        inputs={"direct": Path("a.png"), "reflected": Path("b.png")},
    )
    assert r.max_iters == 3


def test_tuples_take_lists_item_by_item() -> None:
    door = _DOORS["manifest"]
    assert _fit([1, 2.5], tuple[float, ...], door) == ((1.0, 2.5), None)
    assert _fit((1, 2), tuple[int, int], door) == ((1, 2), None)
    assert _fit(["a"], tuple[str, ...] | None, door) == (("a",), None)
    assert _fit(None, tuple[str, ...] | None, door) == (None, None)
    assert _fit([1, True], tuple[int, ...], door) == ([1, True], "a list, each item a whole number")
    assert _fit([1], tuple[float, float], door) == ([1], "a list of 2 items (a number, a number)")
    assert _fit("1,2", tuple[float, float], door)[1] == "a list of 2 items (a number, a number)"


# --------------------------------------------------------------------------- what is refused


@pytest.mark.parametrize(
    "name, value, want",
    [
        ("seed", True, "a whole number"),  # a bool is not an int (Python's bool is one)
        ("resolution", 40.5, "a whole number"),
        ("max_iters", "30", "a whole number"),
        ("height_scale", "big", "a number"),
        ("w_large", False, "a number"),
        ("record_times", 1, "true or false"),
        ("record_times", "yes", "true or false"),
        ("ablation", 3, "a string"),
        ("background", ["#fff"], "a string"),
    ],
)
def test_wrong_types_are_refused_in_each_doors_words(name: str, value: object, want: str) -> None:
    assert _refusal({name: value}, "manifest") == f"design_options: {name} must be {want}, got {value!r}"
    studio_want = "a short text" if want == "a string" else want
    assert _refusal({name: value}, "studio") == f"option {name!r} must be {studio_want}, got {value!r}"


def test_paths_are_texts_at_the_studio() -> None:
    assert _refusal({"direct": 5}, "studio") == "option 'direct' must be an upload id, got 5"
    assert _refusal({"direct_mask": Path("m.png")}, "studio").startswith("option 'direct_mask' must be an upload id")
    assert checked_options({"direct": Path("a.png")}, door=MANIFEST_DOOR) == {"direct": Path("a.png")}
    assert _refusal({"direct": 5}, "manifest") == "design_options: direct must be a path, got 5"


def test_the_studio_bounds_texts_and_refuses_nan_the_manifest_leaves_them_to_the_request() -> None:
    long = "x" * 201
    assert "must be a short text" in _refusal({"eyes": long}, "studio")
    assert checked_options({"eyes": long}, door=MANIFEST_DOOR) == {"eyes": long}
    for v in (math.nan, math.inf, 10**400):  # JSON numbers Python reads (a whole number of any length)
        assert _refusal({"ipd_mm": v}, "studio").startswith("option 'ipd_mm' must be a number")
    out = checked_options({"height_scale": math.nan}, door=MANIFEST_DOOR)
    assert math.isnan(out["height_scale"])  # type: ignore[arg-type]
    # ... which the request refuses, in the manifest's words
    with pytest.raises(ConfigError, match=r"^design_options: w_large must be a non-negative number, got nan"):
        DesignRequest.from_options({"direct": "a", "reflected": "b", "w_large": math.nan}, door=MANIFEST_DOOR)


def test_unknown_fields_are_refused_with_the_names_known() -> None:
    allowed = frozenset({"seed", "max_iters"})
    msg = _refusal({"seed": 1, "zeta": 1, "colour": "red"}, "manifest", allowed=allowed)
    assert msg == "unknown design option(s) ['colour', 'zeta']; allowed: ['max_iters', 'seed']"
    # a field the door does not allow is unknown there (the manifest's images are its own keys)
    assert _refusal({"direct": "a.png"}, "manifest", allowed=allowed).startswith("unknown design option(s) ['direct']")
    msg = _refusal({"zeta": 1, "colour": "red"}, "studio", extra={"verify": bool, "title": object})
    fields = sorted([*_request_hints(), "verify", "title"])
    assert msg == f"unknown option 'zeta'; the options are: {', '.join(fields)}"


def test_the_manifest_lists_every_mistake_the_studio_the_first() -> None:
    options = {"seed": "x", "colour": 1, "resolution": True}
    # the manifest: unknown names first (all), then every mistyped option, sorted by name
    assert _refusal(options, "manifest").startswith("unknown design option(s) ['colour']")
    del options["colour"]
    assert _refusal(options, "manifest") == (
        "design_options: resolution must be a whole number, got True; seed must be a whole number, got 'x'"
    )
    # the studio: the first problem in the order given, whichever it is
    assert _refusal({"seed": "x", "colour": 1}, "studio") == "option 'seed' must be a whole number, got 'x'"
    assert _refusal({"colour": 1, "seed": "x"}, "studio").startswith("unknown option 'colour'")


def test_the_door_chooses_the_error_class_and_the_building_errors_words() -> None:
    class DoorError(SaucerfabError):
        pass

    with pytest.raises(DoorError, match="option 'seed'"):
        checked_options({"seed": "x"}, door=STUDIO_DOOR, error=DoorError)
    with pytest.raises(DoorError, match="^unknown option 'zeta'"):
        DesignRequest.from_options({"zeta": 1}, door=STUDIO_DOOR, error=DoorError)
    # a value the request refuses: the manifest says where, the studio passes the request's words on
    bad = {"direct": "a", "reflected": "b", "max_iters": 0}
    with pytest.raises(ConfigError, match=r"^design_options: max_iters must be at least 1, got 0$"):
        DesignRequest.from_options(bad, door=MANIFEST_DOOR)
    with pytest.raises(ConfigError, match=r"^max_iters must be at least 1, got 0$"):
        DesignRequest.from_options(bad, door=STUDIO_DOOR)
    # a request that cannot even be made (no pictures)
    with pytest.raises(ConfigError, match=r"^design_options: .*missing"):
        DesignRequest.from_options({}, door=MANIFEST_DOOR)
    with pytest.raises(ConfigError, match=r"^bad design options: .*missing"):
        DesignRequest.from_options({}, door=STUDIO_DOOR)


def test_allowed_names_must_be_fields() -> None:
    with pytest.raises(ValueError, match="zeta"):
        checked_options({}, door=MANIFEST_DOOR, allowed=frozenset({"seed", "zeta"}))


# --------------------------------------------------------------------------- the front doors call it


class _Uploads:
    """A studio workspace holding any upload id (check_options asks it for the records)."""

    def upload_record(self, upload_id: str) -> dict[str, str]:
        return {"name": f"{upload_id}.png", "kind": "direct"}


def test_the_studios_form_goes_through_it() -> None:
    from saucerfab.studio.options import check_options
    from saucerfab.studio.workspace import StudioError

    ws: Any = _Uploads()
    body = {"direct": "a", "reflected": "b", "height_scale": 2, "verify": False, "title": " t ", "seed": None}
    options, title = check_options(ws, body)
    assert options == {"direct": "a", "reflected": "b", "height_scale": 2.0, "verify": False} and title == "t"
    assert type(options["height_scale"]) is float
    for bad, words in [
        ({"verify": "no"}, "option 'verify' must be true or false, got 'no'"),
        ({"max_iters": "many"}, "option 'max_iters' must be a whole number, got 'many'"),
        ({"colour": "red"}, "unknown option 'colour'; the options are: ablation, background,"),
    ]:
        with pytest.raises(StudioError) as exc:
            check_options(ws, {"direct": "a", "reflected": "b", **bad})
        assert str(exc.value).startswith(words), str(exc.value)


def test_the_manifests_design_options_go_through_it() -> None:
    from saucerfab.batch.manifest import _check_design_options, design_option_keys

    images = {"direct": Path("a.png"), "reflected": Path("b.png")}
    _check_design_options({"resolution": 24, "height_scale": 1}, images, None, None)
    with pytest.raises(ConfigError) as exc:
        _check_design_options({"printer": "j55", "colour": 1}, images, None, None)
    assert str(exc.value) == (
        f"unknown design option(s) ['colour', 'printer']; allowed: {sorted(design_option_keys())}"
    )
    with pytest.raises(ConfigError, match=r"^design_options: seed must be a whole number, got 1\.5$"):
        _check_design_options({"seed": 1.5}, images, None, None)
    with pytest.raises(ConfigError, match=r"^design_options: .*height_scale"):
        _check_design_options({"height_scale": -1}, images, None, None)
