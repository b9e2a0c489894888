"""``optimize_design``: from a :class:`DesignRequest` to a design folder (Algorithm 1).

1. :func:`saucerfab.optimize.prepare.prepare`: every input is read and
   validated before any work (scene, shape, images, masks), so bad input
   stops at once with a clear message.
2. the stages of :mod:`saucerfab.optimize.stages` (the paper's method or an
   ablation), each a DR-solver run against blur-matched targets on the
   objective its declared terms make (:data:`saucerfab.optimize.energies.TERMS`),
   with the weights set from the compatibility score rho unless the user gives them;
3. texturing with the final shape (section 3.4.2);
4. metrics, previews and the design folder, written atomically, with the
   pages the caller asks for (``pages``: the workflow's
   :func:`saucerfab.workflow.run_design` adds the design's ``report.html``;
   the optimizer itself draws no page).

Looks (:mod:`saucerfab.optimize.looks`): a first look right after step 1,
before torch is imported, and a refined one after every stage, written
into the checkpoint folder and handed to the ``look`` callback.

Checkpoints: after every stage, and on Ctrl-C, the iterate is saved in a
sibling folder ``.<out name>.checkpoint``; running the same request again
resumes from it (the request's hash must match). A finished run removes it.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from saucerfab.errors import Interrupted, OutputError
from saucerfab.model.design import Design, FaceView
from saucerfab.model.design_folder import load_design, save_design
from saucerfab.optimize.checkpoint import Checkpoint, check_output_folder, request_hash
from saucerfab.optimize.diagnose import check_base_shape, conflict_share
from saucerfab.optimize.energies import WEIGHTS
from saucerfab.optimize.looks import Look, Looks
from saucerfab.optimize.prepare import Prepared, prepare
from saucerfab.optimize.printable import PrintTarget
from saucerfab.optimize.request import DesignRequest
from saucerfab.optimize.stages import (
    SIGMA_LARGE,
    WEIGHT_FACTORS,
    StageSpec,
    check_weights,
    method_used,
    stages_for,
    term_weight,
    without_enhancement,
)

if TYPE_CHECKING:
    import torch

    from saucerfab.optimize.solver import Objective
    from saucerfab.optimize.viewpoints import EyeRig
    from saucerfab.optimize.views import Rig

#: progress(stage, iteration, max_iterations, parts, elapsed_s)
Progress = Callable[[str, int, int, dict[str, float], float], None]


class _StageInterrupted(Exception):
    """Ctrl-C in a stage's solver run; the iterate the stage started from is intact."""


