"""Tests of saucerfab.optimize.enhancement: the paper's enhanced targets (eq. 7-8, Figure 19)."""

from __future__ import annotations

import numpy as np
import pytest

from saucerfab.optimize.enhancement import LIGHT_BLUE, black_white_targets, solid_colour_targets


def test_black_white_targets_are_the_papers_colours():
    dm = np.zeros((6, 8), bool)
    dm[1:3, 2:5] = True
    rm = np.zeros((5, 5), bool)
    rm[0, 0] = True
    de, re_ = black_white_targets(dm, rm)
    assert de.shape == (6, 8, 3) and re_.shape == (5, 5, 3) and de.dtype == np.float32
    assert LIGHT_BLUE == (0.0, 0.5, 1.0)
    assert (de[dm] == [0.0, 0.0, 0.0]).all() and (de[~dm] == [0.0, 0.5, 1.0]).all()
    assert (re_[rm] == [1.0, 1.0, 1.0]).all() and (re_[~rm] == [0.0, 0.5, 1.0]).all()


def test_solid_colour_targets():
    masks = [np.eye(4, dtype=bool), np.fliplr(np.eye(4, dtype=bool)), np.zeros((4, 4), bool)]
    masks[2][0, 1] = True
    out = solid_colour_targets(masks)
    assert len(out) == 3
    for m, img, c in zip(masks, out, ([1, 0, 0], [0, 1, 0], [0, 0, 1])):
        assert (img[m] == c).all() and (img[~m] == [1, 1, 1]).all()
    with pytest.raises(ValueError):
        solid_colour_targets(masks + [masks[0]])


def test_soft_masks_blend():
    de, _ = black_white_targets(np.full((2, 2), 0.5), np.zeros((2, 2), bool))
    np.testing.assert_allclose(de[0, 0], [0.0, 0.25, 0.5])
