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

The names and value types are checked, and the options turned into a request, by
the one conversion the batch manifest uses too
(:func:`saucerfab.optimize.request.checked_options`,
:meth:`~saucerfab.optimize.request.DesignRequest.from_options`), in the studio's words.
"""

from __future__ import annotations

from typing import Any

from saucerfab.errors import ConfigError
from saucerfab.optimize.request import TYPE_WORDS, OptionsDoor
from saucerfab.studio.workspace import UPLOAD_ID_RE, NotFound, StudioError, Workspace

#: how the run form's options are checked and worded: a form sends JSON (NaN is a JSON number to Python)
#: and a text has a bound (it is recorded and shown); the first problem alone (tests/studio pins the messages)
STUDIO_DOOR = OptionsDoor(
    words={**TYPE_WORDS, "str": "a short text", "path": "an upload id"},
    text_max=200,
    finite=True,
    paths_as_text=True,
    all_at_once=False,
    unknown=lambda names, known: f"unknown option {names[0]!r}; the options are: {', '.join(sorted(known))}",
    mistyped=lambda bad: "; ".join(f"option {n!r} must be {w}, got {v!r}" for n, w, v in bad),
    build_errors=(TypeError, ValueError),  # a value the dataclass could not even compare
    build_prefix="bad design options: ",
)

#: the fields that take an upload id
UPLOAD_FIELDS = ("direct", "reflected", "reflected2", "direct_mask", "reflected_mask", "reflected2_mask")
#: the studio's own switches (not DesignRequest fields), with their defaults
STUDIO_SWITCHES: dict[str, Any] = {"verify": True}
#: the options besides DesignRequest's fields, by annotation: the switches (of their
#: default's type) and the run's title (any value: one that is no text gives way to
#: the pictures' names)
_STUDIO_OPTIONS: dict[str, Any] = {**{k: type(v) for k, v in STUDIO_SWITCHES.items()}, "title": object}
#: what each fit rule does, in a sentence (for the page's choices)
FIT_RULES = {
    "pad": "the whole picture is shown; its frame takes its shape (a wide picture, a wide frame)",
    "crop": "cut to its content (what differs from its background); the frame takes that shape",
}

#: what each scene preset is, in the page's words (its saucer's size follows the cup's diameter)
SCENE_LABELS = {
    "paper": "Rectangle in front of the cup (the paper's)",
    "wide": "Wide rectangle in front of the cup",
    "round": "Round saucer, cup at the centre",
}


def scene_choices() -> list[dict[str, Any]]:
    """The scene presets for the page: key, label, whether the saucer is round, and a round one's
    diameter over the cup's diameter (what a form left empty gets: the page shows it for the cup given)."""
    from saucerfab.model.scene import PRESETS

    if set(SCENE_LABELS) != set(PRESETS):  # a new preset needs its words here
        raise RuntimeError(f"SCENE_LABELS covers {sorted(SCENE_LABELS)} but the presets are {sorted(PRESETS)}")
    out = []
    for key, factory in PRESETS.items():
        scene = factory()
        entry: dict[str, Any] = {"key": key, "label": SCENE_LABELS[key], "round": scene.saucer.is_disc}
        if scene.saucer.is_disc:
            entry["saucer_per_cup"] = 2.0 * scene.saucer.radius / scene.cup_width_units
        out.append(entry)
    return out


def option_choices() -> dict[str, Any]:
    """What ``GET /api/options`` answers (less the limits and samples, which the app adds)."""
    from saucerfab.imaging.fitting import FITS
    from saucerfab.model.cups import CUP_CLASSES
    from saucerfab.model.heightfield import BASE_SHAPES
    from saucerfab.model.profiles import list_profiles
    from saucerfab.model.scene import default_scene
    from saucerfab.optimize.request import ENHANCEMENTS, FRAMES, METHODS, DesignRequest
    from saucerfab.optimize.stages import STAGE_CAPS

    if set(FIT_RULES) != set(FITS):  # a new fit rule needs its sentence here
        raise RuntimeError(f"FIT_RULES covers {sorted(FIT_RULES)} but the fit rules are {FITS}")
    scene = default_scene()
    default = DesignRequest.default
    return {
        "shapes": sorted(BASE_SHAPES),
        "cups": [{"kind": k, "usage": cls.spec_usage} for k, cls in CUP_CLASSES.items()],
        "scenes": scene_choices(),
        "printers": [{"key": k, "name": p.name} for k, p in sorted(list_profiles().items())],
        "fits": list(FITS),
        "fit_rules": dict(FIT_RULES),
        "frames": list(FRAMES),
        "enhancements": list(ENHANCEMENTS),
        "methods": list(METHODS),
        "stage_caps": dict(STAGE_CAPS),
        "defaults": {
            "printer": default("printer"),
            "scene": default("scene"),
            "cup_diameter_mm": scene.cup_diameter_mm,
            "resolution": scene.saucer.resolution,
            "image_size": scene.direct.image_size,
            "max_iters": default("max_iters"),
            "shape": default("shape"),
            "fit": default("fit"),
            "frames": default("frames"),
            "enhancement": default("enhancement"),
            "method": default("method"),
            **STUDIO_SWITCHES,
        },
    }


def check_options(ws: Workspace, body: Any) -> tuple[dict[str, Any], str]:
    """The client's options checked for form (names, types, upload ids): (options to record, title).

    Raises:
        StudioError: not an object, an unknown option, a wrong type, a missing picture.
        NotFound: an upload id the workspace does not hold.
    """
    from saucerfab.optimize.request import checked_options

    if not isinstance(body, dict):
        raise StudioError('the run options must be a JSON object, e.g. {"direct": UPLOAD_ID, "reflected": UPLOAD_ID}')
    title = body.get("title")
    given = {k: v for k, v in body.items() if v is not None}  # null: not given (as in merged_options)
    options: dict[str, Any] = checked_options(given, door=STUDIO_DOOR, extra=_STUDIO_OPTIONS, error=StudioError)
    options.pop("title", None)
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
    from saucerfab.model.heightfield import BASE_SHAPES
    from saucerfab.model.profiles import list_profiles
    from saucerfab.model.scene import PRESETS
    from saucerfab.optimize.request import DesignRequest

    given = {k: v for k, v in options.items() if k not in STUDIO_SWITCHES}
    paths: dict[str, object] = {name: ws.upload_path(given[name]) for name in UPLOAD_FIELDS if name in given}
    shape = given.get("shape")
    if isinstance(shape, str):
        if UPLOAD_ID_RE.match(shape):
            paths["shape"] = str(ws.upload_path(shape))
        elif shape.replace("-", "_").lower() not in BASE_SHAPES:
            raise ConfigError(f"unknown base shape {shape!r}; built-in shapes are {sorted(BASE_SHAPES)}, or upload "
                              "a heightfield (.png or .npy) and give its upload id")
    if "scene" in given and given["scene"] not in PRESETS:
        raise ConfigError(f"unknown scene {given['scene']!r}; the studio's scenes are {sorted(PRESETS)}")
    if "printer" in given and given["printer"] not in list_profiles():
        raise ConfigError(f"unknown printer {given['printer']!r}; the printers are {sorted(list_profiles())}")
    return DesignRequest.from_options(given, door=STUDIO_DOOR, inputs=paths)


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
