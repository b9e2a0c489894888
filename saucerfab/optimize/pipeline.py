"""``run_design``: from a :class:`DesignRequest` to a design folder (Algorithm 1).

1. ``prepare``: every input is read and validated before any work (scene,
   shape, images, masks), so bad input stops at once with a clear message.
2. the stages of :mod:`saucerfab.optimize.stages` (the paper's method or an
   ablation), each a DR-solver run against blur-matched targets, with the
   weights set from the compatibility score rho unless the user gives them;
3. texturing with the final shape (section 3.4.2);
4. metrics, previews and the design folder, written atomically.

Checkpoints: after every stage, and on Ctrl-C, the iterate is saved in a
sibling folder ``.<out name>.checkpoint``; running the same request again
resumes from it (the request's hash must match). A finished run removes it.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from saucerfab import __version__
from saucerfab.design import Design, save_design
from saucerfab.errors import ConfigError, Interrupted, MaskError, OutputError
from saucerfab.fileio import sha256_file, write_bytes_atomic
from saucerfab.optimize.printable import PrintTarget, preflight, print_target
from saucerfab.optimize.request import DesignRequest
from saucerfab.optimize.stages import ABLATION_STAGES, SIGMA_LARGE, WEIGHT_FACTORS, StageSpec, without_enhancement
from saucerfab.scene import Scene, load_scene, parse_cup_spec

#: progress(stage, iteration, max_iterations, parts, elapsed_s)
Progress = Callable[[str, int, int, dict[str, float], float], None]

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


def build_scene(request: DesignRequest) -> Scene:
    """The request's scene with its cup, cup diameter, resolution and image-size overrides."""
    scene = load_scene(request.scene)
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


