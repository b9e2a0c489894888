"""What a design run is asked to do: inputs, scene, sizes, weights, switches.

:class:`DesignRequest` is the one home of a design run's defaults and of the
lists of choices its options take (``saucerfab design`` and the batch
manifest read them from here). Its weight fields come from the declared
energy terms (:data:`saucerfab.optimize.energies.WEIGHTS`).
"""

from __future__ import annotations

import functools
import math
import os
import types
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields, make_dataclass
from pathlib import Path
from typing import Any

from saucerfab.errors import ConfigError, SaucerfabError
from saucerfab.imaging.fitting import FITS
from saucerfab.model.eyes import DEFAULT_IPD_MM, EYES_USAGE, OLD_DESIGN_EYE_NAME, EyeSpec, parse_eyes
from saucerfab.model.heightfield import HEIGHT_SCALE
from saucerfab.model.profiles import DEFAULT_PRINTER
from saucerfab.model.scene import DEFAULT_PRESET, VIEW_NAMES
from saucerfab.optimize.energies import WEIGHTS
from saucerfab.optimize.stages import ABLATION_STAGES, METHODS, check_weights, stage_cap, stages_for, stall_window

#: the request's image fields: one picture per view, and its optional foreground mask
IMAGE_ROLES = VIEW_NAMES + tuple(f"{v}_mask" for v in VIEW_NAMES)

#: conflict-reduction strategies of the full method: "subject" is the paper's
#: black-white enhancement (each picture needs a clear subject), "none" uses the
#: pictures as they are (Figure 11 e), "auto" picks per pair (see optimize/prepare.py)
ENHANCEMENTS = ("auto", "subject", "none")
#: the paper's method ("full") and Figure 11's ablations
ABLATIONS = tuple(ABLATION_STAGES)
#: view frames (the first is the default; see DesignRequest.frames)
FRAMES = ("inscribed", "contain", "cover", "scene")
#: prism placements with a second reflected image (the first is the default)
PRISM_PLACEMENTS = ("auto", "as_given")
#: starting face colours (the first is the default)
COLOR_INITS = ("gray", "projected")
#: the default weight of the whole view around the frames (DesignRequest.surround_weight)
SURROUND_WEIGHT = 1.0

#: one keyword-only field per declared weight: a rho weight is None ("automatic") unless given
_Weights = make_dataclass(
    "_Weights",
    [(w.key, float | None if w.per_stage else float, field(default=w.default, kw_only=True)) for w in WEIGHTS],
    frozen=True,
)


def _one_of(name: str, value: object, choices: tuple[str, ...]) -> None:
    """Refuse ``value`` unless it is one of ``choices``."""
    if value not in choices:
        listed = ", ".join(repr(c) for c in choices[:-1]) + f" or {choices[-1]!r}"
        raise ConfigError(f"{name} must be {listed}, got {value!r}")


