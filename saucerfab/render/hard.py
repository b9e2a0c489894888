"""Hard (sigma -> 0) rasterization: nearest face wins. No gradients.

Used for visibility (which faces a view shows: texturing, targets,
conflict areas), for textured previews at any resolution, and by the
fabrication and check stages. Conventions are :mod:`saucerfab.render.camera`'s:
pixel (i, j) has its centre at NDC ``((2j+1)/S - 1, 1 - (2i+1)/S)``; a pixel
belongs to a face when its centre is inside the projected triangle (edges
inclusive; between two faces sharing an edge the nearer, then the lower
index, wins). No back-face culling (reflected meshes have flipped winding).

Depth is the view-axis depth ``<v - eye, forward>``, interpolated
perspective-correctly: ``1/z = sum_k b_k / z_k`` with screen-space
barycentrics ``b``; the returned barycentrics are perspective-correct
(``b_k z / z_k``), so attributes (UVs) interpolate as on the 3-D triangle.
Faces with any vertex at depth <= ``near`` are skipped (behind the camera).

The kernel is a serial numba loop over faces and their pixel boxes (cost
follows covered pixels); :func:`rasterize_hard_reference` is the slow,
obvious per-pixel version the tests compare it with.
"""

from __future__ import annotations

import numpy as np

from saucerfab.render.camera import Camera

_kernel = None


def _get_kernel():  # type: ignore[no-untyped-def]
    global _kernel
    if _kernel is not None:
        return _kernel
    import numba

    @numba.njit(cache=True)
    def kernel(sx, sy, z, faces, size, near, face_id, bary, depth):  # type: ignore[no-untyped-def]
        nf = faces.shape[0]
        for f in range(nf):
            a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
            za, zb, zc = z[a], z[b], z[c]
            if za <= near or zb <= near or zc <= near:
                continue
            ax, ay, bx, by, cx, cy = sx[a], sy[a], sx[b], sy[b], sx[c], sy[c]
            den = (by - cy) * (ax - cx) + (cx - bx) * (ay - cy)
            if den == 0.0:
                continue
            x0 = max(int(np.floor(min(ax, bx, cx) - 0.5)), 0)
            x1 = min(int(np.ceil(max(ax, bx, cx) - 0.5)), size - 1)
            y0 = max(int(np.floor(min(ay, by, cy) - 0.5)), 0)
            y1 = min(int(np.ceil(max(ay, by, cy) - 0.5)), size - 1)
            for i in range(y0, y1 + 1):
                py = i + 0.5
                for j in range(x0, x1 + 1):
                    px = j + 0.5
                    w0 = ((by - cy) * (px - cx) + (cx - bx) * (py - cy)) / den
                    w1 = ((cy - ay) * (px - cx) + (ax - cx) * (py - cy)) / den
                    w2 = 1.0 - w0 - w1
                    if w0 < -1e-12 or w1 < -1e-12 or w2 < -1e-12:
                        continue
                    inv = w0 / za + w1 / zb + w2 / zc
                    zz = 1.0 / inv
                    old = face_id[i, j]
                    if old >= 0 and (zz > depth[i, j] or (zz == depth[i, j] and f > old)):
                        continue
                    face_id[i, j] = f
                    depth[i, j] = zz
                    bary[i, j, 0] = w0 * zz / za
                    bary[i, j, 1] = w1 * zz / zb
                    bary[i, j, 2] = w2 * zz / zc

    _kernel = kernel
    return kernel


