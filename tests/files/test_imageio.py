"""``saucerfab.files.imageio``'s PNG writers: several pictures encoded on threads give the bytes of one at a time."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from saucerfab.files import imageio, machine
from saucerfab.files.imageio import png_bytes, png_bytes_many


def _pictures() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(3)
    return {
        "texture.png": rng.integers(0, 256, (96, 160, 3), dtype=np.uint8),
        "grey.png": rng.integers(0, 256, (40, 30), dtype=np.uint8),
        "flat.png": np.full((8, 8, 3), 200, np.uint8),
        "ramp.png": np.tile(np.arange(64, dtype=np.uint8)[:, None, None], (1, 64, 3)),
    }


@pytest.mark.parametrize("level", [1, imageio.PNG_COMPRESS_LEVEL])
def test_png_bytes_many_gives_the_bytes_of_one_at_a_time_in_order(level: int, monkeypatch: pytest.MonkeyPatch) -> None:
    pictures = _pictures()
    # as many threads as pictures, whatever this machine's cores
    monkeypatch.setattr(machine, "usable_cores", lambda: 8)
    many = png_bytes_many(pictures, level)
    assert list(many) == list(pictures)
    for name, img in pictures.items():
        assert many[name] == png_bytes(img, level), name
        with Image.open(io.BytesIO(many[name])) as im:
            assert np.array_equal(np.asarray(im), img), name


def test_png_bytes_many_on_one_core_and_with_one_picture(monkeypatch: pytest.MonkeyPatch) -> None:
    pictures = _pictures()
    monkeypatch.setattr(machine, "usable_cores", lambda: 1)
    assert png_bytes_many(pictures) == {n: png_bytes(p) for n, p in pictures.items()}
    one = {"only.png": pictures["texture.png"]}
    assert png_bytes_many(one) == {"only.png": png_bytes(one["only.png"])}
    assert png_bytes_many({}) == {}


def test_usable_cores_counts_this_process_cores() -> None:
    import os

    n = machine.usable_cores()
    assert n >= 1
    if hasattr(os, "sched_getaffinity"):
        assert n == len(os.sched_getaffinity(0))