@dataclass(frozen=True)
class DesignRequest(_Weights):
    """All inputs of one ``saucerfab design`` run.

    Attributes:
        direct: image seen directly on the saucer (PNG/JPEG/WebP).
        reflected: image seen in the mirror cup.
        shape: base shape: a built-in name (``saucerfab shapes``) or a .png/.npy file.
        scene: a preset name (``saucerfab.model.scene.PRESETS``: "paper", the default, or "wide")
            or a scene TOML path.
        reflected2: second reflected image (prism cups, two-reflection mode).
        cup: optional cup spec overriding the scene's (``circle:R``, ``prism:6``...).
        resolution: heightfield vertices per side (None: the scene's, 150).
        image_size: rendered image size in pixels (None: the scene's, 512).
        seed: seed for everything random (seeded shapes, tie breaks).
        direct_mask, reflected_mask, reflected2_mask: optional foreground mask images.
        height_scale: model units per unit of a shape file's values.
        w_large, w_small, lam, barrier_weight: the weights of the energy terms,
            one keyword-only field per declared weight
            (:data:`saucerfab.optimize.energies.WEIGHTS`). w_large, w_small
            (E_deform at sigma 1e-5 and 1e-7) and lam (E_sparse) override the
            automatic rho-based weights when given. barrier_weight weighs
            E_barrier (eq. 5) in the objective; 1 is the paper as written.
            The barrier only has to keep iterates feasible (the line search
            does too). At weight 1 a face covering a few pixels settles near
            c = 0.33 instead of the enhancement's black, which blunts the
            black-white contrast; at the default 0.01 the full method reaches
            lower E_visual and E_deform (benchmarks/results/HISTORY.md, "Design (issue 4)").
        max_iters: iteration cap for every stage; None (the default): the
            cap of the method that runs (:data:`saucerfab.optimize.stages.STAGE_CAPS`:
            under "auto" 120 for pictures with the black-white enhancement
            and 90 for photographs, 120 for "fast", 400 for "paper" and the
            ablations).
        ablation: "full" (the paper's method) or one of Figure 11's ablations
            (:data:`ABLATIONS`, the keys of :data:`saucerfab.optimize.stages.ABLATION_STAGES`).
        method: how the full method runs (:data:`METHODS`): "auto" (the
            default) skips the small-sigma Laplacian stage for pictures with
            the black-white enhancement (each stage to at most 120
            iterations) and runs it for photographs (90 each); "fast" always
            skips it (120 each); "paper" runs Algorithm 1's three stages as
            written, to 400 iterations each. The ablations always run as the
            paper wrote them ("fast" with one is refused). Measured in
            benchmarks/RESULTS.md, Design speed against its anchors; the
            module docstring of
            :mod:`saucerfab.optimize.stages`.
        frames: "inscribed" (the default) re-aims the scene's view frames at
            the largest square wholly on the saucer and wholly on its
            reflection, so each whole picture is seen; "contain" at the
            largest square in the bounding box of each (the reflected
            picture's corners then fall off the reflection); "cover" so the
            saucer fills each frame (the pictures' margins fall off it);
            "scene" keeps the scene's frames as they are (the paper's
            preset, which puts part of each picture where no saucer is).
            Measured in benchmarks/results/HISTORY.md ("Verify (issue 13)",
            "Default path (issue 14, in part)"). See
            :mod:`saucerfab.optimize.framing`.
        enhancement: "auto" (the default) uses the paper's black-white
            enhancement when every picture has a clear subject (an alpha
            channel, a mask file, or a subject on a plain background) and
            the pictures as they are otherwise (full-bleed photographs);
            "subject" always enhances (a picture without a usable mask is
            refused); "none" never does. Only with ``ablation="full"``.
        fit: what of each picture its frame shows, at that part's own aspect (a wide
            picture gets a wide frame: :mod:`saucerfab.optimize.framing`): "pad" (the
            whole picture) or "crop" (cut to its content: the box of what differs from
            its background, :func:`saucerfab.imaging.fitting.crop_to_content`); one rule for all,
            or per picture as "direct=crop,reflected=pad".
        background: "#rrggbb" of the padding, of what transparent areas
            show and of the ground outside the frames; None: each picture's border
            colour (median of its outer ring), and outside the frames one ground,
            the direct picture's, where those differ
            (:func:`saucerfab.imaging.images.piece_ground`).
        color_init: "gray" (0.5 everywhere, the paper's choice) or "projected"
            (each face coloured from the enhanced targets by the texturing
            step, the paper's Figure 12 (c), which it reports as comparable;
            it skips the first iterations' colour fitting).
        record_times: write wall-clock times into the design folder
            (design.json metrics, the energy log, the energies plot's axis).
            False makes the folder byte-identical run to run, as batch jobs
            need; the plot is then over iterations.
        printer: the printer profile the design is made for (a key such as
            ``j55``, or a profile .toml): the optimizer keeps the relief within
            its minimum feature and the design is refused up front when the
            part cannot fit its build volume (:mod:`saucerfab.optimize.printable`).
        cup_diameter_mm: the real cup's width across its footprint, mm (None:
            the scene's, 80); sets the design's physical scale.
        saucer_diameter_mm: a round saucer's diameter, mm (None: the scene's; the ``round``
            preset's is :data:`saucerfab.model.scene.ROUND_DIAMETER_PER_CUP` times the cup's
            width). The scene's disc is rebuilt at that diameter
            (:func:`saucerfab.model.scene.disc_saucer`), its grid from
            :func:`~saucerfab.model.scene.round_grid` unless ``resolution`` is given. Only for a
            scene whose saucer is a disc: with a rectangle it is refused, as is a disc too small
            for the cup (the scene's own message names the smallest), when the scene is built
            (:func:`saucerfab.optimize.prepare.build_scene`, before any work).
        prism_placement: with a second reflected image, "auto" turns the
            prism to the placement whose facet regions overlap least
            (:func:`saucerfab.optimize.regions.best_placement`); "as_given"
            keeps the cup's rotation.
        eyes: where the design is optimised for (:mod:`saucerfab.model.eyes`, one definition
            with ``saucerfab verify``): "design" (the paper: the design eye alone;
            "point", its older name, is read as "design"),
            "both" (the design eye and a viewer's two eyes, ``ipd_mm`` apart along the
            direct view's right axis) or "box:W,H[,N]" (an N x N grid of eyes, W x H mm,
            around the design eye). Millimetres at the design's scale
            (``cup_diameter_mm``). E_visual sums over the eyes, each with its own
            direct and reflected views (:mod:`saucerfab.optimize.viewpoints`,
            weights :func:`saucerfab.model.eyes.eye_weights`), and the texturing blends
            what each eye wants. Measured in benchmarks/RESULTS.md (Eyes).
        surround_weight: the weight of the whole view around the frames
            (:mod:`saucerfab.optimize.surround`): the saucer seen directly outside the
            direct frame and the mirror's image of it outside the reflected frame aim at
            each picture's background, per unit of view area against the frames'
            E_visual; 0 leaves them out (the paper's energy, the frames alone). None (the
            default): :data:`SURROUND_WEIGHT` for the full method, 0 for an ablation (Figure 11's
            settings are the paper's energies; a weight given with one is refused).
        ipd_mm: the distance between a viewer's eyes with ``eyes="both"`` (None: 64 mm,
            :data:`saucerfab.model.eyes.DEFAULT_IPD_MM`); refused with the other modes.
    """

    direct: Path
    reflected: Path
    shape: str = "waves"
    scene: str = DEFAULT_PRESET
    reflected2: Path | None = None
    cup: str | None = None
    resolution: int | None = None
    image_size: int | None = None
    seed: int = 0
    direct_mask: Path | None = None
    reflected_mask: Path | None = None
    reflected2_mask: Path | None = None
    height_scale: float = HEIGHT_SCALE
    max_iters: int | None = None
    ablation: str = "full"
    method: str = METHODS[0]
    frames: str = FRAMES[0]
    enhancement: str = ENHANCEMENTS[0]
    fit: str = FITS[0]
    background: str | None = None
    printer: str = DEFAULT_PRINTER
    cup_diameter_mm: float | None = None
    prism_placement: str = PRISM_PLACEMENTS[0]
    color_init: str = COLOR_INITS[0]
    record_times: bool = True
    eyes: str = "design"
    ipd_mm: float | None = None
    surround_weight: float | None = None
    saucer_diameter_mm: float | None = None

    def eye_spec(self) -> EyeSpec:
        """The eyes the design is made for (:attr:`eyes`, :attr:`ipd_mm`), as verify takes them."""
        ipd = DEFAULT_IPD_MM if self.ipd_mm is None else self.ipd_mm
        return parse_eyes(self.eyes, ipd)

    def fit_by_view(self) -> dict[str, str]:
        """The fit rule of each view (``direct``, ``reflected``, ``reflected2``) from :attr:`fit`.

        Raises:
            ConfigError: not ``pad``, ``crop`` or ``VIEW=RULE,...`` with known views and rules.
        """
        views = VIEW_NAMES
        text = str(self.fit).strip().lower()
        if text in FITS:
            return dict.fromkeys(views, text)
        out = dict.fromkeys(views, FITS[0])
        for part in text.split(","):
            view, _, rule = part.partition("=")
            if view.strip() not in views or rule.strip() not in FITS:
                raise ConfigError(
                    f"--fit {self.fit!r}: give pad or crop, or per picture e.g. 'direct=crop,reflected=pad' "
                    f"(pictures: {', '.join(views)}; rules: {', '.join(FITS)})"
                )
            out[view.strip()] = rule.strip()
        return out

    def __post_init__(self) -> None:
        for name in IMAGE_ROLES:
            v = getattr(self, name)
            if v is not None:
                object.__setattr__(self, name, Path(os.fspath(v)))
        if self.ablation not in ABLATIONS:
            raise ConfigError(f"unknown ablation {self.ablation!r}; use one of {ABLATIONS}")
        stages_for(self.ablation, self.method)  # refuses an unknown method, and fast with an ablation
        self.fit_by_view()  # refuses a bad --fit now, before any work
        if self.background is not None:
            from saucerfab.imaging.images import parse_colour

            parse_colour(self.background)
        if self.enhancement not in ENHANCEMENTS:
            raise ConfigError(f"enhancement must be one of {', '.join(ENHANCEMENTS)}, got {self.enhancement!r}")
        if self.enhancement != "auto" and self.ablation != "full":
            raise ConfigError(
                f"--enhancement {self.enhancement} chooses the targets of the full method, but --ablation "
                f"{self.ablation} fixes its own; give one of the two"
            )
        _one_of("frames", self.frames, FRAMES)
        _one_of("prism_placement", self.prism_placement, PRISM_PLACEMENTS)
        _one_of("color_init", self.color_init, COLOR_INITS)
        v = self.cup_diameter_mm
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0):
            raise ConfigError(f"cup_diameter_mm must be a positive number of millimetres, got {v!r}")
        v = self.saucer_diameter_mm
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0):
            raise ConfigError(f"saucer_diameter_mm must be a positive number of millimetres, got {v!r}")
        if not isinstance(self.printer, str) or not self.printer:
            raise ConfigError(f"printer must be a profile name such as 'j55' or a .toml path, got {self.printer!r}")
        if not isinstance(self.eyes, str):
            raise ConfigError(f"eyes must be one of {EYES_USAGE}, got {self.eyes!r}")
        if self.eyes.strip().lower() == OLD_DESIGN_EYE_NAME:  # one word in every command: the older name read
            object.__setattr__(self, "eyes", "design")
        if self.ipd_mm is not None and (isinstance(self.ipd_mm, bool) or not isinstance(self.ipd_mm, (int, float))):
            raise ConfigError(f"ipd_mm must be a distance in mm, got {self.ipd_mm!r}")
        spec = self.eye_spec()  # refuses a bad --eyes or --ipd-mm now, before any work
        if self.ipd_mm is not None and spec.mode != "both":
            what = "the design eye alone" if spec.mode == "design" else "an eye box (its size is box:W,H)"
            raise ConfigError(
                f"--ipd-mm {self.ipd_mm:g} sets the distance between a viewer's two eyes, but --eyes {self.eyes} is "
                f"{what}; drop --ipd-mm, or give --eyes both"
            )
        if spec.mode != "design" and self.reflected2 is not None:
            raise ConfigError(
                f"--eyes {self.eyes} is not supported with a second reflected image (--reflected2) yet; "
                "give --eyes design"
            )
        v = self.surround_weight
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0):
            raise ConfigError(f"surround_weight must be a non-negative number (0: the frames alone), got {v!r}")
        if v and self.ablation != "full":
            raise ConfigError(
                f"--ablation {self.ablation} runs the paper's Figure 11 setting with the paper's energies, which score "
                f"the frames alone; --surround-weight {v:g} would add the whole view: give one of the two"
            )
        v = self.max_iters
        if v is not None and (isinstance(v, bool) or not isinstance(v, int)):
            raise ConfigError(f"max_iters must be a whole number of iterations per stage, got {v!r}")
        if v is not None and v < 1:
            raise ConfigError(f"max_iters must be at least 1, got {v}")
        for w in WEIGHTS:
            v = getattr(self, w.key)
            if w.positive and not (v > 0):
                raise ConfigError(f"{w.key} must be positive, got {v!r}")
            if not w.positive and v is not None and not (v >= 0):
                raise ConfigError(f"{w.key} must be a non-negative number, got {v!r}")
        # a weight no stage of this run uses would be ignored
        # (with --enhancement auto, whether the pictures get the enhancement is known once they are read)
        enhanced = {"subject": True, "none": False}.get(self.enhancement)
        check_weights(self.ablation, {w.key: getattr(self, w.key) for w in WEIGHTS}, self.method, enhanced)

    def surround(self) -> float:
        """The weight of the whole view around the frames this run uses (:attr:`surround_weight` resolved)."""
        if self.surround_weight is not None:
            return float(self.surround_weight)
        return SURROUND_WEIGHT if self.ablation == "full" else 0.0

    def stage_cap(self, enhanced: bool = True) -> int:
        """Iterations per stage at most: :attr:`max_iters`, or the cap of the method that runs.

        Args:
            enhanced: the pictures have the black-white enhancement, or are used as they are (known once
                they are read: ``prepare``).
        """
        return stage_cap(self.ablation, self.method, self.max_iters, enhanced)

    def stall_window(self) -> int:
        """Renders over which a stage must make progress, else it ends (0: the paper's rules only)."""
        return stall_window(self.ablation, self.method)

    @classmethod
    def default(cls, name: str) -> object:
        """The default of field ``name`` (for ``--help`` texts), e.g. ``DesignRequest.default("max_iters")``."""
        return cls.__dataclass_fields__[name].default

    @classmethod
    def from_options(
        cls,
        options: Mapping[str, object],
        *,
        door: OptionsDoor,
        allowed: frozenset[str] | None = None,
        inputs: Mapping[str, object] | None = None,
        error: type[SaucerfabError] = ConfigError,
    ) -> DesignRequest:
        """The request of a mapping of options (a manifest's ``design_options``, the studio's form).

        Args:
            options: field name -> value as the front door read it (TOML, CSV, JSON values);
                checked and converted by :func:`checked_options`.
            door: the front door (:class:`OptionsDoor`): its messages, and which errors
                of building the request it rewords.
            allowed: the fields ``options`` may set; None: every field.
            inputs: fields the front door resolved itself (image paths, an uploaded
                shape's path), laid over ``options`` unchecked.
            error: the class of every refusal (the studio's, say).

        Raises:
            SaucerfabError: an unknown field, a value of the wrong type (as ``error``), or
                a value the request refuses (as the request raised it, or as ``error``
                with the door's prefix).
        """
        kwargs = checked_options(options, door=door, allowed=allowed, error=error)
        try:
            return cls(**{**kwargs, **(inputs or {})})
        except door.build_errors as exc:
            raise error(f"{door.build_prefix}{exc}") from None


