"""The stages of Algorithm 1 and the ablation settings of Figure 11.

A stage is one DR-solver run with a fixed target set (the inputs or their
black-white enhancement), a SoftRas sigma, and a regulariser: the Laplacian
deformation energy with weight w (eq. 6/8), nothing, or the sparse spike
energy with weight lambda solved by proximal steps (eq. 10).

The paper's method ("full", Figure 11 f)::

    enhanced, sigma 1e-5, w = 0.08 rho     -> convergence
    enhanced, sigma 1e-7, w = 0.2 rho      -> convergence
    enhanced, sigma 1e-5, sparse, lambda = 6e-5 rho, centred on the previous heights

then texturing (always).

How the full method runs (:data:`METHODS`, ``--method``), each with its own
iteration cap per stage (:data:`STAGE_CAPS`; ``--max-iters`` overrides it):

- ``"auto"``, the default, skips the small-sigma Laplacian stage for
  pictures with the black-white enhancement (a clear subject) and stops
  their two stages at convergence or 120 iterations; photographs (the
  pictures as they are) run all three stages, at most 90 iterations each
  (:func:`skips_small_sigma`, :data:`STAGE_CAPS`). Over three starts each on
  the bundled pairs against the paper's stages to 400 iterations (the
  default before issue 18), skipping the stage raised the verified
  pictures of the subject pairs by 0.7 dB from the design eye on average
  but lowered the photographs' by 0.6 dB; the photographs' three stages at
  90 iterations raised theirs by 0.3 dB (benchmarks/results/HISTORY.md, "The
  default method", issue 18).
- ``"fast"`` always skips it (120 iterations a stage): the quickest.
- ``"paper"`` runs Algorithm 1's three stages as written, each to
  convergence or 400 iterations (the default before issue 18).

``"auto"`` and ``"fast"`` also end a stage that has stalled: over its last
:data:`STALL_WINDOWS` renders (accepted steps and rejected trials) the
objective fell by less than the solver's ``tol`` per render
(``SolverSettings.stall_window``). It cuts the last stage's tail of steps
found after five or six halvings each; the paper's method keeps the paper's
stopping rules alone.

The ablations (Figure 11) always run as the paper wrote them.

One deliberate change from the paper: the sparse stage renders with the
large sigma (:data:`SIGMA_SPARSE`), not the small one. At sigma 1e-7 a face
influences pixels only within about 0.1 px of its edges (512 x 512), so once
the Laplacian term is dropped the visual term gives no usable descent: on
the bundled samples the line searches failed within 10-16 iterations and the
moves made raised the final E_visual (7461 -> 7485-7528 over the lambdas,
prox steps and line-search lengths tried). At sigma 1e-5 the same stage (the
paper's lambda and alpha) moves 8 % of the vertices and lowers the final
E_visual by 3.7 % (``benchmarks/bench_sparse_stage.py``; benchmarks/results/HISTORY.md, "Design (issue 4)").

The energies a stage can use are declared in :mod:`saucerfab.optimize.energies`
(:data:`~saucerfab.optimize.energies.TERMS`); a stage names its regulariser
and the weight that scales it, and :func:`term_weight` gives every term's
weight in a stage.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

from saucerfab.errors import ConfigError
from saucerfab.optimize.energies import TERMS, WEIGHTS, Term

#: iteration cap per stage of the paper's method (``SolverSettings.max_iters``'s default)
MAX_ITERS = 400

SIGMA_LARGE = 1e-5
SIGMA_SMALL = 1e-7
#: sigma of the sparse spike stage (the paper: SIGMA_SMALL; see the module docstring)
SIGMA_SPARSE = SIGMA_LARGE


@dataclass(frozen=True)
class StageSpec:
    """One optimisation stage.

    Attributes:
        name: label in logs and design.json.
        targets: "enhanced" (eq. 7) or "original" (eq. 2).
        sigma: SoftRas sigma.
        regulariser: the name of the declared term (:data:`~saucerfab.optimize.energies.TERMS`)
            the stage optimises with E_visual ("deform", "sparse"), or "none".
        weight: the key of the term's per-stage weight that scales it
            ("w_large", "w_small", "lam"), or "" for none.
    """

    name: str
    targets: str
    sigma: float
    regulariser: str
    weight: str


def _lap(prefix: str, targets: str) -> list[StageSpec]:
    return [
        StageSpec(f"{prefix}_sigma_large", targets, SIGMA_LARGE, "deform", "w_large"),
        StageSpec(f"{prefix}_sigma_small", targets, SIGMA_SMALL, "deform", "w_small"),
    ]


#: Figure 11's six settings; "full" is the paper's method (f).
ABLATION_STAGES: dict[str, list[StageSpec]] = {
    # (a) no deformation energy: enhanced targets, heights free within delta
    "no_deform": [
        StageSpec("bw_free_sigma_large", "enhanced", SIGMA_LARGE, "none", ""),
        StageSpec("bw_free_sigma_small", "enhanced", SIGMA_SMALL, "none", ""),
    ],
    # (b) Laplacian only, original images (eq. 6)
    "laplacian": _lap("plain", "original"),
    # (c) Laplacian with black-white enhancement (eq. 8)
    "laplacian_bw": _lap("bw", "enhanced"),
    # (d) sparse only (eq. 10 from the base shape)
    "sparse_only": [StageSpec("sparse", "enhanced", SIGMA_SPARSE, "sparse", "lam")],
    # (e) sparse refinement of (b), with the original images
    "laplacian_sparse": _lap("plain", "original")
    + [StageSpec("sparse", "original", SIGMA_SPARSE, "sparse", "lam")],
    # (f) the paper's method: sparse refinement of (c)
    "full": _lap("bw", "enhanced") + [StageSpec("sparse", "enhanced", SIGMA_SPARSE, "sparse", "lam")],
}

#: how the full method runs (``DesignRequest.method``; the first is the default: see the module docstring)
METHODS = ("auto", "fast", "paper")
#: iteration cap per stage of each method: (for pictures with the black-white enhancement, for pictures used
#: as they are). ``DesignRequest.max_iters``, when given, overrides it; the ablations run as the paper wrote
#: them, with its cap. The default's two (module docstring): its two stages of enhanced pictures take 120 each,
#: its three stages of photographs 90 each (about as many iterations in all)
STAGE_CAPS: dict[str, tuple[int, int]] = {"auto": (120, 90), "fast": (120, 120), "paper": (MAX_ITERS, MAX_ITERS)}
#: renders over which a stage must lower its objective by ``tol`` relative per render, else it ends
#: (``SolverSettings.stall_window``; 0: off). The paper's method and the ablations keep the paper's rules only
STALL_WINDOWS: dict[str, int] = {"auto": 16, "fast": 16, "paper": 0}


def method_used(ablation: str, method: str = METHODS[0]) -> str:
    """The method that runs: ``method``, except that the ablations run as ``"paper"`` under ``"auto"``.

    Raises:
        ConfigError: an unknown method, or "fast" with an ablation other than "full" (they run as written).
    """
    if method not in METHODS:
        raise ConfigError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if ablation != "full" and method == "fast":
        raise ConfigError(
            f"--method fast shortens the full method, but --ablation {ablation} is one of the paper's Figure 11 "
            "settings, which run as written; drop --method fast, or --ablation"
        )
    return "paper" if ablation != "full" else method


def stage_cap(ablation: str, method: str = METHODS[0], max_iters: int | None = None, enhanced: bool = True) -> int:
    """Iterations per stage at most: ``max_iters`` when given, else the cap of the method that runs.

    Args:
        enhanced: the pictures have the black-white enhancement (:data:`STAGE_CAPS`' first cap), or are used
            as they are (its second).
    """
    if max_iters is not None:
        return max_iters
    with_enhancement, as_they_are = STAGE_CAPS[method_used(ablation, method)]
    return with_enhancement if enhanced else as_they_are


def stall_window(ablation: str, method: str = METHODS[0]) -> int:
    """The stall rule's window in renders for the method that runs (:data:`STALL_WINDOWS`; 0: off)."""
    return STALL_WINDOWS[method_used(ablation, method)]


def skips_small_sigma(ablation: str, method: str = METHODS[0], enhanced: bool = True) -> bool:
    """Whether the full method's small-sigma Laplacian stage is skipped (module docstring).

    Args:
        enhanced: the targets are the black-white enhancement (pictures with a
            clear subject), as :func:`saucerfab.optimize.prepare.choose_enhancement` decided.
    """
    used = method_used(ablation, method)
    return used == "fast" or (used == "auto" and enhanced)


def stages_for(ablation: str, method: str = METHODS[0], enhanced: bool = True) -> list[StageSpec]:
    """The stages of ``ablation`` as ``method`` runs them (module docstring).

    The names are those of the enhanced targets; :func:`without_enhancement`
    renames them for pictures used as they are.

    Args:
        ablation: a key of :data:`ABLATION_STAGES` ("full" is the paper's method).
        method: one of :data:`METHODS`.
        enhanced: the pictures have the black-white enhancement ("auto" skips the small-sigma stage then).
    Raises:
        ConfigError: an unknown method, or "fast" with an ablation other than "full" (they run as written).
    """
    stages = ABLATION_STAGES[ablation]
    if skips_small_sigma(ablation, method, enhanced):
        stages = [st for st in stages if not (st.regulariser == "deform" and st.sigma == SIGMA_SMALL)]
    return stages


def without_enhancement(stages: list[StageSpec]) -> list[StageSpec]:
    """The same stages against the original images (for pictures with no clear subject).

    Of the paper's method this is Figure 11 (e), Laplacian then sparse
    without enhancement, which benchmarks/results/HISTORY.md ("Design (issue 4)") measures as good as or
    better than the full method on 2 of 3 bundled pairs.
    """
    return [
        replace(st, targets="original", name=st.name.replace("bw_", "plain_", 1)) if st.targets == "enhanced" else st
        for st in stages
    ]


#: rho multipliers of the per-stage weights (section 3.5), from their declarations
WEIGHT_FACTORS: dict[str, float] = {w.key: w.rho_factor for w in WEIGHTS if w.rho_factor is not None}


def _check_table() -> None:
    """Every stage names a declared term and one of that term's per-stage weights (a developer's slip)."""
    for ablation, stages in ABLATION_STAGES.items():
        for st in stages:
            allowed = {"none": {""}, **{t.name: {w.key for w in t.weights if w.per_stage} for t in TERMS}}
            if st.weight not in allowed.get(st.regulariser, ()):
                raise ValueError(f"stage {st.name} of {ablation}: regulariser {st.regulariser!r} with weight "
                                 f"{st.weight!r}; declared: {allowed}")


_check_table()


def weights_used(ablation: str, method: str = METHODS[0], enhanced: bool | None = None) -> set[str]:
    """The weight options (``w_large``, ``w_small``, ``lam``) that the stages of ``ablation`` use (:func:`stages_for`).

    Args:
        enhanced: whether the pictures have the black-white enhancement; None
            (not known yet, before the pictures are read): those of either.
    """
    cases = (True, False) if enhanced is None else (enhanced,)
    return {spec.weight for e in cases for spec in stages_for(ablation, method, e) if spec.weight}


def term_weight(spec: StageSpec, term: Term, values: Mapping[str, float]) -> float:
    """The weight of ``term`` in stage ``spec``.

    The stage's weight when the stage uses the term; else the term's fixed
    weight (the barrier's, in every stage); else 0 (a smooth term is still
    evaluated and logged, so every stage's log has the same columns).

    Args:
        values: weight key -> value, for the per-stage weights and the fixed ones.
    """
    if spec.regulariser == term.name:
        return values[spec.weight]
    fixed = [w for w in term.weights if not w.per_stage]
    return values[fixed[0].key] if fixed else 0.0


def _every_weight(ablation: str) -> set[str]:
    """The weight options of every stage of ``ablation`` as the paper wrote it."""
    return {spec.weight for spec in ABLATION_STAGES[ablation] if spec.weight}


def check_weights(
    ablation: str, given: Mapping[str, float | None], method: str = METHODS[0], enhanced: bool | None = None
) -> None:
    """Refuse a per-stage weight that no stage of ``ablation`` run by ``method`` uses (it would be ignored).

    Args:
        given: weight key -> the value given, None where not given.
        enhanced: as :func:`weights_used`: None before the pictures are read
            (a weight is refused only when no pictures could use it), then
            whether they have the black-white enhancement.
    Raises:
        ConfigError: naming the option, the stages' weight options and what uses it.
    """
    used = weights_used(ablation, method, enhanced)
    per_stage = [w for w in WEIGHTS if w.per_stage]
    for w in per_stage:
        if given.get(w.key) is None or w.key in used:
            continue
        uses = ", ".join(v.option for v in per_stage if v.key in used) or "no weight option"
        if ablation == "full" and w.key in _every_weight(ablation):
            used_by = (f"--method {method}" if method != "auto" else
                       "the default method (auto), for pictures with a clear subject (these have one),")
            raise ConfigError(
                f"{w.option} weighs a stage that {used_by} skips (its stages use {uses}); "
                f"drop {w.option}, or give --method paper (it runs every stage)"
            )
        takers = ", ".join(a for a in ABLATION_STAGES if w.key in _every_weight(a))
        raise ConfigError(
            f"{w.option} is not used by --ablation {ablation} (its stages use {uses}); "
            f"drop {w.option}, or choose an --ablation that uses it ({takers})"
        )
