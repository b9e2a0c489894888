"""Texturing with the shape fixed (paper, section 3.4.2).

Each saucer face is classified by where the viewer sees it: directly only,
in the reflection only, in both, or in neither (:class:`FaceView`). Its
texture coordinates are its corners' projections into the image of the view
it is seen in. The texture is the input images side by side::

    +-----------+-----------+-------------+-----------+
    |  direct   | reflected | reflected2  | surround  |    each panel T x T, the view's whole frame
    +-----------+-----------+-------------+-----------+

A face seen in both views takes its coordinates in the view it is larger in
(more samples; the paper: always the reflected image's), and that panel's
texels under it become the mean of the two images' colours there weighted
by the face's share of each view's picture (its samples in each;
:data:`BOTH_WEIGHTING`): the colour that leaves the least squared error
over both pictures. The paper's rule is the plain average in the reflected
panel, which paints a sliver the eye barely sees half in the other
picture's colour however large it is in that picture (the dark specks of a
photograph's reflected picture across a direct one); and a slope seen
broadly on the saucer but as a sliver in the cup has almost no texels of
its own in the reflected panel, so it showed its reflected neighbours'
colours across the direct picture (specks of the other picture along the
round saucer's rings: 6.7 dB of astronaut-rocket's direct view). Faces no frame sees but the
design eye sees around them (:mod:`saucerfab.optimize.surround`) take the
background of the view they are seen in, from the last panel (stripes of
those colours; FaceView.SURROUND). Faces seen in neither keep their
direct-view projection (clamped to the panel); the fabrication bake gives
them a smooth continuation of their neighbours' colours.

With more eyes than the design eye (``--eyes both``, :class:`EyeViews`), the
texture keeps the design eye's layout (its panels and face coordinates) and
each texel under a face seen by the design eye becomes the weighted mean of
what every eye wants there: the design eye's panel colour (weight: its eye
weight) and, for every other eye and every view in which that eye sees the
face, that view's picture where the eye sees the texel's point on the
picture's decal (:mod:`saucerfab.optimize.viewpoints`), with that eye's weight.

Visibility (:func:`saucerfab.optimize.views.visible_faces`) is read from the
hard rasterizer's face buffer at ``supersample`` times the view's
resolution, so faces smaller than a pixel are not lost.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from saucerfab.model.design import FRAMED_VIEWS, FaceView
from saucerfab.optimize.targets import sample_bilinear
from saucerfab.optimize.views import Rig, visible_faces
from saucerfab.render.texels import raster_triangles_2d


@dataclass
class TextureResult:
    """Output of :func:`texture_saucer`.

    Attributes:
        texture: (T, K*T, 3) uint8, the panels side by side.
        face_uvs: (F, 3, 2) float32 per-corner UVs (u right, v up) into ``texture``.
        face_view: (F,) uint8 :class:`FaceView` per face.
        face_panel: (F,) int8, panel index each face samples (0 = direct).
    """

    texture: np.ndarray
    face_uvs: np.ndarray
    face_view: np.ndarray
    face_panel: np.ndarray


#: with more eyes: an eye's colour joins a texel's blend only where it differs from the design
#: eye's by at most this much (largest channel difference, colours in [0, 1]); where the eyes
#: disagree more, the design eye's colour stays. 1.0: every eye always joins (a plain weighted
#: mean); 0.0: the design eye's texture alone (the other eyes shape the relief only)
EYE_BLEND_MAX_DIFF = 1.0


@dataclass
class EyeViews:
    """A moved eye for :func:`texture_saucer`: its views and where each of its vertices shows the pictures.

    Attributes:
        weight: the eye's weight in the blend (:func:`saucerfab.model.eyes.eye_weights`).
        rig: the eye's views (:class:`~saucerfab.optimize.views.ViewMeshes` or a Rig).
        coords: view name -> (V', 2) NDC in the design eye's frame of that view, per vertex of the eye's
            view at the final heights (:func:`saucerfab.optimize.viewpoints.design_frame_ndc`).
    """

    weight: float
    rig: Any
    coords: dict[str, np.ndarray]


def classify_faces(visible: dict[str, np.ndarray]) -> np.ndarray:
    """(F,) uint8 FaceView from per-view visibility."""
    d = visible["direct"]
    r = np.zeros_like(d)
    for name, v in visible.items():
        if name != "direct":
            r |= v
    out = np.full(d.shape, FaceView.NEITHER, np.uint8)
    out[d & ~r] = FaceView.DIRECT
    out[r & ~d] = FaceView.REFLECTED
    out[d & r] = FaceView.BOTH
    return out


def _uv_from_ndc(ndc_xy: np.ndarray, panel: int, panels: int) -> np.ndarray:
    """NDC (..., 2) in a view frame -> atlas UV (u right, v up), clamped to the panel."""
    u = (panel + np.clip((ndc_xy[..., 0] + 1) / 2, 0, 1)) / panels
    v = np.clip((ndc_xy[..., 1] + 1) / 2, 0, 1)
    return np.stack([u, v], axis=-1)


def texture_saucer(
    rig: Rig,
    heights: np.ndarray,
    images: dict[str, np.ndarray],
    *,
    supersample: int = 2,
    eyes: list[EyeViews] | None = None,
    design_weight: float = 1.0,
    surround: list[tuple[np.ndarray, np.ndarray]] | None = None,
) -> TextureResult:
    """Texture the saucer with the input images (section 3.4.2).

    Args:
        heights: (N, N) final heights.
        images: view name -> (T, T, 3) float image in [0, 1] covering that
            view's frame (all the same T; may exceed the render size).
        eyes: the other eyes the design is made for (none: the paper's texturing).
        design_weight: the design eye's weight in the blend with ``eyes``.
        surround: the faces seen outside every frame, as (faces (F,) bool,
            colour (3,) in [0, 1]) pairs (:func:`saucerfab.optimize.surround.surround_faces`
            with each view's background): a face no frame sees takes its pair's
            colour (FaceView.SURROUND), from one more panel of the texture holding
            the colours side by side as stripes.
    """
    names = [v.name for v in rig.views]
    surround = [(np.asarray(m, bool), np.asarray(col, np.float64)) for m, col in (surround or [])]
    k = len(names) + (1 if surround else 0)
    t = images["direct"].shape[0]
    h = np.asarray(heights, np.float64).reshape(-1)
    samples = rig.face_samples(heights, supersample)
    visible = {name: n > 0 for name, n in samples.items()}
    face_view = classify_faces(visible)
    faces = rig.faces_np
    nf = faces.shape[0]

    direct = rig.view("direct")
    # every grid vertex (a disc's direct view takes only some): faces seen in neither view use it too
    ndc_d = direct.camera.project(rig.grid.vertices(h))[:, :2]
    uv_direct = _uv_from_ndc(ndc_d[faces], 0, k)  # (F, 3, 2)
    face_uvs = uv_direct.copy()
    face_panel = np.zeros(nf, np.int8)

    # float64 copies, clipped as they are made: each big array made once (first
    # touches of fresh memory cost ~10 us a page on the machines measured)
    panels = [np.clip(images[n], 0, 1, out=np.empty(images[n].shape, np.float64)) for n in names]
    # the reflected pictures as given, for faces seen in both that keep the direct panel (their
    # panels' texels change as faces blend into them)
    reflected_images = [None] + [np.clip(images[n], 0, 1).astype(np.float64) for n in names[1:]]
    for p, view in enumerate(rig.views[1:], start=1):
        if view.faces.shape[0] == 0:
            continue
        ndc_r = view.camera.project(view.vertices_np(h))[:, :2]
        src = view.face_src.numpy()
        uv_r = _uv_from_ndc(ndc_r[view.faces.numpy()], p, k)
        seen = visible[view.name][src]
        # Faces seen in both: the two images under the face blended by the face's samples,
        # in the panel of the view it is larger in (paper: always the reflected panel)
        both = seen & (face_view[src] == FaceView.BOTH)
        on_direct = both & _keeps_direct(samples["direct"][src], samples[view.name][src])
        use = src[seen & ~on_direct]
        face_uvs[use] = uv_r[seen & ~on_direct]
        face_panel[use] = p
        if both.any():
            w_d, w_r = _both_weights(samples["direct"][src], samples[view.name][src])
            tri_r = ndc_to_texel(ndc_r[view.faces.numpy()], t)
            tri_d = ndc_to_texel(ndc_d[faces[src]], t)
            on_r = both & ~on_direct
            _blend_both(panels[p], tri_r[on_r], tri_d[on_r], panels[0], w_r[on_r], w_d[on_r])
            _blend_both(panels[0], tri_d[on_direct], tri_r[on_direct], reflected_images[p], w_d[on_direct],
                        w_r[on_direct])
    if surround:  # the last panel, before the eyes' blend: its UVs are in k panels' units
        panels.append(_surround_panel(surround, face_uvs, face_panel, face_view, t, k))
    if eyes:  # (the surround's faces are not the frames': the blend leaves them)
        _blend_eyes(panels, face_uvs, face_panel, face_view, h, images, eyes, design_weight)
    # panel by panel, in place: the same values as clip(rint(concatenate(panels) * 255))
    # without three atlas-sized float64 temporaries (about 0.4 s of page faults at T = 1024)
    texture8 = np.empty((t, t * k, 3), np.uint8)
    for p, panel in enumerate(panels):
        panel *= 255
        np.rint(panel, out=panel)
        np.clip(panel, 0, 255, out=panel)
        texture8[:, p * t:(p + 1) * t] = panel
    return TextureResult(texture8, face_uvs.astype(np.float32), face_view, face_panel)


#: how a face seen in both views weighs them: "samples" (its share of each view's picture) or
#: "even" (the paper's plain average)
BOTH_WEIGHTING = "samples"


def _both_weights(direct: np.ndarray, reflected: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K,) float64 weights of the direct and reflected colours of K faces seen in both, from their samples."""
    if BOTH_WEIGHTING == "even":
        return np.ones(direct.shape), np.ones(reflected.shape)
    return direct.astype(np.float64), reflected.astype(np.float64)


def _keeps_direct(direct: np.ndarray, reflected: np.ndarray) -> np.ndarray:
    """(K,) bool: faces seen in both that keep their direct-panel coordinates: larger in the direct
    view's picture (more samples). A face's colour lives in its texels: a slope seen broadly
    on the saucer and as a sliver in the cup has almost no texels of its own in the reflected
    panel (none, often, under the sliver), so its colour there would be its reflected
    neighbours', seen across the direct picture as specks of the other picture."""
    if BOTH_WEIGHTING == "even":  # the paper's rule: always the reflected panel
        return np.zeros(direct.shape, bool)
    return direct > reflected


def _blend_both(
    panel: np.ndarray,
    tri_own: np.ndarray,
    tri_other: np.ndarray,
    other: np.ndarray,
    w_own: np.ndarray,
    w_other: np.ndarray,
) -> None:
    """Blend, in place, ``panel`` (T, T, 3)'s texels under K faces seen in both views with the other view's picture.

    Args:
        tri_own: (K, 3, 2) the faces' corners in ``panel`` (continuous texels).
        tri_other: (K, 3, 2) the same corners in ``other`` (T, T, 3), the other view's picture.
        w_own, w_other: (K,) the faces' weights of the two views (:func:`_both_weights`).
    """
    if not tri_own.shape[0]:
        return
    t = panel.shape[0]
    pix, ti, bary = raster_triangles_2d(tri_own, t, t)
    col = sample_bilinear(other, np.einsum("kc,kcd->kd", bary, tri_other[ti]))
    flat = panel.reshape(-1, 3)
    # a texel under several faces is blended once: the faces' mean weights, the other
    # colours' mean by their weights
    wo = np.bincount(pix, weights=w_other[ti], minlength=t * t)
    ws = np.bincount(pix, weights=w_own[ti], minlength=t * t)
    acc = np.stack([np.bincount(pix, weights=w_other[ti] * col[:, c], minlength=t * t) for c in range(3)], 1)
    hit = np.bincount(pix, minlength=t * t) > 0
    mean_o = acc[hit] / wo[hit, None]
    share_o = (wo[hit] / (wo[hit] + ws[hit]))[:, None]
    flat[hit] = (1.0 - share_o) * flat[hit] + share_o * mean_o


def _surround_panel(
    surround: list[tuple[np.ndarray, np.ndarray]],
    face_uvs: np.ndarray,
    face_panel: np.ndarray,
    face_view: np.ndarray,
    t: int,
    k: int,
) -> np.ndarray:
    """The last panel (T, T, 3) float64: one stripe of each surround colour; its faces pointed at their stripe's centre (in place).

    A face is marked SURROUND only where no frame sees it (``face_view`` NEITHER):
    the frames' texturing is never overridden.
    """
    panel = np.empty((t, t, 3), np.float64)
    p = k - 1
    n = len(surround)
    for i, (faces, colour) in enumerate(surround):
        lo, hi = (i * t) // n, ((i + 1) * t) // n
        panel[:, lo:hi] = np.clip(colour, 0.0, 1.0)
        mine = np.asarray(faces, bool) & (face_view == FaceView.NEITHER)
        face_uvs[mine] = ((p + (lo + hi) / 2 / t) / k, 0.5)  # every corner at the stripe's centre
        face_panel[mine] = p
        face_view[mine] = FaceView.SURROUND
    return panel


def _blend_eyes(
    panels: list[np.ndarray],
    face_uvs: np.ndarray,
    face_panel: np.ndarray,
    face_view: np.ndarray,
    h: np.ndarray,
    images: dict[str, np.ndarray],
    eyes: list[EyeViews],
    design_weight: float,
) -> None:
    """Blend, in place, each panel's texels under the design eye's seen faces with what the other eyes want."""
    k = len(panels)
    t = panels[0].shape[0]
    pictures = {n: np.clip(v, 0, 1).astype(np.float64) for n, v in images.items()}
    # per eye and view: visibility of the saucer faces, and saucer face -> the view's face
    seen_by = []
    for eye in eyes:
        vis = visible_faces(eye.rig, h.reshape(eye.rig.n, eye.rig.n))
        for view in eye.rig.views:
            fsrc = np.asarray(view.face_src)
            inv = np.full(face_panel.shape[0], -1, np.int64)
            inv[fsrc] = np.arange(fsrc.shape[0])
            seen_by.append((eye.weight, view, eye.coords[view.name], vis[view.name], inv))
    for p in range(k):
        on_p = np.flatnonzero((face_panel == p) & np.isin(face_view, FRAMED_VIEWS))
        if not on_p.size:
            continue
        uv = face_uvs[on_p].astype(np.float64)
        tri = np.stack([(uv[..., 0] * k - p) * t, (1.0 - uv[..., 1]) * t], axis=-1)
        pix, ti, bary = raster_triangles_2d(tri, t, t)
        if not pix.size:
            continue
        f = on_p[ti]
        flat = panels[p].reshape(-1, 3)
        num = design_weight * flat[pix]
        den = np.full(pix.shape[0], float(design_weight))
        for w, view, coords, vis, inv in seen_by:
            vf = inv[f]
            ok = (vf >= 0) & vis[f]
            if not ok.any():
                continue
            corners = coords[np.asarray(view.faces)[vf[ok]]]  # (K, 3, 2) design-frame NDC
            ndc = np.einsum("kc,kcd->kd", bary[ok], corners)
            col = sample_bilinear(pictures[view.name], ndc_to_texel(ndc, t))
            agree = np.abs(col - flat[pix[ok]]).max(axis=1) <= EYE_BLEND_MAX_DIFF
            idx = np.flatnonzero(ok)[agree]
            num[idx] += w * col[agree]
            den[idx] += w
        cnt = np.bincount(pix, weights=den, minlength=t * t)
        acc = np.stack([np.bincount(pix, weights=num[:, c], minlength=t * t) for c in range(3)], 1)
        hit = cnt > 0
        flat[hit] = acc[hit] / cnt[hit, None]


def ndc_to_texel(ndc_xy: np.ndarray, size: int) -> np.ndarray:
    """NDC (..., 2) -> continuous texel ``(column, row)`` in a size x size panel."""
    return np.stack([(ndc_xy[..., 0] + 1) * size / 2, (1 - ndc_xy[..., 1]) * size / 2], axis=-1)