# --------------------------------------------------------------------------- options from a front door

@dataclass(frozen=True)
class OptionsDoor:
    """How one front door takes a mapping of design options, and words what it refuses.

    Each door defines its own (the batch manifest's ``design_options``:
    :data:`saucerfab.batch.manifest.MANIFEST_DOOR`; the studio's run form:
    :data:`saucerfab.studio.options.STUDIO_DOOR`); the check is this module's.

    Attributes:
        words: what a value of each kind (``bool``, ``int``, ``float``, ``str``, ``path``) must be, in
            the door's messages.
        text_max: the longest text a ``str`` option takes, in characters; None: any.
        finite: refuse NaN and infinities at the type check; False leaves them to the request's own checks.
        paths_as_text: a ``Path`` option must be a text (the studio's upload id), not any path-like object.
        all_at_once: every unknown name in one message, else every mistyped option in one (sorted by
            name); False: the first problem in the order given, alone.
        unknown: the message for the unknown names (in the order given) and the names known.
        mistyped: the message for the mistyped options, each (name, what it must be, value).
        build_errors: errors of building the request that are reworded as ``build_prefix`` + message;
            any other passes as the request raised it.
        build_prefix: see ``build_errors``.
    """

    words: dict[str, str]
    text_max: int | None
    finite: bool
    paths_as_text: bool
    all_at_once: bool
    unknown: Callable[[list[str], Mapping[str, object]], str]
    mistyped: Callable[[list[tuple[str, str, object]]], str]
    build_errors: tuple[type[Exception], ...]
    build_prefix: str


