"""Hard rasterization (nearest face wins, no gradients): previews and visibility.

The camera, NDC and pixel conventions are :mod:`saucerfab.model.camera`'s:
pixel (i, j) samples the NDC point ``((2j + 1)/S - 1, 1 - (2i + 1)/S)``.

A pixel centre is covered by a face when its screen-space barycentric
coordinates are all >= 0 (edges and corners included, so a closed mesh has no
cracks); of the faces covering it the one with the smallest depth wins, and
on equal depth the lower face index (deterministic whatever the thread count).
Faces with a corner at depth <= ``near`` (default 1e-6: at or behind the eye)
are not drawn: there is no near-plane clipping, which the saucer scenes never
need.

The kernel bins faces into bands of BAND image rows that one thread each owns
whole (``prange`` over bands: no races, and the result does not depend on the
thread count). The brute-force per-pixel ray-triangle reference is in
``tests/render_reference.py``.

Depth is the camera-space depth (distance along the view axis, model units),
interpolated perspective-correctly: ``1/z = sum_k w_k / z_k`` with ``w`` the
screen-space barycentrics. ``bary`` holds the perspective-correct barycentrics
``b_k = z w_k / z_k`` of the visible point, so the world point is
``sum_k b_k V_k`` and per-corner attributes (UVs) interpolate as ``sum_k b_k a_k``.

Texture coordinates and sampling (bilinear, clamp-to-edge) are
:mod:`saucerfab.render.sampling`'s.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numba import njit, prange

from saucerfab.errors import ConfigError
from saucerfab.model.camera import Camera
from saucerfab.render.sampling import sample_bilinear

#: rows per band of the image that one thread owns whole
BAND = 16


def _as_numpy(x: Any, name: str, dtype: Any) -> np.ndarray:
    """Array from a numpy array or a torch tensor (detached, CPU)."""
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    try:
        return np.ascontiguousarray(np.asarray(x, dtype=dtype))
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a numeric array, got {type(x).__name__}") from None


def _check_mesh(vertices: Any, faces: Any) -> tuple[np.ndarray, np.ndarray]:
    v = _as_numpy(vertices, "vertices", np.float64)
    f = _as_numpy(faces, "faces", np.int64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ConfigError(f"vertices must have shape (V, 3), got {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3:
        raise ConfigError(f"faces must have shape (F, 3), got {f.shape}")
    if f.size and (f.min() < 0 or f.max() >= v.shape[0]):
        raise ConfigError(f"faces index vertices {f.min()}..{f.max()}, but there are {v.shape[0]} vertices")
    return v, f


def _sized(camera: Camera, image_size: int | None) -> Camera:
    if image_size is None:
        return camera
    if not isinstance(image_size, (int, np.integer)) or image_size < 1:
        raise ConfigError(f"image_size must be a positive integer, got {image_size!r}")
    return camera.with_size(int(image_size))


@njit(cache=True)
def _bin_rows(box: np.ndarray, n_bands: int):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    """Faces per band of BAND rows (CSR, in increasing face order)."""
    count = np.zeros(n_bands + 1, np.int64)
    for f in range(box.shape[0]):
        if box[f, 1] >= box[f, 0] and box[f, 3] >= box[f, 2]:
            for b in range(box[f, 0] // BAND, box[f, 1] // BAND + 1):
                count[b + 1] += 1
    start = np.cumsum(count)
    fill = start[:-1].copy()
    items = np.empty(start[-1], np.int64)
    for f in range(box.shape[0]):
        if box[f, 1] >= box[f, 0] and box[f, 3] >= box[f, 2]:
            for b in range(box[f, 0] // BAND, box[f, 1] // BAND + 1):
                items[fill[b]] = f
                fill[b] += 1
    return start, items


@njit(parallel=True, cache=True)
def _raster(proj, faces, size, near, face_id, bary, depth):  # type: ignore[no-untyped-def] # pragma: no cover - jit
    n = faces.shape[0]
    box = np.empty((n, 4), np.int64)
    for f in prange(n):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        ok = proj[a, 2] > near and proj[b, 2] > near and proj[c, 2] > near
        xs = (proj[a, 0], proj[b, 0], proj[c, 0])
        ys = (proj[a, 1], proj[b, 1], proj[c, 1])
        lox, hix = min(xs), max(xs)
        loy, hiy = min(ys), max(ys)
        ok = ok and np.isfinite(lox) and np.isfinite(hix) and np.isfinite(loy) and np.isfinite(hiy)
        if not ok:
            box[f, 0], box[f, 1], box[f, 2], box[f, 3] = 0, -1, 0, -1
            continue
        # centres inside the box: column j has x = (2j + 1)/S - 1, row i has y = 1 - (2i + 1)/S
        box[f, 2] = max(int(np.ceil(min(max(((lox + 1) * size - 1) / 2, -1.0), size))), 0)
        box[f, 3] = min(int(np.floor(min(max(((hix + 1) * size - 1) / 2, -1.0), size))), size - 1)
        box[f, 0] = max(int(np.ceil(min(max(((1 - hiy) * size - 1) / 2, -1.0), size))), 0)
        box[f, 1] = min(int(np.floor(min(max(((1 - loy) * size - 1) / 2, -1.0), size))), size - 1)
    n_bands = (size + BAND - 1) // BAND
    start, items = _bin_rows(box, n_bands)
    for band in prange(n_bands):
        for k in range(start[band], start[band + 1]):
            f = items[k]
            a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
            x0, y0, z0 = proj[a, 0], proj[a, 1], proj[a, 2]
            x1, y1, z1 = proj[b, 0], proj[b, 1], proj[b, 2]
            x2, y2, z2 = proj[c, 0], proj[c, 1], proj[c, 2]
            det = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
            if det == 0.0:
                continue  # a face seen edge-on covers no pixel centre
            for i in range(max(box[f, 0], band * BAND), min(box[f, 1], band * BAND + BAND - 1) + 1):
                py = 1 - (2 * i + 1) / size
                for j in range(box[f, 2], box[f, 3] + 1):
                    px = (2 * j + 1) / size - 1
                    w1 = ((px - x0) * (y2 - y0) - (x2 - x0) * (py - y0)) / det
                    w2 = ((x1 - x0) * (py - y0) - (px - x0) * (y1 - y0)) / det
                    w0 = 1.0 - w1 - w2
                    if w0 < 0 or w1 < 0 or w2 < 0:
                        continue
                    q0, q1, q2 = w0 / z0, w1 / z1, w2 / z2
                    z = 1.0 / (q0 + q1 + q2)
                    cur = face_id[i, j]
                    if cur < 0 or z < depth[i, j] or (z == depth[i, j] and f < cur):
                        face_id[i, j] = f
                        depth[i, j] = z
                        bary[i, j, 0], bary[i, j, 1], bary[i, j, 2] = q0 * z, q1 * z, q2 * z


def rasterize_hard(
    vertices: Any, faces: Any, camera: Camera, image_size: int | None = None, *, near: float = 1e-6
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest-face rasterization of a mesh (no gradients).

    Args:
        vertices: World positions, shape [V, 3], model units (numpy or torch).
        faces: Vertex indices, shape [F, 3], integer. Both windings are drawn.
        camera: The view.
        image_size: Output size S; default ``camera.image_size``.
        near: Faces with a corner at depth <= near (model units) are skipped.

    Returns:
        A tuple of numpy arrays ``(face_id, bary, depth)``:

        - **face_id** - Visible face per pixel, shape [S, S], int64, -1 for background.
        - **bary** - Perspective-correct barycentrics of the visible point on its
          face, shape [S, S, 3], float64, summing to 1 (0 on background).
        - **depth** - Camera-space depth of the visible point, shape [S, S],
          float64, model units (``inf`` on background).

    Raises:
        ConfigError: arrays of the wrong shape, indices out of range, a bad image size.
    """
    v, f = _check_mesh(vertices, faces)
    cam = _sized(camera, image_size)
    s = cam.image_size
    proj = np.ascontiguousarray(cam.project(v)) if v.shape[0] else np.zeros((0, 3))
    face_id = np.full((s, s), -1, np.int64)
    bary = np.zeros((s, s, 3))
    depth = np.full((s, s), np.inf)
    if f.shape[0]:
        _raster(proj, f, s, float(near), face_id, bary, depth)
    return face_id, bary, depth