def prepare(request: DesignRequest) -> Prepared:
    """Read and validate every input; raise a SaucerfabError before any work."""
    from saucerfab import images as im
    from saucerfab.heightfield import load_shape
    from saucerfab.masks import PLAIN_SHARE, plain_background_share, prepare_image
    from saucerfab.optimize.enhancement import black_white_targets, solid_colour_targets

    scene = build_scene(request)
    if request.reflected2 is not None and not scene.cup.faceted:
        raise ConfigError(
            "a second reflected image needs a prism cup (e.g. --cup prism:6): only a prism's "
            f"facets split the reflection into two regions; the scene's cup is a {scene.cup.kind}"
        )
    target = print_target(scene, request.printer)  # an unknown printer stops here, before any reading
    n = scene.saucer.resolution
    base = load_shape(request.shape, n, height_scale=request.height_scale, seed=request.seed, saucer=scene.saucer)
    print_notes = preflight(target, scene, base)
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
    if request.frames != "scene":
        from saucerfab.optimize.framing import fit_frames

        scene = fit_frames(scene, base, request.frames, groups)
    s = scene.direct.image_size
    t = int(min(TEXTURE_MAX, max(1024, s)))
    names = ["direct", "reflected"] + (["reflected2"] if request.reflected2 is not None else [])
    paths = {"direct": request.direct, "reflected": request.reflected, "reflected2": request.reflected2}
    mask_paths = {
        "direct": request.direct_mask,
        "reflected": request.reflected_mask,
        "reflected2": request.reflected2_mask,
    }
    render, texture, masks, inputs = {}, {}, {}, {}
    problems: list[str] = []
    fits = request.fit_by_view()
    for name in names:
        path = paths[name]
        if path is None:  # pragma: no cover - names only lists given images
            continue
        loaded = im.load_image(path)  # decoded once, fitted at two sizes
        fname = Path(path).name
        fitting = {"fit": fits[name], "background": request.background}
        if request.enhancement == "none" and request.ablation == "full":
            view = prepare_image(path, s, mask_method="none", loaded=loaded, **fitting)
        else:
            try:
                view = prepare_image(path, s, mask_path=mask_paths[name], loaded=loaded, **fitting)
            except MaskError as exc:
                if request.enhancement == "subject" or request.ablation != "full":
                    raise
                # the reason without the machine's path to the file (design folders are reproducible)
                why = str(exc).split(". Give")[0].replace(repr(str(path)), repr(fname))
                problems.append(f"{name} picture: {why}")
                view = prepare_image(path, s, mask_method="none", loaded=loaded, **fitting)
            else:
                if view.mask_source == "threshold":
                    plain = plain_background_share(view)
                    if plain < PLAIN_SHARE:
                        problems.append(f"{name} picture {fname!r}: no plain background around a subject "
                                        f"({plain:.0%} of it is near its border colour)")
        render[name] = view.flattened()
        masks[name] = view.mask
        # the texture keeps more of the input's detail than the render size
        rgb_t, alpha_t, _ = im.fit_square(loaded, t, background=view.background, fit=fits[name])
        texture[name] = rgb_t if alpha_t is None else im.flatten_alpha(rgb_t, alpha_t, view.background)
        inputs[name] = {"file": Path(path).name, "sha256": view.sha256, "mask_source": view.mask_source}
        if view.notes:
            inputs[name]["notes"] = list(view.notes)
        if mask_paths[name] is not None:
            inputs[f"{name}_mask"] = {"file": Path(mask_paths[name]).name, "sha256": sha256_file(mask_paths[name])}
    if Path(str(request.shape)).suffix.lower() in (".png", ".npy"):
        inputs["shape"] = {"file": Path(request.shape).name, "sha256": sha256_file(request.shape)}
    else:
        inputs["shape"] = {"builtin": request.shape}
    enhancement = choose_enhancement(request, problems, {k: inputs[k]["mask_source"] for k in names})
    if enhancement["strategy"] == "none":
        enhanced = {k: v.copy() for k, v in render.items()}  # no enhanced targets: the pictures themselves
    elif len(names) == 2:
        e_d, e_r = black_white_targets(masks["direct"], masks["reflected"])
        enhanced = {"direct": e_d, "reflected": e_r}
    else:
        e = solid_colour_targets([masks[k] for k in names])
        enhanced = dict(zip(names, e))
    return Prepared(
        scene, base, render, texture, enhanced, masks, inputs, groups, placement or None, enhancement,
        target, tuple(print_notes),
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


def check_output_folder(out: Path, force: bool = True) -> None:
    """Refuse, before any work, an output path whose replacement would lose a user's data.

    The design folder is written atomically and replaces ``out`` when done;
    that is only safe when ``out`` does not exist, is an empty folder, or is
    an earlier design folder (it holds ``design.json``). With ``force``
    False an earlier design folder is refused too (the CLI without
    ``--force``); the library's default replaces it, as batch reruns need.
    """
    if not out.exists():
        return
    if not out.is_dir():
        raise ConfigError(f"--out {str(out)!r} is an existing file; give a new or empty folder for the design")
    if any(out.iterdir()) and not (out / "design.json").is_file():
        raise ConfigError(
            f"--out {str(out)!r} is a non-empty folder that is not a design folder; saucerfab would "
            "replace it. Give a new or empty folder, or remove it first"
        )
    if not force and (out / "design.json").is_file():
        raise ConfigError(
            f"--out {str(out)!r} already holds a design; writing this one would replace it. "
            "Give a new folder, or add --force to replace it"
        )


def request_hash(request: DesignRequest, prepared: Prepared) -> str:
    """Hash of everything that determines the result (for resume and batch)."""
    d = asdict(request)
    for k, v in list(d.items()):
        if isinstance(v, Path):
            d[k] = str(v)
    payload = json.dumps({"req": d, "inputs": prepared.inputs, "v": __version__}, sort_keys=True, default=str)
    return hashlib.sha256(payload.encode()).hexdigest()


class _Checkpoint:
    def __init__(self, out: Path, key: str) -> None:
        self.dir = out.parent / f".{out.name}.checkpoint"
        self.key = key

    def load(self) -> dict[str, Any] | None:
        f = self.dir / "state.npz"
        if not f.is_file():
            return None
        try:
            with np.load(f, allow_pickle=False) as z:
                if str(z["key"]) != self.key:
                    return None
                return {
                    "stage": int(z["stage"]),
                    "h": z["h"],
                    "c": z["c"],
                    "log": json.loads(str(z["log"])),
                    "metrics": json.loads(str(z["metrics"])),
                    "weights": json.loads(str(z["weights"])),
                    # wall time of earlier runs up to the saved state (0 in older checkpoints)
                    "elapsed_s": float(z["elapsed_s"]) if "elapsed_s" in z.files else 0.0,
                }
        except (OSError, ValueError, KeyError):
            return None  # a damaged checkpoint is ignored; the run starts afresh

    def save(
        self, stage: int, h: np.ndarray, c: np.ndarray, log: list, metrics: dict, weights: dict, elapsed_s: float = 0.0
    ) -> None:
        import io

        buf = io.BytesIO()
        np.savez(
            buf,
            key=np.array(self.key),
            stage=np.array(stage),
            h=h,
            c=c,
            log=np.array(json.dumps(log)),
            metrics=np.array(json.dumps(metrics)),
            weights=np.array(json.dumps(weights)),
            elapsed_s=np.array(float(elapsed_s)),
        )
        write_bytes_atomic(self.dir / "state.npz", buf.getvalue())

    def clear(self) -> None:
        shutil.rmtree(self.dir, ignore_errors=True)


def _print_progress(stage: str, it: int, max_it: int, parts: dict[str, float], elapsed: float) -> None:
    per = elapsed / max(it, 1)
    left = per * (max_it - it)
    print(
        f"  {stage:22s} it {it:4d}/{max_it}  E {parts.get('E_total', 0):11.4g}  "
        f"vis {parts.get('E_visual', 0):10.4g}  def {parts.get('E_deform', 0):9.3g}  "
        f"{per * 1000:5.0f} ms/it  <= {left:5.0f} s left",
        file=sys.stderr,
        flush=True,
    )


def run_design(
    request: DesignRequest,
    out: str | Path,
    *,
    progress: Progress | None = None,
    log_every_s: float = 2.0,
) -> Path:
    """Run the whole method and write the design folder ``out`` atomically.

    Args:
        request: what to design.
        out: the design folder to write (replaced atomically if it exists).
        progress: called with (stage, iteration, max, energies, elapsed) about
            every ``log_every_s`` seconds; default prints a line to stderr.

    Raises:
        SaucerfabError: bad inputs (before any work), Interrupted on Ctrl-C
        (after saving a checkpoint).
    """
    import torch

    from saucerfab.heightfield import laplacian
    from saucerfab.optimize.energies import DeformEnergy, barrier_floor, e_barrier, e_visual
    from saucerfab.optimize.printable import CrestProjection
    from saucerfab.optimize.solver import ProxSettings, SolverSettings, solve
    from saucerfab.optimize.targets import blur_matched_targets, compatibility, projected_colors
    from saucerfab.optimize.texturing import texture_saucer, visible_faces
    from saucerfab.optimize.views import Rig

    out = Path(out)
    t_start = time.perf_counter()
    check_output_folder(out)
    prep = prepare(request)
    progress = progress or _print_progress
    torch.manual_seed(request.seed)
    scene = prep.scene
    n = scene.saucer.resolution
    delta = scene.saucer.delta
    dtype = torch.float32
    base = prep.base
    rig = Rig(scene, base, reflected_groups=prep.reflected_groups)
    z = torch.as_tensor(base.reshape(-1), dtype=dtype)
    deform = DeformEnergy(laplacian(n), z)
    stages = ABLATION_STAGES[request.ablation]
    if prep.enhancement and prep.enhancement["strategy"] == "none":
        stages = without_enhancement(stages)
    ckpt = _Checkpoint(out, request_hash(request, prep))
    for note in prep.print_notes:
        print(f"  note: {note}", file=sys.stderr)
    # the printer's minimum feature and wall, kept on every iterate (saucerfab.relief)
    target = prep.target
    project = CrestProjection(target, scene, base) if target is not None else None

    # weights from rho (section 3.5) unless given
    t0 = time.perf_counter()
    targets_cache: dict[tuple[str, float], dict[str, Any]] = {}

    def targets_for(kind: str, sigma: float) -> dict[str, Any]:
        key = (kind, sigma)
        if key not in targets_cache:
            imgs = prep.enhanced if kind == "enhanced" else prep.render
            targets_cache[key] = blur_matched_targets(rig, base, imgs, sigma, dtype=dtype)
        return targets_cache[key]

    given = {"w_large": request.w_large, "w_small": request.w_small, "lam": request.lam}
    if all(v is not None for v in given.values()):
        rho = float("nan")
        weights = {k: float(v) for k, v in given.items()}  # type: ignore[arg-type]
    else:
        kind = stages[0].targets  # rho of the images the first stage aims at
        imgs = prep.enhanced if kind == "enhanced" else prep.render
        rho = compatibility(rig, base, imgs, targets_for(kind, SIGMA_LARGE), SIGMA_LARGE, dtype=dtype)
        weights = {k: (float(given[k]) if given[k] is not None else WEIGHT_FACTORS[k] * rho) for k in WEIGHT_FACTORS}
    t_setup = time.perf_counter() - t0

    log: list[dict[str, Any]] = []
    metrics: dict[str, Any] = {"stages": [], "rho": rho, "weights": weights, "setup_s": t_setup}
    if prep.placement:
        metrics["prism_placement"] = prep.placement
    first = 0
    earlier_s = 0.0  # wall time of earlier (interrupted) runs that the checkpoint carries
    resumed = ckpt.load()
    if resumed is not None:
        first = resumed["stage"]
        earlier_s = resumed["elapsed_s"]
        h = torch.as_tensor(resumed["h"], dtype=dtype)
        c = torch.as_tensor(resumed["c"], dtype=dtype)
        log = resumed["log"]
        metrics = resumed["metrics"]
        weights = resumed["weights"]
        print(f"  resuming from checkpoint after stage {first} of {len(stages)}", file=sys.stderr)
    else:
        h = torch.as_tensor(base.reshape(-1), dtype=dtype) + 0.0
        if request.color_init == "projected":
            imgs = prep.enhanced if stages[0].targets == "enhanced" else prep.render
            c = torch.as_tensor(projected_colors(rig, base, imgs), dtype=dtype)
        else:
            c = torch.full((rig.num_faces, 3), 0.5, dtype=dtype)
        # feasibility margin: the barrier is infinite on the boundary, and a
        # colour a hair from it would start with a huge barrier gradient
        c = c.clamp(0.02, 0.98)
        if project is not None:
            h = project(h)

    mu = request.barrier_weight
    h_e = h.clone()
    for si in range(first, len(stages)):
        spec: StageSpec = stages[si]
        targets = targets_for(spec.targets, spec.sigma)
        target_list = [targets[v.name] for v in rig.views]
        w = weights[spec.weight] if spec.regulariser == "deform" else 0.0
        prox = None
        if spec.regulariser == "sparse":
            h_e = h.clone()
            prox = ProxSettings(center=h_e, lam=weights["lam"])
        sigma = spec.sigma

        def objective(hh: torch.Tensor, cc: torch.Tensor, *, _w: float = w, _s: float = sigma, _t: list = target_list):
            imgs = rig.render(hh, cc, _s)
            ev = e_visual(imgs, _t)
            ed = deform(hh)
            eb = e_barrier(hh, z, cc, delta)
            total = ev + _w * ed + mu * eb
            return total, {"E_visual": float(ev.detach()), "E_deform": float(ed.detach()), "E_barrier": float(eb.detach())}

        stage_t0 = time.perf_counter()
        last = [0.0]

        def cb(it: int, total: float, parts: dict[str, float], _name: str = spec.name) -> None:
            now = time.perf_counter()
            entry = {"stage": _name, "iteration": it, **parts}
            if request.record_times:
                entry["time_s"] = now - t_start
            log.append(entry)
            if now - last[0] >= log_every_s:
                last[0] = now
                progress(_name, it, request.max_iters, parts, now - stage_t0)

        settings = SolverSettings(
            max_iters=request.max_iters,
            lr_h=delta / 20,
            energy_floor=mu * barrier_floor(rig.num_vertices, rig.num_faces, delta),
            # the sparse stage starts with vertices resting on their bounds (solver, item 4)
            boundary_rule="coordinate" if prox is not None else "global",
        )
        try:
            res = solve(objective, h, c, z, delta, settings, prox=prox, callback=cb, project=project)
        except KeyboardInterrupt:
            # Save the state this stage started from: resuming re-runs the
            # stage from there, which gives exactly the uninterrupted result.
            done_log = [e for e in log if e["stage"] != spec.name]
            ckpt.save(si, h.numpy(), c.numpy(), done_log, metrics, weights, earlier_s + stage_t0 - t_start)
            saved = (
                f"no stage had finished yet; the start of the first stage is saved in {ckpt.dir}"
                if si == 0
                else f"stage {si} of {len(stages)} ({stages[si - 1].name}) was the last to finish and is saved in {ckpt.dir}"
            )
            raise Interrupted(
                f"interrupted in stage {spec.name} ({si + 1} of {len(stages)}); {saved}. "
                "Run the same command again to resume."
            ) from None
        h, c = res.h, res.c
        if res.stop_reason == "nonfinite_gradient":
            print(
                f"  warning: stage {spec.name} ended after {res.iterations} iterations on a NaN/inf gradient "
                "(a renderer defect); the design continues from its last finite iterate. "
                "Please report it with design.json.",
                file=sys.stderr,
            )
        vis = visible_faces(rig, h.numpy().reshape(n, n))
        seen_d = vis["direct"]
        seen_r = np.zeros_like(seen_d)
        for k, v in vis.items():
            if k != "direct":
                seen_r |= v
        any_seen = (seen_d | seen_r).sum()
        with torch.no_grad():
            ev = float(e_visual(rig.render(h, c, sigma), target_list))
        metrics["stages"].append(
            {
                "name": spec.name,
                "targets": spec.targets,
                "sigma": sigma,
                "regulariser": spec.regulariser,
                "weight": w if spec.regulariser == "deform" else (weights["lam"] if prox else 0.0),
                "iterations": res.iterations,
                "evaluations": res.evaluations,
                "converged": res.converged,
                "stop_reason": res.stop_reason,
                "seconds": res.seconds,
                "seconds_per_iteration": res.seconds / max(res.iterations, 1),
                "E_visual": ev,
                "E_deform": float(deform(h)),
                "E_sparse": float((h - h_e).abs().sum()) if prox else None,
                "conflict_fraction": float((seen_d & seen_r).sum() / max(any_seen, 1)),
                "max_abs_height_change": float((h - z).abs().max()),
            }
        )
        progress(spec.name, res.iterations, request.max_iters, {**(res.log[-1] if res.log else {}), "E_total": res.energy}, res.seconds)
        ckpt.save(si + 1, h.numpy(), c.numpy(), log, metrics, weights, earlier_s + time.perf_counter() - t_start)

    # texturing with the final shape
    t0 = time.perf_counter()
    heights = h.numpy().astype(np.float64).reshape(n, n)
    tex = texture_saucer(rig, heights, prep.texture)
    metrics["texturing_s"] = time.perf_counter() - t0
    metrics["face_views"] = {
        name: int((tex.face_view == k).sum()) for k, name in enumerate(["neither", "direct", "reflected", "both"])
    }
    metrics["max_abs_height_change"] = float(np.abs(heights - base).max())
    metrics["E_deform"] = float(deform(torch.as_tensor(heights.reshape(-1), dtype=dtype)))
    if target is not None:
        metrics["printable"] = printable_metrics(target, heights, project)
    design = Design(
        scene=scene,
        heights=heights,
        base_heights=base,
        texture=tex.texture,
        face_uvs=tex.face_uvs,
        face_view=tex.face_view,
        parameters=_parameters(request, weights, rho, stages, prep.enhancement, target),
        metrics=metrics,
        inputs=prep.inputs,
        # the inputs as meant, at the texture's detail: what verify compares prints with
        references={k: np.round(np.clip(v, 0.0, 1.0) * 255.0).astype(np.uint8) for k, v in prep.texture.items()},
    )
    from saucerfab.optimize.previews import make_previews

    t0 = time.perf_counter()
    previews, final_metrics = make_previews(design, rig, prep, c.numpy(), log)
    metrics.update(final_metrics)
    metrics["previews_s"] = time.perf_counter() - t0
    # total_s: the whole design, earlier interrupted runs included (up to their checkpoint)
    metrics["total_s"] = earlier_s + time.perf_counter() - t_start
    if resumed is not None:
        metrics["this_run_s"] = time.perf_counter() - t_start
        metrics["resumed_after_stage"] = first
    if not request.record_times:
        _drop_times(metrics)
    energy_log = "\n".join(json.dumps(e) for e in log).encode() + b"\n"
    from saucerfab.report_page import REPORT_NAME, design_report

    report = design_report(design, previews).encode("utf-8")
    try:
        save_design(design, out, previews=previews, extra_files={"energy_log.jsonl": energy_log, REPORT_NAME: report})
    except OSError as exc:
        # nothing half-written is left (save_design writes a temporary folder and renames it);
        # the finished stages stay in the checkpoint, so no work is lost
        raise OutputError(
            f"cannot write the design folder {str(out)!r}: {exc.strerror or exc}"
            + (f" ({exc.filename})" if exc.filename else "")
            + f"; the optimised state is kept in {str(ckpt.dir)!r}: free space (or fix the folder) and run "
            "the same command again to finish without optimising again"
        ) from None
    ckpt.clear()
    return out


_TIME_KEYS = ("setup_s", "texturing_s", "previews_s", "total_s", "this_run_s", "seconds", "seconds_per_iteration")


def _drop_times(metrics: dict[str, Any]) -> None:
    """Remove wall-clock times (in place), so the design folder is reproducible byte for byte."""
    for key in _TIME_KEYS:
        metrics.pop(key, None)
    metrics.pop("resumed_after_stage", None)  # how the run went, not what it made: a resumed run is the same design
    for st in metrics.get("stages", []):
        for key in _TIME_KEYS:
            st.pop(key, None)


def _parameters(
    request: DesignRequest,
    weights: dict[str, float],
    rho: float,
    stages: list[StageSpec],
    enhancement: dict[str, str] | None,
    target: PrintTarget | None = None,
) -> dict[str, Any]:
    d = asdict(request)
    for k, v in list(d.items()):
        if isinstance(v, Path):
            d[k] = v.name
        elif k in ("shape", "scene") and isinstance(v, str) and Path(v).suffix.lower() in (".png", ".npy", ".toml"):
            d[k] = Path(v).name  # a file's name, not the machine's path to it
    d["weights_used"] = weights
    d["rho"] = rho
    d["stages"] = [asdict(s) for s in stages]
    d["enhancement_used"] = dict(enhancement or {})
    if target is not None:
        d["print_target"] = target.to_dict()
    if isinstance(d.get("printer"), str) and d["printer"].lower().endswith(".toml"):
        d["printer"] = Path(d["printer"]).name
    return d


def printable_metrics(target: PrintTarget, heights: np.ndarray, project: Any) -> dict[str, Any]:
    """The final heights against the printer's minimum feature (``metrics.printable`` of design.json)."""
    from saucerfab.relief import WALL_MARGIN, crest_widths, wall_widths

    dx, dy = target.spacing_mm
    hmm = np.asarray(heights) * target.mm_per_unit
    p = target.profile
    w = crest_widths(hmm, dx, dy, p.min_feature_mm)
    ww = wall_widths(hmm, dx, dy, p.min_wall_mm)
    out: dict[str, Any] = {
        "printer": p.key,
        "thin_crest_vertices": int((w < p.min_feature_mm).sum()),
        "narrowest_crest_mm": float(w.min()) if np.isfinite(w).any() else None,
        "thin_wall_crest_vertices": int((ww < WALL_MARGIN * p.min_wall_mm).sum()),
        "narrowest_crest_at_min_wall_mm": float(ww.min()) if np.isfinite(ww).any() else None,
        "crests_can_be_thin": target.crests_can_be_thin,
    }
    if project is not None:
        out.update(project.stats())
    return out