#: what a value of each kind must be, in words every door may start from
TYPE_WORDS = {"bool": "true or false", "int": "a whole number", "float": "a number"}


@functools.lru_cache(maxsize=1)
def _request_hints() -> dict[str, Any]:
    """:class:`DesignRequest`'s init fields -> their annotations, evaluated once (get_type_hints is slow)."""
    hints = typing.get_type_hints(DesignRequest)
    return {f.name: hints[f.name] for f in fields(DesignRequest) if f.init}


def _fit(value: object, hint: Any, door: OptionsDoor) -> tuple[object, str | None]:
    """(``value`` converted, None) when it fits the annotation ``hint``, else (``value``, what it must be).

    Covers the annotations of :class:`DesignRequest` (``bool``, ``int``, ``float``, ``str``,
    ``Path``, ``X | None``) and ``tuple[X, ...]`` / ``tuple[X, Y]`` (a list or tuple, item by
    item, made a tuple). TOML, CSV and JSON values are plain, so nothing more is needed. A
    whole number is a number (``height_scale = 1``, made 1.0); a bool is neither (Python's
    bool is an int). Any other annotation lets the value through: the request's own checks
    judge it.
    """
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(hint)
        if value is None and type(None) in args:
            return None, None
        wants = []
        for arg in args:
            if arg is not type(None):
                fitted, want = _fit(value, arg, door)
                if want is None:
                    return fitted, None
                wants.append(want)
        return value, " or ".join(wants)
    if origin is tuple:
        return _fit_tuple(value, typing.get_args(hint), door)
    if hint is bool:
        return (value, None) if isinstance(value, bool) else (value, door.words["bool"])
    if hint is int:
        return (value, None) if isinstance(value, int) and not isinstance(value, bool) else (value, door.words["int"])
    if hint is float:
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            return value, door.words["float"]
        try:
            number = float(value)
        except OverflowError:  # a whole number past float's range (JSON allows any length)
            return value, door.words["float"]
        if door.finite and not math.isfinite(number):
            return value, door.words["float"]
        return number, None
    if hint is str:
        fits = isinstance(value, str) and (door.text_max is None or len(value) <= door.text_max)
        return (value, None) if fits else (value, door.words["str"])
    if hint is Path:  # kept as given: DesignRequest makes it a Path, the studio records its upload id
        fits = isinstance(value, str) or (not door.paths_as_text and isinstance(value, os.PathLike))
        return (value, None) if fits else (value, door.words["path"])
    return value, None