def _is_interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` is a Ctrl-C (SIGINT), as raised or as an extension turned it into its own error.

    Python runs the SIGINT handler between bytecodes; when that is just as a
    numba kernel returns, CPython reports ``SystemError: ... returned a result
    with an exception set`` with the KeyboardInterrupt as its cause (seen in the
    studio's shutdown test under load: the checkpoint was then not saved).
    """
    seen = 0
    cur: BaseException | None = exc
    while cur is not None and seen < 8:
        if isinstance(cur, KeyboardInterrupt):
            return True
        cur, seen = cur.__cause__ or cur.__context__, seen + 1
    return False


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


#: ``pages(design, previews)``: more files of the design folder made from the finished design and its
#: previews (PNG bytes by name), by relative name -> bytes (the workflow's report page)
Pages = Callable[[Design, dict[str, bytes]], dict[str, bytes]]


def optimize_design(
    request: DesignRequest,
    out: str | Path,
    *,
    progress: Progress | None = None,
    log_every_s: float = 2.0,
    look: Look | None = None,
    pages: Pages | None = None,
) -> Design:
    """Run the whole method and write the design folder ``out`` atomically; return the design.

    Args:
        request: what to design.
        out: the design folder to write (replaced atomically if it exists).
        progress: called with (stage, iteration, max, energies, elapsed) about
            every ``log_every_s`` seconds; default prints a line to stderr.
        look: called as ``look(stage, files, elapsed_s)`` after each look is
            written (:mod:`saucerfab.optimize.looks`): ``"first_look"`` (the base
            shape with projected colours, before any optimisation), then each
            stage's name; ``files`` maps each view and ``"composite"`` to its PNG
            in the checkpoint folder's ``previews/``; ``elapsed_s`` counts from
            the call of optimize_design. An exception it raises is reported and ignored.
        pages: files made from the finished design, written with the folder (atomically, with it).

    Returns:
        the design as written, read back from ``out`` (its ``folder``).

    Raises:
        SaucerfabError: bad inputs (before any work), Interrupted on Ctrl-C
        (after saving a checkpoint).
    """
    out = Path(out)
    t_start = time.perf_counter()
    check_output_folder(out)
    prep = prepare(request)
    enhanced = _enhanced(prep.enhancement)
    # a weight of a stage these pictures skip would be ignored: refused now, before any stage
    check_weights(request.ablation, {w.key: getattr(request, w.key) for w in WEIGHTS}, request.method, enhanced)
    stages = stages_for(request.ablation, request.method, enhanced)
    if not enhanced:
        stages = without_enhancement(stages)
    ckpt = Checkpoint(out, request_hash(request, prep))
    for note in prep.print_notes:
        print(f"  note: {note}", file=sys.stderr)
    # the first look, before torch is imported, rho and any stage: what the saucer shows before optimisation
    looks = Looks(ckpt.dir / "previews", look, t_start)
    looks.first(prep)

    import torch

    from saucerfab.optimize.viewpoints import eye_rigs
    from saucerfab.optimize.views import Rig

    torch.manual_seed(request.seed)
    rig = Rig(prep.scene, prep.base, reflected_groups=prep.reflected_groups)
    shape_check = check_base_shape(prep, rig, request.shape, request.seed)  # a note now if the shape defeats the method
    # --eyes: one rig per eye, each with its own reflection (the design eye's is ``rig``)
    spec = request.eye_spec()
    eyes = [] if spec.mode == "design" else eye_rigs(prep.scene, prep.base, spec, prep.reflected_groups,
                                                     rig_class=Rig, design_rig=rig)
    loop = _StageLoop(request, prep, rig, stages, progress or _print_progress, log_every_s, t_start, eyes)

    first = 0
    earlier_s = 0.0  # wall time of earlier (interrupted) runs that the checkpoint carries
    resumed = ckpt.load()
    if resumed is not None:
        first, earlier_s = resumed["stage"], resumed["elapsed_s"]
        h = torch.as_tensor(resumed["h"], dtype=loop.dtype)
        c = torch.as_tensor(resumed["c"], dtype=loop.dtype)
        loop.log, loop.metrics, loop.weights = resumed["log"], resumed["metrics"], resumed["weights"]
        print(f"  resuming from checkpoint after stage {first} of {len(stages)}", file=sys.stderr)
    else:
        h, c = loop.start()
    for si in range(first, len(stages)):
        try:
            h, c = loop.run_stage(si, h, c)
        except _StageInterrupted:
            # Save the state this stage started from: resuming re-runs the
            # stage from there, which gives exactly the uninterrupted result.
            done_log = [e for e in loop.log if e["stage"] != stages[si].name]
            ckpt.save(si, h.numpy(), c.numpy(), done_log, loop.metrics, loop.weights,
                      earlier_s + loop.stage_t0 - t_start)
            saved = (
                f"no stage had finished yet; the start of the first stage is saved in {ckpt.dir}"
                if si == 0
                else f"stage {si} of {len(stages)} ({stages[si - 1].name}) was the last to finish and is saved in {ckpt.dir}"
            )
            raise Interrupted(
                f"interrupted in stage {stages[si].name} ({si + 1} of {len(stages)}); {saved}. "
                "Run the same command again to resume."
            ) from None
        ckpt.save(si + 1, h.numpy(), c.numpy(), loop.log, loop.metrics, loop.weights,
                  earlier_s + time.perf_counter() - t_start)
        looks.show(stages[si].name, prep, rig, h.numpy().reshape(rig.n, rig.n))  # the refined look

    design, previews, energy_log = loop.finish(h, c)
    metrics = loop.metrics
    metrics["base_shape"] = shape_check.conclude(metrics["face_views"])  # with the hint where it is the cause
    # total_s: the whole design, earlier interrupted runs included (up to their checkpoint)
    metrics["total_s"] = earlier_s + time.perf_counter() - t_start
    if resumed is not None:
        metrics["this_run_s"] = time.perf_counter() - t_start
        metrics["resumed_after_stage"] = first
    if not request.record_times:
        _drop_times(metrics)
    extra = pages(design, previews) if pages is not None else {}
    _write(design, previews, {"energy_log.jsonl": energy_log, **extra}, out, ckpt)
    ckpt.clear()
    # read back, so what the caller gets is what every later reader gets (float32 UVs, the PNGs' bytes)
    return load_design(out)


def _write(design: Design, previews: dict[str, bytes], extra: dict[str, bytes], out: Path,
           ckpt: Checkpoint) -> None:
    """Write the design folder with its previews and ``extra`` files (the energy log, pages), atomically."""
    try:
        save_design(design, out, previews=previews, extra_files=extra)
    except OSError as exc:
        # nothing half-written is left (save_design writes a temporary folder and renames it);
        # the finished stages stay in the checkpoint, so no work is lost
        raise OutputError(
            f"cannot write the design folder {str(out)!r}: {exc.strerror or exc}"
            + (f" ({exc.filename})" if exc.filename else "")
            + f"; the optimised state is kept in {str(ckpt.dir)!r}: free space (or fix the folder) and run "
            "the same command again to finish without optimising again"
        ) from None


class _StageLoop:
    """The stages of one run: targets, weights, each stage's objective from the declared terms, log and metrics.

    Attributes:
        log: one entry per accepted iteration (the energy log).
        metrics: design.json's metrics so far (``stages`` grows by one per stage).
        weights: the per-stage weights by key (given, or from rho: section 3.5).
        stage_t0: when the current stage started (``time.perf_counter``).
    """

    def __init__(
        self,
        request: DesignRequest,
        prep: Prepared,
        rig: Rig,
        stages: list[StageSpec],
        progress: Progress,
        log_every_s: float,
        t_start: float,
        eyes: list[EyeRig] | None = None,
    ) -> None:
        import torch

        from saucerfab.optimize.energies import TERMS, Problem
        from saucerfab.optimize.printable import CrestProjection
        from saucerfab.optimize.surround import Surround
        from saucerfab.optimize.targets import compatibility
        from saucerfab.optimize.viewpoints import decal_height

        self.request, self.prep, self.rig, self.stages = request, prep, rig, stages
        self.cap = request.stage_cap(_enhanced(prep.enhancement))  # iterations per stage at most
        self.stall_window = request.stall_window()  # renders without progress that end a stage
        #: the eyes of --eyes (the design eye first), or [] for the design eye alone (the paper)
        self.eyes = list(eyes or [])
        self.z0 = decal_height(prep.base)
        self._eye_targets: dict[tuple[str, float], list[list[Any]]] = {}
        self.progress, self.log_every_s, self.t_start = progress, log_every_s, t_start
        self.dtype = torch.float32
        scene = prep.scene
        self.z = torch.as_tensor(prep.base.reshape(-1), dtype=self.dtype)
        self.problem = Problem(self.z, scene.saucer.delta, scene.saucer.resolution, rig.num_faces)
        #: every declared term with its energy for this run, in the energy log's order
        self.energies = [(t, t.make(self.problem)) for t in TERMS]
        # the printer's minimum feature and wall, kept on every iterate (saucerfab.model.relief)
        self.project = CrestProjection(prep.target, scene, prep.base) if prep.target is not None else None
        self._targets: dict[tuple[str, float], dict[str, Any]] = {}
        #: the whole view around the frames (saucerfab.optimize.surround); None with surround_weight 0
        self.surround = Surround(rig, prep, prep.ground) if request.surround() > 0 else None
        #: per view, the pixels of its picture's rectangle (None: the whole square), what E_visual scores
        self.masks = rig.picture_masks()
        self.stage_t0 = time.perf_counter()

        # weights from rho (section 3.5) unless given
        t0 = time.perf_counter()
        given = {k: getattr(request, k) for k in WEIGHT_FACTORS}
        if all(v is not None for v in given.values()):
            rho = float("nan")
            self.weights = {k: float(v) for k, v in given.items()}
        else:
            kind = stages[0].targets  # rho of the images the first stage aims at
            rho = compatibility(rig, prep.base, self._images(kind), self.targets_for(kind, SIGMA_LARGE), SIGMA_LARGE,
                                dtype=self.dtype)
            self.weights = {k: (float(v) if v is not None else WEIGHT_FACTORS[k] * rho) for k, v in given.items()}
        self.rho = rho
        self.log: list[dict[str, Any]] = []
        self.metrics: dict[str, Any] = {
            "stages": [], "rho": rho, "weights": self.weights, "setup_s": time.perf_counter() - t0,
        }
        if prep.placement:
            self.metrics["prism_placement"] = prep.placement

    def _images(self, kind: str) -> dict[str, np.ndarray]:
        """The pictures a stage aims at: the enhanced targets or the fitted inputs."""
        return self.prep.enhanced if kind == "enhanced" else self.prep.render

    def targets_for(self, kind: str, sigma: float) -> dict[str, Any]:
        """Blur-matched targets (view name -> (S, S, 3) tensor), made once per (kind, sigma)."""
        from saucerfab.optimize.targets import blur_matched_targets

        key = (kind, sigma)
        if key not in self._targets:
            self._targets[key] = blur_matched_targets(self.rig, self.prep.base, self._images(kind), sigma,
                                                      dtype=self.dtype)
        return self._targets[key]

    def eye_targets_for(self, kind: str, sigma: float) -> list[list[Any]]:
        """Per eye after the design eye, its blur-matched targets in its views' order: each view's
        picture as that eye should see it (:func:`saucerfab.optimize.viewpoints.decal_images`)."""
        from saucerfab.optimize.targets import blur_matched_targets
        from saucerfab.optimize.viewpoints import decal_images

        key = (kind, sigma)
        if key not in self._eye_targets:
            out = []
            for eye in self.eyes[1:]:
                pics = decal_images(self.prep.scene, eye, self.prep.base, self._images(kind), self.z0)
                t = blur_matched_targets(eye.rig, self.prep.base, pics, sigma, dtype=self.dtype)
                out.append([t[v.name] for v in eye.rig.views])
            self._eye_targets[key] = out
        return self._eye_targets[key]

    def e_visual_eyes(self, spec: StageSpec, design_part: torch.Tensor, hh: torch.Tensor,
                      cc: torch.Tensor) -> torch.Tensor:
        """E_visual over the eyes: the design eye's ``design_part`` and each other eye's, weighted
        (:func:`saucerfab.model.eyes.eye_weights`) and scaled to the design eye's pixels
        (:attr:`~saucerfab.optimize.viewpoints.EyeRig.area_factor`), added in eye order."""
        from saucerfab.optimize.energies import e_visual

        total = self.eyes[0].weight * design_part
        for eye, targets in zip(self.eyes[1:], self.eye_targets_for(spec.targets, spec.sigma), strict=True):
            total = total + (eye.weight * eye.area_factor) * e_visual(eye.rig.render(hh, cc, spec.sigma), targets)
        return total

    def start(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The starting iterate: the base heights and grey (or projected) colours, strictly feasible."""
        import torch

        from saucerfab.optimize.targets import projected_colors

        h = self.z + 0.0
        if self.request.color_init == "projected":
            imgs = self._images(self.stages[0].targets)
            c = torch.as_tensor(projected_colors(self.rig, self.prep.base, imgs), dtype=self.dtype)
        else:
            c = torch.full((self.rig.num_faces, 3), 0.5, dtype=self.dtype)
        # feasibility margin: the barrier is infinite on the boundary, and a
        # colour a hair from it would start with a huge barrier gradient
        c = c.clamp(0.02, 0.98)
        if self.project is not None:
            h = self.project(h)
        return h, c

    def weight_values(self) -> dict[str, float]:
        """Every declared weight's value: the per-stage ones (:attr:`weights`) and the fixed ones (the request's)."""
        fixed = {w.key: getattr(self.request, w.key) for w in WEIGHTS if not w.per_stage}
        return {**self.weights, **fixed}

    def objective(self, spec: StageSpec, targets: list[torch.Tensor]) -> Objective:
        """``E = E_visual + sum_k w_k E_k`` over the smooth terms, with the stage's weights.

        Every smooth term is evaluated and logged (weight 0 where the stage
        does not use it); the terms are evaluated first and added in
        :data:`~saucerfab.optimize.energies.TERMS` order, so the sum and its
        gradient are the same float operations in the same order every run.
        """
        from saucerfab.optimize.energies import e_visual

        values = self.weight_values()
        smooth = [(t.key, fn, term_weight(spec, t, values)) for t, fn in self.energies if t.prox is None]
        rig, sigma = self.rig, spec.sigma

        multi = bool(self.eyes)
        masks = self.masks
        if multi:
            self.eye_targets_for(spec.targets, sigma)  # made once, before the solver's clock
        w_surround, surround = self.request.surround(), self.surround
        if surround is not None:
            surround.targets_for(spec.targets, sigma)  # made once, before the solver's clock

        def objective(hh: torch.Tensor, cc: torch.Tensor) -> tuple[torch.Tensor, dict[str, float]]:
            ev = e_visual(rig.render(hh, cc, sigma), targets, masks)
            if multi:  # --eyes: the weighted sum over the eyes (the design eye alone: the paper's, untouched)
                ev = self.e_visual_eyes(spec, ev, hh, cc)
            terms = [(key, w, fn(hh, cc)) for key, fn, w in smooth]
            total = ev
            around = {}
            if surround is not None:  # the saucer around the frames, seen directly and in the cup
                es = surround.energy(hh, cc, spec.targets, sigma)
                total = total + w_surround * es
                around = {"E_surround": float(es.detach())}
            for _, w, e in terms:
                total = total + w * e
            return total, {"E_visual": float(ev.detach()), **around,
                           **{key: float(e.detach()) for key, _, e in terms}}

        return objective

    def run_stage(self, si: int, h: torch.Tensor, c: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Run stage ``si`` from (h, c); log it, add its metrics, return the new iterate."""
        import torch

        from saucerfab.optimize.energies import e_visual
        from saucerfab.optimize.solver import ProxSettings, SolverSettings, solve
        from saucerfab.optimize.texturing import classify_faces
        from saucerfab.optimize.views import visible_faces

        spec, request, rig = self.stages[si], self.request, self.rig
        targets = self.targets_for(spec.targets, spec.sigma)
        target_list = [targets[v.name] for v in rig.views]
        values = self.weight_values()
        h_e = h.clone()  # the heights the stage starts from: a proximal term's centre
        prox = None
        for t, fn in self.energies:
            if t.prox is not None and spec.regulariser == t.name:
                prox = ProxSettings(center=h_e, lam=values[spec.weight], name=t.key, value=fn, operator=t.prox)
        self.stage_t0 = stage_t0 = time.perf_counter()
        last = [0.0]

        def cb(it: int, total: float, parts: dict[str, float]) -> None:
            now = time.perf_counter()
            entry = {"stage": spec.name, "iteration": it, **parts}
            if request.record_times:
                entry["time_s"] = now - self.t_start
            self.log.append(entry)
            if now - last[0] >= self.log_every_s:
                last[0] = now
                self.progress(spec.name, it, self.cap, parts, now - stage_t0)

        delta = self.problem.delta
        settings = SolverSettings(
            max_iters=self.cap,
            lr_h=delta / 20,
            # the weighted floors of the terms (the barrier's): see SolverSettings.energy_floor
            energy_floor=sum(term_weight(spec, t, values) * t.floor(self.problem) for t, _ in self.energies if t.floor),
            # the sparse stage starts with vertices resting on their bounds (solver, item 4)
            boundary_rule="coordinate" if prox is not None else "global",
            stall_window=self.stall_window,
        )
        try:
            res = solve(self.objective(spec, target_list), h, c, self.z, delta, settings, prox=prox, callback=cb,
                        project=self.project)
        except BaseException as exc:
            if _is_interrupt(exc):
                raise _StageInterrupted from None
            raise
        h, c = res.h, res.c
        if res.stop_reason == "nonfinite_gradient":
            print(
                f"  warning: stage {spec.name} ended after {res.iterations} iterations on a NaN/inf gradient "
                "(a renderer defect); the design continues from its last finite iterate. "
                "Please report it with design.json.",
                file=sys.stderr,
            )
        face_view = classify_faces(visible_faces(rig, h.numpy().reshape(rig.n, rig.n)))
        with torch.no_grad():
            ev_t = e_visual(rig.render(h, c, spec.sigma), target_list, self.masks)
            ev = float(ev_t)
            more_parts = {"E_visual_eyes": float(self.e_visual_eyes(spec, ev_t, h, c))} if self.eyes else {}
            if self.surround is not None:
                more_parts["E_surround"] = float(self.surround.energy(h, c, spec.targets, spec.sigma))
        reported: dict[str, float | None] = {}
        for t, fn in self.energies:
            if t.in_metrics and t.prox is None:
                reported[t.key] = float(fn(h, c))
            elif t.in_metrics:
                reported[t.key] = float(fn(h, h_e)) if prox is not None and prox.name == t.key else None
        self.metrics["stages"].append(
            {
                "name": spec.name,
                "targets": spec.targets,
                "sigma": spec.sigma,
                "regulariser": spec.regulariser,
                "weight": values[spec.weight] if spec.weight else 0.0,
                "iterations": res.iterations,
                "evaluations": res.evaluations,
                "converged": res.converged,
                "stop_reason": res.stop_reason,
                "seconds": res.seconds,
                "seconds_per_iteration": res.seconds / max(res.iterations, 1),
                "E_visual": ev,
                **more_parts,
                **reported,
                "conflict_fraction": conflict_share(face_view),
                "max_abs_height_change": float((h - self.z).abs().max()),
            }
        )
        self.progress(spec.name, res.iterations, self.cap,
                      {**(res.log[-1] if res.log else {}), "E_total": res.energy}, res.seconds)
        return h, c

    def finish(self, h: torch.Tensor, c: torch.Tensor) -> tuple[Design, dict[str, bytes], bytes]:
        """Texture the final shape; the design, its previews and the energy log (as bytes); metrics completed."""
        import torch

        from saucerfab.optimize.previews import make_previews
        from saucerfab.optimize.texturing import texture_saucer

        prep, rig, metrics, request = self.prep, self.rig, self.metrics, self.request
        t0 = time.perf_counter()
        heights = h.numpy().astype(np.float64).reshape(rig.n, rig.n)
        surround = self.surround.texture_colours(heights) if self.surround is not None else None
        if self.eyes:
            from saucerfab.optimize.texturing import EyeViews
            from saucerfab.optimize.viewpoints import design_frame_ndc

            others = [
                EyeViews(e.weight, e.rig, {v.name: design_frame_ndc(prep.scene, e.scene, v, heights, self.z0)
                                           for v in e.rig.views})
                for e in self.eyes[1:]
            ]
            tex = texture_saucer(rig, heights, prep.texture, eyes=others, design_weight=self.eyes[0].weight,
                                 surround=surround)
        else:
            tex = texture_saucer(rig, heights, prep.texture, surround=surround)
        metrics["texturing_s"] = time.perf_counter() - t0
        metrics["face_views"] = {fv.name.lower(): int((tex.face_view == fv).sum()) for fv in FaceView}
        metrics["max_abs_height_change"] = float(np.abs(heights - prep.base).max())
        h_final = torch.as_tensor(heights.reshape(-1), dtype=self.dtype)
        for t, fn in self.energies:
            if t.in_metrics and t.prox is None:
                metrics[t.key] = float(fn(h_final, c))
        if prep.target is not None:
            from saucerfab.optimize.printable import printable_metrics

            metrics["printable"] = printable_metrics(prep.target, heights, self.project)
        design = Design(
            scene=prep.scene,
            heights=heights,
            base_heights=prep.base,
            texture=tex.texture,
            face_uvs=tex.face_uvs,
            face_view=tex.face_view,
            parameters=_parameters(request, self.weights, self.rho, self.stages, prep.enhancement, prep.target,
                                   self.eyes, prep.ground),
            metrics=metrics,
            inputs=prep.inputs,
            # the inputs as meant, at the texture's detail: what verify compares prints with
            references={k: np.round(np.clip(v, 0.0, 1.0) * 255.0).astype(np.uint8) for k, v in prep.texture.items()},
        )
        t0 = time.perf_counter()
        previews, final_metrics = make_previews(design, rig, prep, c.numpy(), self.log)
        metrics.update(final_metrics)
        metrics["previews_s"] = time.perf_counter() - t0
        energy_log = "\n".join(json.dumps(e) for e in self.log).encode() + b"\n"
        return design, previews, energy_log


_TIME_KEYS = ("setup_s", "texturing_s", "previews_s", "total_s", "this_run_s", "seconds", "seconds_per_iteration")


def _drop_times(metrics: dict[str, Any]) -> None:
    """Remove wall-clock times (in place), so the design folder is reproducible byte for byte."""
    for key in _TIME_KEYS:
        metrics.pop(key, None)
    metrics.pop("resumed_after_stage", None)  # how the run went, not what it made: a resumed run is the same design
    for st in metrics.get("stages", []):
        for key in _TIME_KEYS:
            st.pop(key, None)


def _enhanced(enhancement: dict[str, str] | None) -> bool:
    """Whether the stages aim at the black-white enhancement (False: the pictures as they are, photographs).

    Args:
        enhancement: the conflict reduction prepare chose (``Prepared.enhancement``), None for none chosen.
    """
    return not (enhancement and enhancement["strategy"] == "none")


def _parameters(
    request: DesignRequest,
    weights: dict[str, float],
    rho: float,
    stages: list[StageSpec],
    enhancement: dict[str, str] | None,
    target: PrintTarget | None = None,
    eyes: list[EyeRig] | None = None,
    ground: str | None = None,
) -> dict[str, Any]:
    d = asdict(request)
    if request.background is None and ground is not None:
        # the one ground chosen for pictures whose border colours differ: export's walls and plate and
        # verify's whole view read it (saucerfab.imaging.images.recorded_background)
        d["ground"] = ground
    if eyes:
        # the eyes the design was made for: mm from the design eye along the direct view's right and up
        d["ipd_mm"] = request.eye_spec().ipd_mm if request.eye_spec().mode == "both" else None
        d["eyes_used"] = [
            {"name": e.eye.name, "offset_mm": list(e.eye.offset_mm), "weight": e.weight} for e in eyes
        ]
    else:
        # the design eye alone (the paper): the folder as before --eyes existed, byte for byte
        d.pop("eyes", None)
        d.pop("ipd_mm", None)
    if d.get("saucer_diameter_mm") is None:  # a rectangle's (or the round preset's own) folder as before the option
        d.pop("saucer_diameter_mm", None)
    for k, v in list(d.items()):
        if isinstance(v, Path):
            d[k] = v.name
        elif k in ("shape", "scene") and isinstance(v, str) and Path(v).suffix.lower() in (".png", ".npy", ".toml"):
            d[k] = Path(v).name  # a file's name, not the machine's path to it
    d["weights_used"] = weights
    d["rho"] = rho
    d["method_used"] = method_used(request.ablation, request.method)
    d["max_iters_used"] = request.stage_cap(_enhanced(enhancement))
    d["stall_window_used"] = request.stall_window()
    d["stages"] = [asdict(s) for s in stages]
    d["enhancement_used"] = dict(enhancement or {})
    if target is not None:
        d["print_target"] = target.to_dict()
    if isinstance(d.get("printer"), str) and d["printer"].lower().endswith(".toml"):
        d["printer"] = Path(d["printer"]).name
    return d
