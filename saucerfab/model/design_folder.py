"""The design folder: what `saucerfab design` writes and `export`/`batch` read (a :class:`~saucerfab.model.design.Design` on disk).

Layout (schema ``saucerfab.design/1``)::

    DESIGN/
      design.json        schema, versions, scene, parameters, input hashes, metrics
      heights.npy        (N, N) float64, final heights h, model units
      base_heights.npy   (N, N) float64, the base shape z, model units
      texture.png        (H, W, 3) 8-bit sRGB texture image
      face_uvs.npy       (F, 3, 2) float32, texture coordinates of each face corner
      face_view.npy      (F,) uint8, per-face texturing case (FaceView)
      reference_<view>.png  (T, T, 3) 8-bit sRGB, each input picture as the designer
                         meant it: alpha composited over its background and fitted
                         into the view's square frame (what ``saucerfab verify``
                         compares the print with; ``export`` copies them)
      previews/          PNG previews (optional, for people)
      report.html        the design's page (saucerfab.pages.folder_pages), written with the folder
      verify/            the quick verify of a trial export (``saucerfab design``
                         writes it after the folder; optional)

The arrays' conventions are :mod:`saucerfab.model.design`'s.

The folder is written atomically (built under a temporary name, renamed).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from saucerfab import __version__
from saucerfab.errors import DesignError, SaucerfabError
from saucerfab.files.fileio import atomic_dir
from saucerfab.files.imageio import PixelLimitError, npy_header, open_bounded, png_bytes_many
from saucerfab.model.design import Design, FaceView
from saucerfab.model.heightfield import make_grid, triangulate
from saucerfab.model.scene import Scene, scene_from_dict, scene_to_dict

SCHEMA = "saucerfab.design/1"
MAX_TEXTURE_PIXELS = 8192 * 8192


def reference_name(view: str) -> str:
    """File name of a view's reference picture in design and print folders."""
    return f"reference_{view}.png"


def _npy_bytes(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, a, allow_pickle=False)
    return buf.getvalue()


def design_json(design: Design) -> dict[str, Any]:
    """The ``design.json`` content for ``design``."""
    import platform

    return {
        "schema": SCHEMA,
        "saucerfab_version": __version__,
        "python": platform.python_version(),
        "scene": scene_to_dict(design.scene),
        "parameters": design.parameters,
        "inputs": design.inputs,
        "metrics": design.metrics,
        "files": {
            "heights": "heights.npy",
            "base_heights": "base_heights.npy",
            "texture": "texture.png",
            "face_uvs": "face_uvs.npy",
            "face_view": "face_view.npy",
            **{f"reference_{v}": reference_name(v) for v in sorted(design.references)},
        },
        "conventions": {
            "grid": "heights[i, j] at x = xs[j], y = ys[i]; vertex = i * N + j",
            "faces": "saucerfab.model.heightfield.triangulate(N), counter-clockwise from +z",
            "uv": "u left->right, v bottom->top of texture.png",
        },
    }


def save_design(
    design: Design,
    out: str | os.PathLike[str],
    *,
    previews: dict[str, bytes] | None = None,
    extra_files: dict[str, bytes] | None = None,
) -> Path:
    """Write ``design`` as a design folder at ``out``, atomically.

    Args:
        previews: PNG bytes by file name, written under ``previews/``.
        extra_files: more files by relative name (e.g. an energy log).
    """
    design.validate()
    files = {
        "heights.npy": _npy_bytes(np.asarray(design.heights, np.float64)),
        "base_heights.npy": _npy_bytes(np.asarray(design.base_heights, np.float64)),
        "face_uvs.npy": _npy_bytes(np.asarray(design.face_uvs, np.float32)),
        "face_view.npy": _npy_bytes(np.asarray(design.face_view, np.uint8)),
    }
    pictures = {"texture.png": design.texture}
    pictures.update({reference_name(view): img for view, img in sorted(design.references.items())})
    files.update(png_bytes_many(pictures))
    for name, data in (previews or {}).items():
        files[f"previews/{name}"] = data
    files.update(extra_files or {})
    for rel in files:
        parts = Path(rel).parts
        if Path(rel).is_absolute() or ".." in parts or not parts:
            raise ValueError(f"design file name {rel!r} must be a relative path inside the folder")
    meta = design_json(design)
    meta["file_sha256"] = {k: hashlib.sha256(v).hexdigest() for k, v in sorted(files.items())}
    files["design.json"] = (json.dumps(meta, indent=2, sort_keys=True) + "\n").encode()
    with atomic_dir(out) as tmp:
        for rel, data in files.items():
            p = tmp / rel
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_bytes(data)
    return Path(out)


def _load_npy(path: Path, max_elems: int) -> np.ndarray:
    """A design's numeric array, refused from its header when over ``max_elems`` values."""
    try:
        shape, dtype = npy_header(path)
        if int(np.prod(shape)) > max_elems:
            raise DesignError(f"{path} holds {shape}; larger than any design saucerfab makes")
        if dtype.kind not in "biuf":  # the callers convert to float/uint8
            raise DesignError(f"{path} holds {dtype} values; a design stores numbers")
        return np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise DesignError(f"cannot read {path}: {exc}") from None


