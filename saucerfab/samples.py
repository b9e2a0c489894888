"""The bundled sample pictures (``samples/``) and the pairs they make.

One list for the demo, the benchmarks and the tests. The graphics are made by
``samples/make_samples.py``; the photographs come from scikit-image's data
(CC0 / public domain, provenance in ``samples/photos/README.md``).
"""

from __future__ import annotations

from pathlib import Path

#: the samples folder of a source checkout
SAMPLES = Path(__file__).resolve().parents[1] / "samples"

#: graphics: a subject on a plain background or alpha (name -> (direct, reflected), relative to SAMPLES)
GRAPHIC_PAIRS: dict[str, tuple[str, str]] = {
    "heart-star": ("direct_heart.png", "reflected_star.png"),
    "fish-moon": ("fish_wide.jpg", "reflected2_moon.png"),
    "tree-note": ("tree_gray16.png", "note_palette.png"),
}

#: full-bleed photographs, as most people bring them
PHOTO_PAIRS: dict[str, tuple[str, str]] = {
    "chelsea-coffee": ("photos/chelsea.png", "photos/coffee.png"),
    "astronaut-rocket": ("photos/astronaut.png", "photos/rocket.jpg"),
    "coffee-hubble": ("photos/coffee.png", "photos/hubble_deep_field.jpg"),
    "rocket-chelsea": ("photos/rocket.jpg", "photos/chelsea.png"),
}

#: every bundled pair
PAIRS: dict[str, tuple[str, str]] = {**GRAPHIC_PAIRS, **PHOTO_PAIRS}

#: the pair the demo designs
DEMO_PAIR = "heart-star"


def pair_paths(name: str, samples: Path = SAMPLES) -> tuple[Path, Path]:
    """(direct, reflected) file paths of pair ``name`` under ``samples``."""
    direct, reflected = PAIRS[name]
    return samples / direct, samples / reflected
