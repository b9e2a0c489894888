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

How the full method runs (:data:`METHODS`, ``--method``): ``"paper"``, the
default, runs all three stages; ``"fast"`` runs the first and the last and
skips the small-sigma Laplacian stage, a draft mode for trying pictures: on
the bundled pairs it took 0.56-0.90x the time (0.76x over all seven) and
its verified pictures moved by -1.6 to +3.5 dB from the design eye (mean
about 0; the photographs lost up to 1.6 dB), so it is not the default
(benchmarks/RESULTS.md, "Design speed in one run"). The ablations (Figure
11) always run as the paper wrote them.

One deliberate change from the paper: the sparse stage renders with the
large sigma (:data:`SIGMA_SPARSE`), not the small one. At sigma 1e-7 a face
influences pixels only within about 0.1 px of its edges (512 x 512), so once
the Laplacian term is dropped the visual term gives no usable descent: on
the bundled samples the line searches failed within 10-16 iterations and the
moves made raised the final E_visual (7461 -> 7485-7528 over the lambdas,
prox steps and line-search lengths tried). At sigma 1e-5 the same stage (the
paper's lambda and alpha) moves 8 % of the vertices and lowers the final
E_visual by 3.7 % (``benchmarks/bench_sparse_stage.py``; benchmarks/RESULTS.md).

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

#: iteration cap per stage (``DesignRequest.max_iters``, ``SolverSettings.max_iters``)
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

#: how the full method runs (``DesignRequest.method``; the first is the default)
METHODS = ("paper", "fast")


def stages_for(ablation: str, method: str = METHODS[0]) -> list[StageSpec]:
    """The stages of ``ablation`` as ``method`` runs them (module docstring).

    Args:
        ablation: a key of :data:`ABLATION_STAGES` ("full" is the paper's method).
        method: one of :data:`METHODS`.
    Raises:
        ConfigError: an unknown method, or "fast" with an ablation other than "full" (they run as written).
    """
    if method not in METHODS:
        raise ConfigError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if method == "fast" and ablation != "full":
        raise ConfigError(
            f"--method fast shortens the full method, but --ablation {ablation} is one of the paper's Figure 11 "
            "settings, which run as written; drop --method fast, or --ablation"
        )
    stages = ABLATION_STAGES[ablation]
    if method == "fast":
        stages = [st for st in stages if not (st.regulariser == "deform" and st.sigma == SIGMA_SMALL)]
    return stages


def without_enhancement(stages: list[StageSpec]) -> list[StageSpec]:
    """The same stages against the original images (for pictures with no clear subject).

    Of the paper's method this is Figure 11 (e), Laplacian then sparse
    without enhancement, which benchmarks/RESULTS.md measures as good as or
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


def weights_used(ablation: str, method: str = METHODS[0]) -> set[str]:
    """The weight options (``w_large``, ``w_small``, ``lam``) that the stages of ``ablation`` use (:func:`stages_for`)."""
    return {spec.weight for spec in stages_for(ablation, method) if spec.weight}


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


def check_weights(ablation: str, given: Mapping[str, float | None], method: str = METHODS[0]) -> None:
    """Refuse a per-stage weight that no stage of ``ablation`` run by ``method`` uses (it would be ignored).

    Args:
        given: weight key -> the value given, None where not given.
    Raises:
        ConfigError: naming the option, the stages' weight options and what uses it.
    """
    used = weights_used(ablation, method)
    per_stage = [w for w in WEIGHTS if w.per_stage]
    for w in per_stage:
        if given.get(w.key) is None or w.key in used:
            continue
        uses = ", ".join(v.option for v in per_stage if v.key in used) or "no weight option"
        if ablation == "full" and w.key in _every_weight(ablation):
            raise ConfigError(
                f"{w.option} weighs a stage that --method {method} skips (its stages use {uses}); "
                f"drop {w.option}, or give --method paper (it runs every stage)"
            )
        takers = ", ".join(a for a in ABLATION_STAGES if w.key in _every_weight(a))
        raise ConfigError(
            f"{w.option} is not used by --ablation {ablation} (its stages use {uses}); "
            f"drop {w.option}, or choose an --ablation that uses it ({takers})"
        )
