"""Colour: texture status and size, UVs inside [0, 1], texture dpi on the model, the coloured share.

Textures were already bounded and probed by the readers
(:class:`~saucerfab.check.meshdata.TextureInfo`); here their status becomes
findings and the UVs and faces say how well the colour covers the model.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from saucerfab.check.limits import Limits
from saucerfab.check.meshdata import MeshData
from saucerfab.check.places import fmt_pt, where
from saucerfab.check.report import Finding, finding

if TYPE_CHECKING:
    from saucerfab.model.profiles import PrinterProfile

_TEXTURE_CODES = {
    "missing": "texture_missing",
    "unreadable": "texture_unreadable",
    "too_large": "texture_too_large",
    "unsafe_path": "texture_path_unsafe",
}
_COLOUR_CAPABLE = {"3mf", "obj", "ply", "glb", "gltf", "wrl"}


def texture_status(md: MeshData, out: list[Finding]) -> None:
    """A finding for each texture the reader could not use (missing, unreadable, too large, unsafe path)."""
    for t in md.textures:
        if t.status != "ok":
            out.append(finding(_TEXTURE_CODES.get(t.status, "texture_unreadable"), t.message, where={"entry": t.name}))


def colour_checks(md: MeshData, areas: np.ndarray, Fo: np.ndarray, centroids: np.ndarray,
                   profile: PrinterProfile | None, limits: Limits, out: list[Finding], stats: dict[str, Any]) -> None:
    """Textures, UVs, texture dpi and the coloured share of the surface.

    Args:
        areas: (F,) face areas, mm2; ``Fo`` (F, 3) the file's faces; ``centroids`` (F, 3), mm.
    """
    texture_status(md, out)
    if profile is not None and profile.max_texture_px:
        for t in md.textures:
            if t.status == "ok" and max(t.width or 0, t.height or 0) > profile.max_texture_px:
                out.append(finding(
                    "texture_too_large",
                    f"texture {t.name!r} is {t.width} x {t.height} px, over {profile.name}'s limit of "
                    f"{profile.max_texture_px} px a side; downscale it",
                    where={"entry": t.name},
                ))
    m = len(Fo)
    total = float(areas.sum())
    coloured = np.zeros(m, dtype=bool) if md.face_colour is None else md.face_colour.copy()
    if md.face_texture is not None and md.corner_uv is not None:
        textured = md.face_texture >= 0
        coloured |= textured
        uv = md.corner_uv[textured]
        tol = limits.uv_tolerance
        bad = ~np.isfinite(uv).all(axis=(1, 2)) | ((uv < -tol) | (uv > 1 + tol)).any(axis=(1, 2))
        tidx = np.flatnonzero(textured)
        stats["uv_outside_faces"] = int(bad.sum())
        if bad.any():
            fb = tidx[bad]
            finite_uv = uv[np.isfinite(uv).all(axis=(1, 2))]
            rng = (f" (u, v range {finite_uv[..., 0].min():.3g}..{finite_uv[..., 0].max():.3g}, "
                   f"{finite_uv[..., 1].min():.3g}..{finite_uv[..., 1].max():.3g})") if len(finite_uv) else ""
            out.append(finding(
                "uv_out_of_range",
                f"{len(fb):,} textured faces have texture coordinates outside [0, 1]{rng}: printers clamp or "
                f"wrap them differently, so the colour would be wrong; first near {fmt_pt(centroids[fb[0]])}",
                where=where(centroids[fb[0]], fb, count=len(fb)),
            ))
        _texture_dpi(md, areas, textured, profile, limits, out, stats)
    if total > 0:
        frac = float(areas[coloured].sum()) / total
    else:  # no face has area (all degenerate, reported above): the share of faces instead
        frac = float(coloured.mean()) if m else 0.0
    stats["coloured_fraction"] = round(frac, 5)
    if not md.colour_kinds:
        if md.format in _COLOUR_CAPABLE or profile is not None:
            out.append(finding("no_colour", f"the {md.format.upper()} carries no colour (no texture, vertex or "
                                            "material colours): it prints in the printer's default colour"))
    elif frac < 0.999 and (~coloured).any():
        un = np.flatnonzero(~coloured)
        out.append(finding(
            "partly_coloured",
            f"only {100 * frac:.1f}% of the surface carries colour; the rest prints in the default colour, "
            f"first uncoloured face near {fmt_pt(centroids[un[0]])}",
            where=where(centroids[un[0]], un, count=len(un)),
        ))


def _texture_dpi(md: MeshData, areas: np.ndarray, textured: np.ndarray, profile: PrinterProfile | None,
                 limits: Limits, out: list[Finding], stats: dict[str, Any]) -> None:
    """Texture resolution on the model: texels per inch, area-weighted median over textured faces."""
    assert md.corner_uv is not None and md.face_texture is not None
    ok_tex = np.array([t.status == "ok" and t.width and t.height for t in md.textures] + [False], dtype=bool)
    wh = np.array([[t.width or 0, t.height or 0] for t in md.textures] + [[0, 0]], dtype=np.float64)
    ti = md.face_texture
    sel = textured & ok_tex[ti] & (areas > 0)
    uv = md.corner_uv[sel]
    fin = np.isfinite(uv).all(axis=(1, 2))
    if not fin.any():
        return
    uv = uv[fin]
    idx = np.flatnonzero(sel)[fin]
    px = uv * wh[ti[idx]][:, None, :]
    e1, e2 = px[:, 1] - px[:, 0], px[:, 2] - px[:, 0]
    texel_area = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) / 2
    a = areas[idx]
    dpi = 25.4 * np.sqrt(texel_area / a)

    def weighted_quantile(values: np.ndarray, weights: np.ndarray, q: float) -> float:
        order = np.argsort(values)
        cum = np.cumsum(weights[order])
        return float(values[order][min(np.searchsorted(cum, q * cum[-1]), len(order) - 1)])

    # Leave out faces mapped at a deliberately tiny scale (plain walls an
    # exporter parks on a small patch): they need no resolution. The header
    # is all the checker decodes, so density is the only clue it has.
    best = weighted_quantile(dpi, a, 0.95)
    detailed = dpi >= limits.solid_colour_density * best
    med = weighted_quantile(dpi[detailed], a[detailed], 0.5)
    stats["texture_detailed_fraction"] = round(float(a[detailed].sum() / max(a.sum(), 1e-300)), 4)
    stats["texture_dpi"] = round(med, 1)
    if profile is not None:
        want = limits.texture_dpi_fraction * profile.dpi
        if med < want:
            out.append(finding(
                "texture_low_dpi",
                f"the texture gives {med:.0f} dpi on the model (area-weighted median over the detailed "
                f"faces), under "
                f"{limits.texture_dpi_fraction:g} x {profile.name}'s {profile.dpi:g} dpi; colours will look soft",
            ))