#: RGB of the previews where no face is seen: white
PREVIEW_BACKGROUND = (1.0, 1.0, 1.0)


def _background(background: Any) -> np.ndarray:
    bg = np.asarray(background, dtype=np.float64)
    if bg.shape != (3,) or not np.isfinite(bg).all():
        raise ConfigError(f"background must be 3 finite numbers (RGB), got {background!r}")
    return bg


def _preview(
    vertices: Any,
    faces: Any,
    camera: Camera,
    background: Any,
    image_size: int | None,
    shade: Callable[[np.ndarray, np.ndarray], np.ndarray],
) -> np.ndarray:
    """The background colour, and ``shade(face_id, bary)`` (each of shapes [N], [N, 3])
    at the N pixels where a face is seen; shape [S, S, 3], float64."""
    bg = _background(background)
    face_id, bary, _ = rasterize_hard(vertices, faces, camera, image_size)
    image = np.empty(face_id.shape + (3,))
    image[:] = bg
    seen = face_id >= 0
    image[seen] = shade(face_id[seen], bary[seen])
    return image


def render_face_colors_hard(
    vertices: Any, faces: Any, face_colors: Any, camera: Camera,
    background: tuple[float, float, float] = PREVIEW_BACKGROUND, image_size: int | None = None,
) -> np.ndarray:
    """Nearest-face preview with one colour per face.

    Args:
        vertices: World positions, shape [V, 3], model units.
        faces: Vertex indices, shape [F, 3].
        face_colors: RGB per face, shape [F, 3], in [0, 1].
        camera: The view.
        background: RGB where no face is seen.
        image_size: Output size S; default ``camera.image_size``.

    Returns:
        Image, shape [S, S, 3], float64, row 0 at the top.
    """
    _, f = _check_mesh(vertices, faces)
    colors = _as_numpy(face_colors, "face_colors", np.float64)
    if colors.shape != (f.shape[0], 3):
        raise ConfigError(f"face_colors must have shape ({f.shape[0]}, 3), got {colors.shape}")
    return _preview(vertices, faces, camera, background, image_size, lambda fid, _: colors[fid])