def _fit_tuple(value: object, args: tuple[Any, ...], door: OptionsDoor) -> tuple[object, str | None]:
    """:func:`_fit` for ``tuple[X, ...]`` (``args`` ``(X, Ellipsis)``) and ``tuple[X, Y, ...]`` (fixed length)."""
    variadic = len(args) == 2 and args[1] is Ellipsis
    items = [args[0]] if variadic else list(args)
    wants = [_fit(None, a, door)[1] or "none" for a in items]  # what each item must be, for the message
    want = f"a list, each item {wants[0]}" if variadic else f"a list of {len(items)} items ({', '.join(wants)})"
    if not isinstance(value, (list, tuple)) or (not variadic and len(value) != len(items)):
        return value, want
    out = []
    for i, item in enumerate(value):
        fitted, problem = _fit(item, items[0] if variadic else items[i], door)
        if problem is not None:
            return value, want
        out.append(fitted)
    return tuple(out), None


def checked_options(
    options: Mapping[str, object],
    *,
    door: OptionsDoor,
    allowed: frozenset[str] | None = None,
    extra: Mapping[str, Any] | None = None,
    error: type[SaucerfabError] = ConfigError,
) -> dict[str, object]:
    """``options`` checked against :class:`DesignRequest`'s fields and annotations, and converted.

    The one check of every front door that takes design options as a mapping (the
    batch manifest, the studio): the names (an unknown one is refused with the
    names known), the value types by the field annotations (:func:`_fit`: a bool is
    not a whole number, a text is not a number, None only where the field is
    Optional, a list where it is a tuple) and the conversion (a whole number given
    for a number becomes a float, a list for a tuple a tuple). The values themselves
    (ranges, choices) are the request's to judge: :meth:`DesignRequest.from_options`.

    Args:
        options: field name -> value, as the front door read it.
        door: the front door (:class:`OptionsDoor`): its messages and rules.
        allowed: the fields ``options`` may set; None: every init field.
        extra: the front door's own options (name -> annotation), checked and returned
            the same way (an ``object`` annotation takes any value).
        error: the class of the refusal.

    Returns:
        The options, converted, in the order given.

    Raises:
        SaucerfabError: as ``error``: unknown names, else values of the wrong type
            (all at once or the first, as the door says).
    """
    fields_hints = _request_hints()
    names = fields_hints.keys() if allowed is None else allowed
    if strange := sorted(set(names) - fields_hints.keys()):  # a caller's mistake, not the user's
        raise ValueError(f"allowed names fields DesignRequest does not have: {strange}")
    hints = {**{n: fields_hints[n] for n in names}, **(extra or {})}
    out: dict[str, object] = {}
    unknown: list[str] = []
    mistyped: list[tuple[str, str, object]] = []
    for name, value in options.items():
        if name not in hints:
            unknown.append(name)
        else:
            fitted, want = _fit(value, hints[name], door)
            if want is None:
                out[name] = fitted
            else:
                mistyped.append((name, want, value))
        if (unknown or mistyped) and not door.all_at_once:
            break
    if unknown:
        raise error(door.unknown(unknown, hints))
    if mistyped:
        raise error(door.mistyped(sorted(mistyped, key=lambda m: m[0])))
    return out
