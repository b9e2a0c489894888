"""People's words for the optimizer's keys (saucerfab/pages/labels.py): every declared stage, term and stop reason has one.

These tests fail when the optimizer declares a stage, an energy term or a
stop reason that has no label (the reports and the studio would show the
raw key), and when a stage's label says another sigma or other targets than
the stage has.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from saucerfab.errors import ConfigError
from saucerfab.optimize.energies import TERMS
from saucerfab.optimize.stages import ABLATION_STAGES, METHODS, StageSpec, stages_for, without_enhancement
from saucerfab.pages import labels

SOLVER = Path(labels.__file__).resolve().parents[1] / "optimize" / "solver.py"


def _every_stage() -> list[StageSpec]:
    """Every stage the optimizer can run: each ablation as written, each method's, with and without enhancement."""
    out: list[StageSpec] = []
    for ablation, stages in ABLATION_STAGES.items():
        out += stages + without_enhancement(stages)
        for method in METHODS:
            for enhanced in (True, False):
                try:
                    run = stages_for(ablation, method, enhanced)
                except ConfigError:  # "fast" refuses the ablations: nothing to label
                    continue
                out += run if enhanced else without_enhancement(run)
    return out


def test_every_declared_stage_has_an_accurate_label() -> None:
    stages = _every_stage()
    assert {s.name for s in stages} >= {"bw_sigma_large", "bw_sigma_small", "plain_sigma_large", "sparse"}
    missing = sorted({s.name for s in stages} - set(labels.STAGE_LABELS))
    assert not missing, f"stages without a label in saucerfab/pages/labels.py STAGE_LABELS: {missing}"
    for s in stages:
        text = labels.STAGE_LABELS[s.name]
        assert labels.sigma_text(s.sigma) in text, (s, text)
        assert "_" not in text, text  # words, not a key
        # a label naming the targets names the ones the stage has (the sparse stage's name serves both)
        if labels.TARGET_LABELS["enhanced"] in text:
            assert s.targets == "enhanced", (s, text)
        if labels.TARGET_LABELS["original"] in text:
            assert s.targets == "original", (s, text)
        assert ("no smoothness" in text) == (s.regulariser == "none"), (s, text)
    assert len(set(labels.STAGE_LABELS.values())) == len(labels.STAGE_LABELS), "two stages read the same"


def test_sigma_text_reads_as_people_write_it() -> None:
    assert labels.sigma_text(1e-5) == "σ 1e-5"
    assert labels.sigma_text(2.5e-7) == "σ 2.5e-7"


def test_every_declared_energy_has_a_label_and_hidden_ones_are_declared() -> None:
    keys = {t.key for t in TERMS} | {"E_visual", "E_total"}
    missing = sorted(keys - set(labels.ENERGY_LABELS))
    assert not missing, f"energies without a label in saucerfab/pages/labels.py ENERGY_LABELS: {missing}"
    assert labels.HIDDEN_ENERGIES <= set(labels.ENERGY_LABELS)
    assert "E_barrier" in labels.HIDDEN_ENERGIES and "E_visual" not in labels.HIDDEN_ENERGIES
    assert labels.energy_label("E_deform") == "shape change"
    assert labels.energy_label("E_new_term") == "new term"  # a key from a newer saucerfab: its words


def test_every_stop_reason_of_the_solver_has_a_label() -> None:
    # the solver writes its reasons as literals (reason = "...", or converged, reason = True, "..."): read them
    reasons = set(re.findall(r"""reason = (?:\w+, )?["'](\w+)["']""", SOLVER.read_text(encoding="utf-8")))
    assert {"max_iters", "tolerance", "stalled"} <= reasons, reasons
    missing = sorted(reasons - set(labels.STOP_LABELS))
    assert not missing, f"stop reasons without a label in saucerfab/pages/labels.py STOP_LABELS: {missing}"


@pytest.mark.parametrize(
    ("parameters", "expected"),
    [
        ({"method": "auto", "method_used": "auto", "ablation": "full", "max_iters_used": 120, "stall_window_used": 16,
          "stages": [{"name": "bw_sigma_large", "regulariser": "deform", "sigma": 1e-5},
                     {"name": "sparse", "regulariser": "sparse", "sigma": 1e-5}]},
         "auto (the default): 2 stages (the small-sigma stage skipped: these pictures have a clear subject), at most "
         "120 iterations a stage (or until 16 renders in a row gain too little)"),
        ({"method": "paper", "method_used": "paper", "ablation": "full", "max_iters_used": 400, "stall_window_used": 0,
          "stages": [{"name": "bw_sigma_large"}, {"name": "bw_sigma_small"}, {"name": "sparse"}]},
         "paper: 3 stages, at most 400 iterations a stage"),
        ({"method": "auto", "method_used": "paper", "ablation": "laplacian", "stages": [{"name": "plain_sigma_large"}]},
         "auto (the default), run as paper (the paper's Figure 11 settings run as written): 1 stage"),
        ({"ablation": "full"}, "paper (made before saucerfab chose the stages)"),
    ],
)
def test_method_text_says_what_was_asked_and_what_ran(parameters: dict, expected: str) -> None:
    assert labels.method_text(parameters) == expected


def test_method_text_lists_the_stages_when_asked() -> None:
    p = {"method": "fast", "method_used": "fast", "stages": [{"name": "bw_sigma_large"}, {"name": "sparse"}]}
    assert labels.method_text(p, str) == "fast: 2 stages: bw_sigma_large, sparse"
    assert labels.STAGE_LABELS["sparse"] in labels.method_text(p, labels.stage_label)


def test_design_name_and_api_labels() -> None:
    inputs = {"direct": {"file": "heart.png"}, "reflected": {"file": "star.png"}, "shape": {"builtin": "waves"}}
    assert labels.design_name(inputs) == "heart.png / star.png"
    assert labels.design_name({}) == "synthetic"
    api = labels.api_labels()
    assert api["stages"] == labels.STAGE_LABELS and set(api["hidden_energies"]) == labels.HIDDEN_ENERGIES
    assert api["stop_reasons"]["max_iters"] == "iteration cap"