def render_textured(
    vertices: Any, faces: Any, face_uvs: Any, texture: Any, camera: Camera,
    background: tuple[float, float, float] = PREVIEW_BACKGROUND, image_size: int | None = None,
) -> np.ndarray:
    """Nearest-face preview of a textured mesh (perspective-correct UVs, bilinear).

    Args:
        face_uvs: UV of each face corner, shape [F, 3, 2] (u left to right,
            v bottom to top, [0, 1] spans the texture).
        texture: Shape [H, W, 3], uint8 (0..255) or float (0..1); row 0 is the top.
        vertices, faces, camera, background, image_size: As :func:`render_face_colors_hard`.

    Returns:
        Image, shape [S, S, 3], float64 in [0, 1], row 0 at the top.
    """
    _, f = _check_mesh(vertices, faces)
    uvs = _as_numpy(face_uvs, "face_uvs", np.float64)
    if uvs.shape != (f.shape[0], 3, 2):
        raise ConfigError(f"face_uvs must have shape ({f.shape[0]}, 3, 2), got {uvs.shape}")
    tex = np.asarray(texture.detach().cpu().numpy() if hasattr(texture, "detach") else texture)
    if tex.ndim != 3 or tex.shape[2] != 3 or tex.shape[0] < 1 or tex.shape[1] < 1:
        raise ConfigError(f"texture must have shape (H, W, 3), got {tex.shape}")
    if tex.dtype == np.uint8:
        tex = tex.astype(np.float64) / 255.0
    elif np.issubdtype(tex.dtype, np.floating):
        tex = tex.astype(np.float64)
    else:
        raise ConfigError(f"texture must be uint8 (0..255) or float (0..1), got {tex.dtype}")

    def shade(fid: np.ndarray, bary: np.ndarray) -> np.ndarray:
        return sample_bilinear(tex, np.einsum("nk,nkc->nc", bary, uvs[fid]))

    return _preview(vertices, faces, camera, background, image_size, shade)
