"""The validated inputs of a design run: ``prepare`` reads and checks every input before any work.

* :func:`build_scene`: the request's scene with its overrides (cup, size, a round saucer's
  diameter, resolution);
* :func:`prepare`: the base shape, the fitted pictures (at the render and the
  texture size), their masks and enhanced targets, the printer target and
  the prism placement, as a :class:`Prepared`, so bad input stops at once
  with a clear message;
* :func:`choose_enhancement`: which conflict reduction the design uses, and why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from saucerfab.errors import ConfigError, MaskError
from saucerfab.files.fileio import sha256_file
from saucerfab.model.cups import parse_cup_spec
from saucerfab.model.scene import VIEW_NAMES, Saucer, Scene, disc_saucer, load_scene, round_grid
from saucerfab.optimize.printable import PrintTarget, preflight, print_target
from saucerfab.optimize.request import DesignRequest

#: the largest texture panel, pixels per side (the texture keeps more detail than the render size)
TEXTURE_MAX = 2048


@dataclass
class Prepared:
    """Validated inputs of a run.

    Attributes:
        scene: the scene with the request's overrides applied.
        base: (N, N) base heights, model units.
        render: view name -> (S, S, 3) fitted input image in [0, 1].
        texture: view name -> (T, T, 3) fitted input image for the texture.
        enhanced: view name -> (S, S, 3) enhanced target (black-white or solid colour).
        masks: view name -> (S, S) bool foreground mask.
        inputs: names and sha256 of the input files.
        reflected_groups: prism facet groups in two-reflection mode, else None.
        placement: in two-reflection mode, the prism placement chosen and
            the region overlap of each option.
        enhancement: the conflict reduction chosen: asked, strategy
            (``subject``, ``none`` or ``ablation``) and why (:func:`choose_enhancement`).
        target: the printer and scale the design is made for.
        print_notes: what :func:`saucerfab.optimize.printable.preflight` had to say.
        ground: ``#rrggbb`` every view's surround aims at outside the frames (the
            ``--background``, or the one ground :func:`saucerfab.imaging.images.piece_ground`
            chose for pictures whose border colours differ); None: each picture's own.
    """

    scene: Scene
    base: np.ndarray
    render: dict[str, np.ndarray]
    texture: dict[str, np.ndarray]
    enhanced: dict[str, np.ndarray]
    masks: dict[str, np.ndarray]
    inputs: dict[str, Any]
    reflected_groups: list[list[int]] | None
    placement: dict[str, Any] | None = None
    enhancement: dict[str, str] | None = None
    target: PrintTarget | None = None
    print_notes: tuple[str, ...] = ()
    ground: str | None = None


def build_scene(request: DesignRequest) -> Scene:
    """The request's scene with its cup, cup diameter, saucer diameter, resolution and image-size overrides.

    Raises:
        ConfigError: a saucer diameter for a scene whose saucer is not a disc; a bad override.
        GeometryError: the cup does not fit the saucer (a disc too small: the message names the smallest).
    """
    scene = load_scene(request.scene)
    if request.saucer_diameter_mm is not None:
        scene = _round_saucer(scene, request)
    else:
        if request.cup:
            scene = replace(scene, cup=parse_cup_spec(request.cup))
        if request.cup_diameter_mm is not None:
            scene = scene.with_changes(cup_diameter_mm=float(request.cup_diameter_mm))
    if request.resolution is not None:
        scene = replace(scene, saucer=replace(scene.saucer, resolution=int(request.resolution)))
    if request.image_size is not None:
        s = int(request.image_size)
        scene = replace(
            scene,
            direct=replace(scene.direct, image_size=s),
            reflected=replace(scene.reflected, image_size=s),
        )
    return scene


def _round_saucer(scene: Scene, request: DesignRequest) -> Scene:
    """``scene`` with the request's cup and cup diameter and its disc rebuilt ``saucer_diameter_mm`` across.

    One step, not three: a scene with the preset's disc around the request's cup could be refused
    before the disc the request asks for is in place. The disc's grid is
    :func:`~saucerfab.model.scene.round_grid`'s, or the request's resolution.
    """
    if not scene.saucer.is_disc:
        raise ConfigError(
            f"--saucer-diameter-mm is for a round saucer: add --scene round (the scene {str(request.scene)!r} "
            "has a rectangle saucer)"
        )
    cup = parse_cup_spec(request.cup) if request.cup else scene.cup
    cup_mm = scene.cup_diameter_mm if request.cup_diameter_mm is None else float(request.cup_diameter_mm)
    diameter = float(request.saucer_diameter_mm) * cup.width_units / cup_mm  # mm -> model units at this scale
    return replace(scene, cup=cup, cup_diameter_mm=cup_mm, saucer=_disc(scene, diameter, request))


def _disc(scene: Scene, diameter: float, request: DesignRequest) -> Saucer:
    """``scene``'s disc rebuilt ``diameter`` model units across: its grid at the paper's step, or the request's."""
    n = request.resolution if request.resolution is not None else round_grid(diameter)
    return disc_saucer(diameter, int(n), scene.saucer.delta)


