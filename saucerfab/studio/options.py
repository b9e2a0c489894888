"""A run's options as the client gives them, checked and turned into a :class:`DesignRequest`.

The options are the fields of :class:`saucerfab.optimize.request.DesignRequest`
(its defaults and choices are the only ones: nothing is repeated here) with
three differences a web client needs:

* pictures, masks and a shape file are upload ids (:mod:`saucerfab.studio.workspace`),
  never paths; ``shape`` is a built-in name or an upload id;
* ``scene`` is a preset name and ``printer`` a bundled profile key (a client
  cannot make the server read a file of its choosing);
* two studio switches: ``title`` (the run's name in the history) and
  ``verify`` (the quick verify of a trial export after the design, default true).
"""

from __future__ import annotations

import math
from dataclasses import fields
from typing import Any

from saucerfab.errors import ConfigError
from saucerfab.studio.workspace import UPLOAD_ID_RE, NotFound, StudioError, Workspace

#: the fields that take an upload id
UPLOAD_FIELDS = ("direct", "reflected", "reflected2", "direct_mask", "reflected_mask", "reflected2_mask")
#: the studio's own switches (not DesignRequest fields), with their defaults
STUDIO_SWITCHES: dict[str, Any] = {"verify": True}
#: what each fit rule does, in a sentence (for the page's choices)
FIT_RULES = {
    "pad": "the whole picture is shown; its frame takes its shape (a wide picture, a wide frame)",
    "crop": "cut to its content (what differs from its background); the frame takes that shape",
}


def _kind(annotation: object) -> str:
    """``"int"``, ``"float"``, ``"bool"``, ``"str"`` or ``"upload"`` from a DesignRequest field's annotation."""
    text = annotation if isinstance(annotation, str) else repr(annotation)
    for key, kind in (("Path", "upload"), ("bool", "bool"), ("int", "int"), ("float", "float")):
        if key in text:
            return kind
    return "str"


def _fields() -> dict[str, str]:
    """DesignRequest field name -> its kind."""
    from saucerfab.optimize.request import DesignRequest

    return {f.name: _kind(f.type) for f in fields(DesignRequest)}


def option_choices() -> dict[str, Any]:
    """What ``GET /api/options`` answers (less the limits and samples, which the app adds)."""
    from saucerfab.cups import CUP_CLASSES
    from saucerfab.heightfield import BASE_SHAPES
    from saucerfab.fitting import FITS
    from saucerfab.optimize.request import ENHANCEMENTS, FRAMES, METHODS, DesignRequest
    from saucerfab.optimize.stages import STAGE_CAPS
    from saucerfab.profiles import list_profiles
    from saucerfab.scene import paper_scene

    if set(FIT_RULES) != set(FITS):  # a new fit rule needs its sentence here
        raise RuntimeError(f"FIT_RULES covers {sorted(FIT_RULES)} but the fit rules are {FITS}")
    paper = paper_scene()
    default = DesignRequest.default
    return {
        "shapes": sorted(BASE_SHAPES),
        "cups": [{"kind": k, "usage": cls.spec_usage} for k, cls in CUP_CLASSES.items()],
        "printers": [{"key": k, "name": p.name} for k, p in sorted(list_profiles().items())],
        "fits": list(FITS),
        "fit_rules": dict(FIT_RULES),
        "frames": list(FRAMES),
        "enhancements": list(ENHANCEMENTS),
        "methods": list(METHODS),
        "stage_caps": dict(STAGE_CAPS),
        "defaults": {
            "printer": default("printer"),
            "cup_diameter_mm": paper.cup_diameter_mm,
            "resolution": paper.saucer.resolution,
            "image_size": paper.direct.image_size,
            "max_iters": default("max_iters"),
            "shape": default("shape"),
            "fit": default("fit"),
            "frames": default("frames"),
            "enhancement": default("enhancement"),
            "method": default("method"),
            **STUDIO_SWITCHES,
        },
    }


def _typed(name: str, kind: str, value: Any) -> Any:
    """``value`` checked against the option's kind (JSON numbers, strings, booleans)."""
    ok = {
        "int": isinstance(value, int) and not isinstance(value, bool),
        "float": isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value),
        "bool": isinstance(value, bool),
        "str": isinstance(value, str) and len(value) <= 200,
        "upload": isinstance(value, str),
    }[kind]
    if not ok:
        want = {"int": "a whole number", "float": "a number", "bool": "true or false", "str": "a short text",
                "upload": "an upload id"}[kind]
        raise StudioError(f"option {name!r} must be {want}, got {value!r}")
    return float(value) if kind == "float" else value