def _load_png(path: Path) -> np.ndarray:
    """(H, W, 3) uint8 of a design's PNG, its pixel count bounded before decoding."""
    from PIL import Image

    try:
        with open_bounded(path, ("PNG",), MAX_TEXTURE_PIXELS) as im:
            return np.asarray(im.convert("RGB"), dtype=np.uint8)
    except PixelLimitError as exc:
        raise DesignError(f"{path.name} is {exc.width}x{exc.height}, over the limit") from None
    except (OSError, Image.DecompressionBombError) as exc:
        raise DesignError(f"cannot read {path}: {exc}") from None


def load_design(folder: str | os.PathLike[str]) -> Design:
    """Read and validate a design folder.

    Raises:
        DesignError: missing folder or file, wrong schema, inconsistent arrays.
    """
    folder = Path(folder)
    meta_path = folder / "design.json"
    if not meta_path.is_file():
        raise DesignError(
            f"{str(folder)!r} is not a design folder (no design.json); "
            "make one with 'saucerfab design'"
        )
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DesignError(f"cannot read {meta_path}: {exc}") from None
    if not isinstance(meta, dict) or meta.get("schema") != SCHEMA:
        got = meta.get("schema") if isinstance(meta, dict) else None
        raise DesignError(f"{meta_path} has schema {got!r}; this saucerfab reads {SCHEMA!r}")
    try:
        scene = scene_from_dict(meta["scene"])
    except (KeyError, SaucerfabError) as exc:  # missing, or a scene that no longer validates
        raise DesignError(f"{meta_path} has no valid scene: {exc}") from None
    for key in ("parameters", "metrics", "inputs"):  # free-form, but mappings: every reader takes them so
        if not isinstance(meta.get(key, {}), dict):
            raise DesignError(f"{meta_path}: {key!r} must be a JSON object, got {type(meta[key]).__name__}; "
                              "re-run 'saucerfab design'")
    n = scene.saucer.resolution
    limit = 4 * 2 * n * n * 3 * 2
    for name in ("heights.npy", "base_heights.npy", "face_uvs.npy", "face_view.npy", "texture.png"):
        if not (folder / name).is_file():
            raise DesignError(f"design folder {str(folder)!r} lacks {name}; re-run 'saucerfab design'")
    texture = _load_png(folder / "texture.png")
    references = {}
    for view in ("direct", "reflected", "reflected2"):
        ref = folder / reference_name(view)
        if ref.is_file():
            references[view] = _load_png(ref)
    design = Design(
        scene=scene,
        heights=_load_npy(folder / "heights.npy", limit).astype(np.float64),
        base_heights=_load_npy(folder / "base_heights.npy", limit).astype(np.float64),
        texture=texture,
        face_uvs=_load_npy(folder / "face_uvs.npy", limit).astype(np.float32),
        face_view=_load_npy(folder / "face_view.npy", limit).astype(np.uint8),
        parameters=meta.get("parameters", {}),
        metrics=meta.get("metrics", {}),
        inputs=meta.get("inputs", {}),
        references=references,
        folder=folder,
    )
    design.validate()
    return design


def synthetic_design(
    scene: Scene | None = None,
    *,
    shape: str = "waves",
    resolution: int = 24,
    texture_size: int = 64,
    seed: int = 0,
) -> Design:
    """A small design made without optimization, for tests and demos of later stages.

    Heights are the base shape plus a seeded bump field within delta; the
    texture is a colour checkerboard mapped by planar (x, y) projection, so
    every face is ``DIRECT`` and a texel's expected colour is easy to compute.
    """
    from dataclasses import replace

    from saucerfab.model.heightfield import base_shape

    scene = scene or Scene()
    scene = replace(scene, saucer=replace(scene.saucer, resolution=resolution))
    rng = np.random.default_rng(seed)
    base = base_shape(shape, resolution, seed)
    heights = base + rng.uniform(-0.5, 0.5, base.shape) * scene.saucer.delta
    grid = make_grid(scene.saucer)
    xy = grid.xy()
    (x0, x1), (y0, y1) = scene.saucer.x_range, scene.saucer.y_range
    uv = np.stack([(xy[:, 0] - x0) / (x1 - x0), (xy[:, 1] - y0) / (y1 - y0)], axis=1)
    faces = triangulate(resolution)
    ty, tx = np.mgrid[0:texture_size, 0:texture_size]
    cells = 8
    cx, cy = tx * cells // texture_size, ty * cells // texture_size
    palette = np.array(
        [[230, 57, 70], [29, 53, 87], [241, 250, 238], [69, 123, 157], [255, 183, 3], [42, 157, 143]],
        dtype=np.uint8,
    )
    texture = palette[(cx + 2 * cy) % len(palette)]
    return Design(
        scene=scene,
        heights=heights,
        base_heights=base,
        texture=np.ascontiguousarray(texture),
        face_uvs=uv[faces].astype(np.float32),
        face_view=np.full(faces.shape[0], FaceView.DIRECT, np.uint8),
        parameters={"synthetic": True, "shape": shape, "seed": seed},
        metrics={},
        inputs={},
    )