def _disc_for_printer(scene: Scene, request: DesignRequest, target: PrintTarget) -> tuple[Scene, list[str]]:
    """A round scene's own disc (no ``--saucer-diameter-mm``) shrunk to the largest the printer's build area
    takes, with a note saying so; a diameter the user gave is left for the preflight to refuse."""
    if not scene.saucer.is_disc or request.saucer_diameter_mm is not None:
        return scene, []
    s = scene.mm_per_unit
    across = 2.0 * scene.saucer.radius * s
    largest = math.floor(min(target.profile.build_volume_mm[:2]) + 1e-9)
    if across <= largest:
        return scene, []
    fitted = replace(scene, saucer=_disc(scene, largest / s, request))  # too small: the scene's own error
    return fitted, [f"the round saucer is {largest:g} mm across, the largest {target.profile.name}'s build area takes "
                    f"(the scene's is {across:.0f} mm; --saucer-diameter-mm sets it)"]


def prepare(request: DesignRequest) -> Prepared:
    """Read and validate every input; raise a SaucerfabError before any work."""
    from saucerfab.imaging import fitting
    from saucerfab.imaging import images as im
    from saucerfab.imaging.masks import PLAIN_SHARE, plain_background_share, prepare_image
    from saucerfab.model.heightfield import load_shape
    from saucerfab.optimize.enhancement import black_white_targets, solid_colour_targets

    scene = build_scene(request)
    if request.reflected2 is not None and not scene.cup.faceted:
        raise ConfigError(
            "a second reflected image needs a prism cup (e.g. --cup prism:6): only a prism's "
            f"facets split the reflection into two regions; the scene's cup is a {scene.cup.kind}"
        )
    target = print_target(scene, request.printer)  # an unknown printer stops here, before any reading
    scene, fit_note = _disc_for_printer(scene, request, target)
    n = scene.saucer.resolution
    base = load_shape(request.shape, n, height_scale=request.height_scale, seed=request.seed, saucer=scene.saucer)
    print_notes = [*fit_note, *preflight(target, scene, base)]
    groups: list[list[int]] | None = None
    placement: dict[str, Any] = {}
    if request.reflected2 is not None:
        from saucerfab.optimize.regions import best_placement, region_report, split_reflected_facets

        if request.prism_placement == "auto":
            scene, pick, reports = best_placement(scene, base)
            placement = {"placement": pick, "options": {k: r.to_dict() for k, r in reports.items()}}
        else:
            placement = {"placement": "as_given", "options": {"as_given": region_report(scene, base).to_dict()}}
        groups = split_reflected_facets(scene, base)
    # the views whose picture is given (direct and reflected always; reflected2 with a prism)
    names = [v for v in VIEW_NAMES if getattr(request, v) is not None]
    fits = request.fit_by_view()
    pictures = {name: im.load_image(getattr(request, name)) for name in names}  # decoded once, fitted twice
    shown = {}  # what of each picture is shown: all of it, or ("crop") its content's box
    for name in names:
        if fits[name] == "crop" and getattr(request, f"{name}_mask") is not None:
            raise ConfigError(
                f"--fit crop cuts the {name} picture to its content, but its mask file covers the whole picture; "
                f"give --fit {name}=pad with the mask file, or leave the mask out"
            )
        shown[name] = fitting.crop_to_content(pictures[name], request.background) if fits[name] == "crop" else pictures[name]
    if request.frames != "scene":
        from saucerfab.optimize.framing import fit_frames, frame_notes

        # each frame at the aspect of what its picture shows
        aspects = {n: shown[n].size[0] / shown[n].size[1] for n in names}
        square = fit_frames(scene, base, request.frames, groups)
        scene = fit_frames(scene, base, request.frames, groups, aspects)
        print_notes = [*print_notes, *frame_notes(square, scene, aspects)]
    s = scene.direct.image_size
    t = int(min(TEXTURE_MAX, max(1024, s)))
    mask_paths: dict[str, Path | None] = {v: getattr(request, f"{v}_mask") for v in names}
    render, texture, masks, inputs = {}, {}, {}, {}
    problems: list[str] = []
    for name in names:
        path = getattr(request, name)
        loaded = pictures[name]
        fname = Path(path).name
        fit_args = {"fit": fits[name], "background": request.background}
        if request.enhancement == "none" and request.ablation == "full":
            view = prepare_image(path, s, mask_method="none", loaded=loaded, **fit_args)
        else:
            try:
                view = prepare_image(path, s, mask_path=mask_paths[name], loaded=loaded, **fit_args)
            except MaskError as exc:
                if request.enhancement == "subject" or request.ablation != "full":
                    raise
                # the reason without the machine's path to the file (design folders are reproducible)
                why = str(exc).split(". Give")[0].replace(repr(str(path)), repr(fname))
                problems.append(f"{name} picture: {why}")
                view = prepare_image(path, s, mask_method="none", loaded=loaded, **fit_args)
            else:
                if view.mask_source == "threshold":
                    plain = plain_background_share(view)
                    if plain < PLAIN_SHARE:
                        problems.append(f"{name} picture {fname!r}: no plain background around a subject "
                                        f"({plain:.0%} of it is near its border colour)")
        render[name] = view.flattened()
        masks[name] = view.mask
        # the texture keeps more of the input's detail than the render size
        rgb_t, alpha_t, _ = fitting.fit_square(loaded, t, background=view.background, fit=fits[name])
        texture[name] = rgb_t if alpha_t is None else im.flatten_alpha(rgb_t, alpha_t, view.background)
        inputs[name] = {"file": fname, "sha256": view.sha256, "mask_source": view.mask_source}
        if view.notes:
            inputs[name]["notes"] = list(view.notes)
        mask = mask_paths[name]
        if mask is not None:
            inputs[f"{name}_mask"] = {"file": Path(mask).name, "sha256": sha256_file(mask)}
    if Path(str(request.shape)).suffix.lower() in (".png", ".npy"):
        inputs["shape"] = {"file": Path(request.shape).name, "sha256": sha256_file(request.shape)}
    else:
        inputs["shape"] = {"builtin": request.shape}
    ground = im.piece_ground(texture, request.background)
    if request.background is None and ground is not None:
        print_notes.append(
            f"the pictures' border colours differ: outside the frames every view aims at the direct picture's, "
            f"{ground}, so the plate under the cup reads as one ground beside the cup and in it "
            "(--background chooses another)")
    enhancement = choose_enhancement(request, problems, {k: inputs[k]["mask_source"] for k in names})
    if enhancement["strategy"] == "none":
        enhanced = {k: v.copy() for k, v in render.items()}  # no enhanced targets: the pictures themselves
    elif len(names) == 2:  # the paper's black-white pair
        enhanced = dict(zip(names, black_white_targets(masks[names[0]], masks[names[1]])))
    else:
        e = solid_colour_targets([masks[k] for k in names])
        enhanced = dict(zip(names, e))
    return Prepared(
        scene, base, render, texture, enhanced, masks, inputs, groups, placement or None, enhancement,
        target, tuple(print_notes), ground,
    )


def choose_enhancement(request: DesignRequest, problems: list[str], sources: dict[str, str]) -> dict[str, str]:
    """Which conflict reduction the design uses, and why (recorded in design.json, printed by the CLI).

    ``auto``: the paper's black-white enhancement (``subject``) when every
    picture has a clear subject - an alpha channel, a mask file, or a subject
    the automatic mask finds on a plain background - and the pictures as they
    are (``none``, Figure 11 e) otherwise: a full-bleed photograph has no
    subject to paint black or white, and forcing one prints one picture's
    colours across the other. An ablation other than ``full`` keeps its own targets.
    """
    asked = request.enhancement
    if request.ablation != "full":
        return {"asked": asked, "strategy": "ablation", "why": f"--ablation {request.ablation} fixes the targets"}
    if asked != "auto":
        return {"asked": asked, "strategy": asked, "why": f"--enhancement {asked} was asked for"}
    if problems:
        return {"asked": asked, "strategy": "none", "why": "; ".join(problems)}
    how = ", ".join(f"{k}: {v} mask" for k, v in sources.items())
    return {"asked": asked, "strategy": "subject", "why": f"every picture has a clear subject ({how})"}