def check_options(ws: Workspace, body: Any) -> tuple[dict[str, Any], str]:
    """The client's options checked for form (names, types, upload ids): (options to record, title).

    Raises:
        StudioError: not an object, an unknown option, a wrong type, a missing picture.
        NotFound: an upload id the workspace does not hold.
    """
    if not isinstance(body, dict):
        raise StudioError('the run options must be a JSON object, e.g. {"direct": UPLOAD_ID, "reflected": UPLOAD_ID}')
    kinds = _fields()
    options: dict[str, Any] = {}
    title = body.get("title")
    for name, value in body.items():
        if name == "title" or value is None:
            continue
        if name in STUDIO_SWITCHES:
            options[name] = _typed(name, "bool", value)
            continue
        if name not in kinds:
            known = ", ".join(sorted([*kinds, *STUDIO_SWITCHES, "title"]))
            raise StudioError(f"unknown option {name!r}; the options are: {known}")
        options[name] = _typed(name, kinds[name], value)
    for name in ("direct", "reflected"):
        if name not in options:
            raise StudioError(f"a design needs a {name} picture: upload one and give its id as {name!r}")
    for name in UPLOAD_FIELDS:
        if name in options:
            ws.upload_record(options[name])  # NotFound names the id
    shape = options.get("shape")
    if isinstance(shape, str) and UPLOAD_ID_RE.match(shape):
        if ws.upload_record(shape).get("kind") != "shape":
            raise StudioError(f"upload {shape} is a picture, not a shape; upload the heightfield as role 'shape'")
    if not isinstance(title, str) or not title.strip():
        names = [ws.upload_record(options[k]).get("name", "?") for k in ("direct", "reflected", "reflected2")
                 if k in options]
        title = " / ".join(str(n).rsplit(".", 1)[0] for n in names)
    return options, title.strip()[:120]


def design_request(ws: Workspace, options: dict[str, Any]) -> Any:
    """The :class:`DesignRequest` of a run's recorded options (upload ids made paths).

    Raises:
        ConfigError: an option the library refuses (its message), a scene that
            is not a preset, a printer that is not a bundled profile.
        NotFound: an upload that is gone.
    """
    from saucerfab.heightfield import BASE_SHAPES
    from saucerfab.optimize.request import DesignRequest
    from saucerfab.profiles import list_profiles
    from saucerfab.scene import PRESETS

    given = {k: v for k, v in options.items() if k not in STUDIO_SWITCHES}
    for name in UPLOAD_FIELDS:
        if name in given:
            given[name] = ws.upload_path(given[name])
    shape = given.get("shape")
    if isinstance(shape, str):
        if UPLOAD_ID_RE.match(shape):
            given["shape"] = str(ws.upload_path(shape))
        elif shape.replace("-", "_").lower() not in BASE_SHAPES:
            raise ConfigError(f"unknown base shape {shape!r}; built-in shapes are {sorted(BASE_SHAPES)}, or upload "
                              "a heightfield (.png or .npy) and give its upload id")
    if "scene" in given and given["scene"] not in PRESETS:
        raise ConfigError(f"unknown scene {given['scene']!r}; the studio's scenes are {sorted(PRESETS)}")
    if "printer" in given and given["printer"] not in list_profiles():
        raise ConfigError(f"unknown printer {given['printer']!r}; the printers are {sorted(list_profiles())}")
    try:
        return DesignRequest(**given)
    except (TypeError, ValueError) as exc:  # a value the dataclass could not even compare
        raise ConfigError(f"bad design options: {exc}") from None


def validate_run(ws: Workspace, options: dict[str, Any]) -> None:
    """Build the request and read every input as the design will (``prepare``, about a second; no torch).

    Raises:
        SaucerfabError: what ``saucerfab design`` would refuse, in its words.
    """
    from saucerfab.optimize.prepare import prepare

    try:
        prepare(design_request(ws, options))
    except NotFound:
        raise
    except MemoryError:
        raise StudioError("not enough memory to prepare these inputs; use smaller pictures or sizes") from None


def merged_options(old: dict[str, Any], changes: Any) -> dict[str, Any]:
    """A run's options with ``changes`` (an object; a null value removes the option) laid over them."""
    if not isinstance(changes, dict):
        raise StudioError('the changes must be a JSON object, e.g. {"shape": "bowl"}')
    out = dict(old)
    for k, v in changes.items():
        if v is None:
            out.pop(k, None)
        else:
            out[k] = v
    return out
