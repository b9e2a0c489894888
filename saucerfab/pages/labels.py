"""People's words for the optimizer's internal names: stages, energy terms, stop reasons, the method.

The optimizer names its stages (:data:`saucerfab.optimize.stages.ABLATION_STAGES`,
``bw_sigma_large``...) and its energies (:data:`saucerfab.optimize.energies.TERMS`,
``E_deform``...) for logs and design.json; those keys stay as they are. The
design and print reports (:mod:`saucerfab.pages.folder_pages`) and the studio's page
(through ``GET /api/options``' ``labels``, :func:`api_labels`) show these
labels instead, so a person never reads ``bw sigma large`` or
``E barrier 3.697e+5``. A stage or term added to the optimizer needs its
label here: ``tests/pages/test_labels.py`` fails until it has one.

Importing this module does not import torch.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from saucerfab.optimize.stages import METHODS, SIGMA_LARGE, SIGMA_SMALL, SIGMA_SPARSE


def sigma_text(sigma: float) -> str:
    """A SoftRas sigma as people read it: ``σ 1e-5`` (Python's ``:g`` would write ``1e-05``)."""
    mantissa, exponent = f"{sigma:e}".split("e")
    return f"σ {float(mantissa):g}e{int(exponent)}"


_COARSE = f"coarse ({sigma_text(SIGMA_LARGE)})"
_FINE = f"fine ({sigma_text(SIGMA_SMALL)})"

#: a stage's targets (``StageSpec.targets``) -> what it aims at
TARGET_LABELS: dict[str, str] = {"enhanced": "the black-and-white pictures", "original": "the pictures as they are"}
_BW = f"towards {TARGET_LABELS['enhanced']}"
_AS_IS = f"towards {TARGET_LABELS['original']}"

#: stage name (``StageSpec.name``, design.json's ``metrics.stages[].name``) -> label. The paper's
#: stages (section 3.5): Laplacian-regularised shaping at the large, then the small SoftRas sigma
#: (the large one sees broad shapes, the small one sharp edges), then sparse spikes (eq. 10)
STAGE_LABELS: dict[str, str] = {
    "bw_sigma_large": f"Smooth shaping, {_COARSE}, {_BW}",
    "bw_sigma_small": f"Smooth shaping, {_FINE}, {_BW}",
    "plain_sigma_large": f"Smooth shaping, {_COARSE}, {_AS_IS}",
    "plain_sigma_small": f"Smooth shaping, {_FINE}, {_AS_IS}",
    "bw_free_sigma_large": f"Free shaping (no smoothness term), {_COARSE}, {_BW}",
    "bw_free_sigma_small": f"Free shaping (no smoothness term), {_FINE}, {_BW}",
    "plain_free_sigma_large": f"Free shaping (no smoothness term), {_COARSE}, {_AS_IS}",
    "plain_free_sigma_small": f"Free shaping (no smoothness term), {_FINE}, {_AS_IS}",
    "sparse": f"Sparse spikes (a few points move further), {sigma_text(SIGMA_SPARSE)}",
}

#: energy key (``Term.key``, the energy log's and the metrics' names) -> label
ENERGY_LABELS: dict[str, str] = {
    "E_visual": "image error",  # squared colour difference to the targets, summed over the views (eq. 2/7)
    "E_visual_eyes": "image error over the eyes",
    # the whole view's squared colour difference outside the frames (saucerfab.optimize.surround)
    "E_surround": "image error around the pictures",
    "E_deform": "shape change",  # how far the relief's Laplacian moved from the base shape's (eq. 3)
    "E_sparse": "heights moved",  # sum |h - h_start| of the sparse stage (eq. 9)
    "E_barrier": "bound barrier (keeps heights within the relief bound)",  # eq. 4-5
    "E_total": "objective (weighted sum)",
}
#: energies whose values mean nothing to a person, so pages do not show them: the barrier is a sum of
#: logarithms (its size says only how many vertices there are), and the total includes it
HIDDEN_ENERGIES: frozenset[str] = frozenset({"E_barrier", "E_total"})

#: why a stage ended (``StageResult.stop_reason`` of :mod:`saucerfab.optimize.solver`) -> label
STOP_LABELS: dict[str, str] = {
    "max_iters": "iteration cap",
    "tolerance": "converged",
    "no_descent": "converged (no step lowers it)",
    "stalled": "stalled (too little gain)",
    "stopped": "stopped",
    "nonfinite_gradient": "numerical fault",
}


def _fallback(key: str) -> str:
    """A key with no label (a design from a newer or older saucerfab): its words, underscores as spaces."""
    return str(key).replace("_", " ")


def stage_label(name: str) -> str:
    """The label of stage ``name``."""
    return STAGE_LABELS.get(name) or _fallback(name)


def energy_label(key: str) -> str:
    """The label of energy ``key`` (``E_deform``...)."""
    return ENERGY_LABELS.get(key) or _fallback(key.removeprefix("E_"))


def stop_label(reason: str) -> str:
    """The label of a stage's stop reason."""
    return STOP_LABELS.get(reason) or _fallback(reason)


def design_name(inputs: Mapping[str, Any]) -> str:
    """A design's name for titles: its input pictures' file names (``a.png / b.png``), or ``synthetic``.

    Args:
        inputs: design.json's ``inputs`` (also export.json's ``design.inputs``).
    """
    names = [str(inputs[k].get("file")) for k in ("direct", "reflected", "reflected2")
             if isinstance(inputs.get(k), Mapping)]
    return " / ".join(names) or "synthetic"


def method_text(parameters: Mapping[str, Any], name: Callable[[str], str] | None = None) -> str:
    """How the method ran, in the words ``saucerfab design`` prints: the method asked for, what ran and why.

    E.g. ``auto (the default): 2 stages (the small-sigma stage skipped: these pictures have a clear
    subject), at most 120 iterations a stage (or until 16 renders in a row gain too little)``.

    Args:
        parameters: design.json's ``parameters``.
        name: when given, the stages are listed after their count, each as ``name(stage)``
            (``stage_label``, or ``str`` for the raw names).
    """
    asked = str(parameters.get("method") or METHODS[0])
    used = parameters.get("method_used")
    if not used:  # a design from before --method: it ran the paper's stages
        return "paper (made before saucerfab chose the stages)"
    head = f"{asked} (the default)" if asked == METHODS[0] else asked
    if used != asked:
        head += f", run as {used} (the paper's Figure 11 settings run as written)"
    stages = [s for s in parameters.get("stages", []) if isinstance(s, Mapping)]
    text = f"{head}: {len(stages)} stage{'s' if len(stages) != 1 else ''}"
    if name is not None:
        text += ": " + ", ".join(name(str(s.get("name"))) for s in stages)
    if used == "auto":
        small = any(s.get("regulariser") == "deform" and s.get("sigma") == SIGMA_SMALL for s in stages)
        text += (" (the small-sigma stage run: these pictures are used as they are)" if small
                 else " (the small-sigma stage skipped: these pictures have a clear subject)")
    if parameters.get("max_iters_used"):
        text += f", at most {parameters['max_iters_used']} iterations a stage"
    if parameters.get("stall_window_used"):
        text += f" (or until {parameters['stall_window_used']} renders in a row gain too little)"
    return text


def api_labels() -> dict[str, Any]:
    """The labels for the studio's page (``GET /api/options``' ``labels``).

    ``{"stages": {name: label}, "energies": {key: label}, "hidden_energies": [key...],
    "stop_reasons": {reason: label}}``.
    """
    return {
        "stages": dict(STAGE_LABELS),
        "energies": dict(ENERGY_LABELS),
        "hidden_energies": sorted(HIDDEN_ENERGIES),
        "stop_reasons": dict(STOP_LABELS),
    }