def _screen(vertices: np.ndarray, camera: Camera, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    p = camera.project(np.asarray(vertices, np.float64))
    sx = (p[:, 0] + 1.0) * size / 2.0
    sy = (1.0 - p[:, 1]) * size / 2.0
    return sx, sy, p[:, 2]


def _as_np(a, dtype):  # type: ignore[no-untyped-def]
    if hasattr(a, "detach"):
        a = a.detach().cpu().numpy()
    return np.ascontiguousarray(np.asarray(a), dtype=dtype)


def rasterize_hard(vertices, faces, camera: Camera, image_size: int | None = None, *, near: float = 1e-6):  # type: ignore[no-untyped-def]
    """Nearest-face rasterization.

    Args:
        vertices: (V, 3) world positions (numpy or torch), model units.
        faces: (F, 3) int vertex indices.
        camera: the view; ``image_size`` overrides its size S.
        near: faces with a vertex at depth <= near are skipped.
    Returns:
        ``face_id`` (S, S) int64 (-1 where no face), ``bary`` (S, S, 3)
        float64 perspective-correct barycentrics, ``depth`` (S, S) float64
        view-axis depth (+inf where no face). numpy arrays.
    """
    size = int(image_size or camera.image_size)
    v = _as_np(vertices, np.float64)
    f = _as_np(faces, np.int64)
    face_id = np.full((size, size), -1, np.int64)
    bary = np.zeros((size, size, 3), np.float64)
    depth = np.full((size, size), np.inf, np.float64)
    if f.shape[0] == 0:
        return face_id, bary, depth
    sx, sy, z = _screen(v, camera, size)
    _get_kernel()(sx, sy, z, f, size, float(near), face_id, bary, depth)
    return face_id, bary, depth


def rasterize_hard_reference(vertices, faces, camera: Camera, image_size: int | None = None):  # type: ignore[no-untyped-def]
    """The slow, obvious version: every pixel against every face (tiny scenes only)."""
    size = int(image_size or camera.image_size)
    v = _as_np(vertices, np.float64)
    f = _as_np(faces, np.int64)
    sx, sy, z = _screen(v, camera, size)
    face_id = np.full((size, size), -1, np.int64)
    bary = np.zeros((size, size, 3))
    depth = np.full((size, size), np.inf)
    for i in range(size):
        for j in range(size):
            px, py = j + 0.5, i + 0.5
            for k, (a, b, c) in enumerate(f):
                if min(z[a], z[b], z[c]) <= 1e-6:
                    continue
                den = (sy[b] - sy[c]) * (sx[a] - sx[c]) + (sx[c] - sx[b]) * (sy[a] - sy[c])
                if den == 0:
                    continue
                w0 = ((sy[b] - sy[c]) * (px - sx[c]) + (sx[c] - sx[b]) * (py - sy[c])) / den
                w1 = ((sy[c] - sy[a]) * (px - sx[c]) + (sx[a] - sx[c]) * (py - sy[c])) / den
                w2 = 1 - w0 - w1
                if min(w0, w1, w2) < -1e-12:
                    continue
                zz = 1 / (w0 / z[a] + w1 / z[b] + w2 / z[c])
                if zz < depth[i, j]:
                    depth[i, j] = zz
                    face_id[i, j] = k
                    bary[i, j] = [w0 * zz / z[a], w1 * zz / z[b], w2 * zz / z[c]]
    return face_id, bary, depth


def sample_texture(texture: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear samples of ``texture`` (H, W, C) at ``uv`` (..., 2), u right, v up, clamped.

    Texel (r, c) has its centre at ``u = (c + 0.5) / W``, ``v = 1 - (r + 0.5) / H``.
    Returns float64 (..., C) in the texture's units (uint8 textures give 0..1).
    """
    tex = texture.astype(np.float64) / (255.0 if texture.dtype == np.uint8 else 1.0)
    h, w = tex.shape[:2]
    x = np.clip(uv[..., 0] * w - 0.5, 0, w - 1)
    y = np.clip((1.0 - uv[..., 1]) * h - 0.5, 0, h - 1)
    x0 = np.minimum(np.floor(x).astype(np.int64), max(w - 2, 0))
    y0 = np.minimum(np.floor(y).astype(np.int64), max(h - 2, 0))
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    tx, ty = (x - x0)[..., None], (y - y0)[..., None]
    top = tex[y0, x0] * (1 - tx) + tex[y0, x1] * tx
    bot = tex[y1, x0] * (1 - tx) + tex[y1, x1] * tx
    return top * (1 - ty) + bot * ty


def render_textured(  # type: ignore[no-untyped-def]
    vertices, faces, face_uvs, texture, camera: Camera, background=(1.0, 1.0, 1.0), image_size: int | None = None
) -> np.ndarray:
    """Hard render with per-corner UVs and a texture.

    Args:
        face_uvs: (F, 3, 2) texture coordinates of each face corner (u right, v up).
        texture: (H, W, 3) uint8 or float in [0, 1].
    Returns:
        (S, S, 3) float64 in [0, 1].
    """
    fid, bary, _ = rasterize_hard(vertices, faces, camera, image_size)
    uvs = _as_np(face_uvs, np.float64)
    tex = texture.detach().cpu().numpy() if hasattr(texture, "detach") else np.asarray(texture)
    size = fid.shape[0]
    out = np.tile(np.asarray(background, np.float64), (size, size, 1))
    hit = fid >= 0
    if hit.any():
        uv = np.einsum("kc,kcd->kd", bary[hit], uvs[fid[hit]])
        out[hit] = sample_texture(tex, uv)
    return out


def render_face_colors_hard(  # type: ignore[no-untyped-def]
    vertices, faces, face_colors, camera: Camera, background=(1.0, 1.0, 1.0), image_size: int | None = None
) -> np.ndarray:
    """Hard render with one colour per face: (S, S, 3) float64."""
    fid, _, _ = rasterize_hard(vertices, faces, camera, image_size)
    cols = _as_np(face_colors, np.float64)
    size = fid.shape[0]
    out = np.tile(np.asarray(background, np.float64), (size, size, 1))
    hit = fid >= 0
    out[hit] = cols[fid[hit]]
    return out
