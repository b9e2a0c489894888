"""Colour bleed (issue 45): how much the J55's bleed costs the texture, and what its compensation wins back.

    .venv/bin/python benchmarks/bench_bleed.py                              # heart-star and fish-moon
    .venv/bin/python benchmarks/bench_bleed.py --designs DIR --pictures OUT # reuse DIR/<pair>, save crops

For each graphic pair: ``saucerfab design --direct ... --reflected ...`` (defaults; made once and kept
in ``--designs``), exported for the J55 with ``--bleed-compensation off`` and ``on``. The pages are
read back from the written 3MF files. Printed, per pair:

* the blur: the profile's ``colour_bleed_mm``, the top's texels per mm (area mean, and the least and
  most along x and y: what the one width in texels gets wrong) and sigma in texels;
* texture-space PSNR (dB, sRGB in [0, 1]) of the page as it prints (:func:`bleed_page`) against the
  intended page, over all the top's texels and over the texels some view sees: uncompensated,
  compensated as exported (projected gradient, 8-bit), and the Wiener filter for comparison;
* the verify render's scale: each view's verify pixels per mm (the square frame at ``--res``, from the
  design's texture coordinates), sigma in verify pixels at 256 and 1024 px, and the same PSNRs with the
  top box-filtered to the direct view's pixel size (a stand-in for a render: no perspective, no mirror);
* thin ridges: texels of one picture (DIRECT faces) or the other (REFLECTED) where the band they lie in,
  between texels of the other picture, is narrower than 2 sigma; how many such bands and faces.

Nothing here renders; ``saucerfab verify`` is not run.
"""

from __future__ import annotations

import argparse
import io
import math
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from saucerfab.fabricate.atlas import (  # noqa: E402
    TOP_SHARE,
    AtlasLayout,
    Rect,
    layout_page,
    surface_density,
)
from saucerfab.fabricate.bake import bake_top, locate_columns, locate_rows  # noqa: E402
from saucerfab.fabricate.bleed import bleed_page, compensate_bleed, top_px_per_mm  # noqa: E402
from saucerfab.fabricate.options import FabOptions  # noqa: E402
from saucerfab.fabricate.pipeline import export_design  # noqa: E402
from saucerfab.fabricate.solid import build_solid  # noqa: E402
from saucerfab.model.design import Design, FaceView  # noqa: E402
from saucerfab.model.design_folder import load_design  # noqa: E402
from saucerfab.model.profiles import load_profile  # noqa: E402
from saucerfab.samples import GRAPHIC_PAIRS, pair_paths  # noqa: E402

PRINTER = "j55"
VERIFY_RES = (256, 1024)


def psnr(a: np.ndarray, b: np.ndarray, mask: np.ndarray | None = None) -> float:
    """PSNR (dB) of two (h, w, 3) images in [0, 1] over ``mask`` (h, w) (None: all)."""
    d = (np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2
    mse = float(d.mean()) if mask is None else float(d[mask].mean())
    return 10.0 * math.log10(1.0 / max(mse, 1e-12))


def atlas_page(folder: Path) -> np.ndarray:
    """The (S, S, 3) uint8 page inside ``folder/saucer.3mf``."""
    from PIL import Image

    with zipfile.ZipFile(folder / "saucer.3mf") as z:
        name = next(n for n in z.namelist() if n.lower().endswith(".png"))
        return np.asarray(Image.open(io.BytesIO(z.read(name))).convert("RGB"))


def export_layout(design: Design) -> tuple[AtlasLayout, np.ndarray, np.ndarray, np.ndarray]:
    """The export's page layout for the J55, as :func:`export_design` makes it; and the top's grid (mm)."""
    profile = load_profile(PRINTER)
    solid = build_solid(design, design.scene.mm_per_unit, FabOptions(), profile)
    (x0, x1), (y0, y1) = solid.footprint
    size = profile.texture_px_for(max(x1 - x0, y1 - y0) / TOP_SHARE)
    layout = layout_page(size, FabOptions().padding_px, solid.grid_x, solid.grid_y, solid.heights)
    return layout, solid.grid_x, solid.grid_y, solid.heights


def texel_faces(design: Design, layout: AtlasLayout) -> np.ndarray:
    """(h, w) int64: the design face under each texel of the top (the bake's own rule)."""
    j, fx = locate_columns(layout)
    i, fy = locate_rows(layout)
    k = i[:, None] * (design.n - 1) + j[None, :]
    return 2 * k + (fy[:, None] > fx[None, :])


def view_px_per_mm(design: Design, view: FaceView, res: int) -> float:
    """Verify pixels per mm of surface for the faces of ``view``: ``res`` across the view's square frame.

    The design's texture holds one square tile per picture side by side (u), so a face's texture
    coordinates, scaled by the tiles' count in u, are its frame coordinates; the ratio of the faces'
    frame area to their surface area gives the frame's units per mm.
    """
    faces = np.flatnonzero(design.face_view == view)
    tiles = design.texture.shape[1] / design.texture.shape[0]
    uv = np.asarray(design.face_uvs[faces], np.float64) * np.array([tiles, 1.0])
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    frame_area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    v = design.vertices() * design.scene.mm_per_unit
    tri = v[design.faces()[faces]]
    surface = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
    return res * math.sqrt(frame_area / surface)


def box_down(img: np.ndarray, factor: float) -> np.ndarray:
    """(h, w, 3) float image box-filtered to ``1 / factor`` of its size (PIL's BOX, per channel)."""
    from PIL import Image

    h, w = img.shape[:2]
    size = (max(1, round(w / factor)), max(1, round(h / factor)))
    return np.stack([np.asarray(Image.fromarray(np.ascontiguousarray(img[..., c], np.float32), "F")
                                .resize(size, Image.Resampling.BOX)) for c in range(3)], axis=2)


def thin_ridges(design: Design, layout: AtlasLayout, px_per_mm: float, sigma_mm: float) -> dict[str, float]:
    """Bands of one picture narrower than 2 sigma between texels of the other (see the module's docstring)."""
    from scipy import ndimage

    view = design.face_view[texel_faces(design, layout)]
    direct, reflected = view == FaceView.DIRECT, view == FaceView.REFLECTED
    sig_px = sigma_mm * px_per_mm
    out: dict[str, float] = {"boundary_texels_within_sigma": 0.0}
    thin_total = np.zeros(view.shape, bool)
    for mine, other in ((direct, reflected), (reflected, direct)):
        if not other.any():
            continue
        d_other = ndimage.distance_transform_edt(~other)  # texels to the other picture
        near = mine & (d_other < sig_px)
        out["boundary_texels_within_sigma"] += float(near.sum())
        # in a band of width W between texels of the other picture no texel is farther than W/2 from it:
        # a texel is in a thin band when nothing within 2 sigma around it is farther than sigma
        far = ndimage.maximum_filter(np.where(mine, d_other, 0.0), size=int(2 * math.ceil(2 * sig_px)) + 1)
        thin_total |= mine & (far < sig_px)
    seen = direct | reflected
    _labels, bands = ndimage.label(thin_total)
    faces = np.unique(texel_faces(design, layout)[thin_total])
    out.update({
        "picture_texels": float(seen.sum()),
        "share_within_sigma_of_other": out["boundary_texels_within_sigma"] / max(float(seen.sum()), 1.0),
        "thin_bands": float(bands),
        "thin_texels": float(thin_total.sum()),
        "thin_faces": float(faces.size),
    })
    return out


def crops(path: Path, images: list[np.ndarray], centre: tuple[int, int], half: int = 60, zoom: int = 3) -> None:
    """One PNG: the same crop of each (h, w, 3) [0, 1] image, side by side, enlarged ``zoom`` times (nearest)."""
    from PIL import Image

    r, c = centre
    tiles = []
    for img in images:
        crop = img[max(r - half, 0):r + half, max(c - half, 0):c + half]
        crop = np.repeat(np.repeat(crop, zoom, axis=0), zoom, axis=1)
        tiles.append(np.pad(crop, ((0, 0), (0, 6), (0, 0)), constant_values=1.0))
    Image.fromarray(np.clip(np.rint(np.concatenate(tiles, axis=1) * 255), 0, 255).astype(np.uint8)).save(path)


def bench_pair(pair: str, designs: Path, tmp: Path, pictures: Path | None) -> None:
    folder = designs / pair
    if not (folder / "design.json").is_file():
        direct, reflected = pair_paths(pair)
        t = time.perf_counter()
        subprocess.run([sys.executable, "-m", "saucerfab", "design", "--direct", str(direct), "--reflected",
                        str(reflected), "-o", str(folder), "--force", "--no-verify", "-q"], cwd=ROOT, check=True)
        print(f"  designed in {time.perf_counter() - t:.0f} s")
    design = load_design(folder)
    profile = load_profile(PRINTER)
    pages, secs = {}, {}
    for mode in ("off", "on"):
        t = time.perf_counter()
        res = export_design(design, tmp / f"{pair}-{mode}", printer=PRINTER,
                            options=FabOptions(bleed_compensation=mode))
        secs[mode] = time.perf_counter() - t
        pages[mode] = atlas_page(res.out)
        if mode == "on":
            secs["bleed"] = res.timings.get("bleed", 0.0)
    layout, xs, ys, hs = export_layout(design)
    top = layout.top
    ppm = top_px_per_mm(layout, xs, ys, hs)
    dens_x, dens_y = surface_density(hs, xs, ys)
    k_x = top.w / float(np.sum(dens_x * np.diff(xs)))
    k_y = top.h / float(np.sum(dens_y * np.diff(ys)))
    sigma = profile.colour_bleed_mm
    print(f"  export off {secs['off']:.1f} s, on {secs['on']:.1f} s (compensation {secs['bleed']:.1f} s); "
          f"page {layout.size} px, top {top.w} x {top.h}")
    # least texels per mm of surface (a column's steepest face) along x and y; a flat face in a steep column
    # gets up to the column's density ratio more
    print(f"  sigma {sigma} mm; top {ppm:.2f} texels/mm (area mean; least along x {k_x:.2f}, y {k_y:.2f}; "
          f"most {k_x * dens_x.max():.1f}, {k_y * dens_y.max():.1f}) -> sigma {sigma * ppm:.2f} texels")

    def region(page: np.ndarray) -> np.ndarray:
        return page[top.y:top.y + top.h, top.x:top.x + top.w].astype(np.float32) / 255.0

    chart = [Rect(0, 0, top.w, top.h)]
    want = region(pages["off"])
    t = time.perf_counter()
    wiener = compensate_bleed(want, chart, ppm, sigma, method="wiener")
    wiener = np.rint(wiener * 255) / 255  # 8 bits, as exported
    t_w = time.perf_counter() - t
    printed = {"uncompensated": bleed_page(want, chart, ppm, sigma),
               "compensated": bleed_page(region(pages["on"]), chart, ppm, sigma),
               "wiener": bleed_page(wiener.astype(np.float32), chart, ppm, sigma)}
    _rgb, known = bake_top(design, layout)
    seen = known
    print(f"  texture space PSNR dB (all top texels / seen {seen.mean() * 100:.0f}%):")
    for name, img in printed.items():
        print(f"    {name:14s} {psnr(img, want):6.2f} / {psnr(img, want, seen):6.2f}")
    print(f"    (wiener took {t_w:.1f} s)")
    print("  verify scale:")
    for view in (FaceView.DIRECT, FaceView.REFLECTED):
        vpm = [view_px_per_mm(design, view, r) for r in VERIFY_RES]
        print(f"    {view.name.lower():9s} " + "; ".join(
            f"--res {r}: {v:.2f} px/mm, sigma {sigma * v:.2f} px" for r, v in zip(VERIFY_RES, vpm)))
    for r in VERIFY_RES:
        factor = ppm / view_px_per_mm(design, FaceView.DIRECT, r)
        small = box_down(want, factor)
        row = ", ".join(f"{n} {psnr(box_down(img, factor), small):.2f}" for n, img in printed.items())
        print(f"    top box-filtered to the direct view's pixel at --res {r} (1/{factor:.1f}): {row}")
    ridges = thin_ridges(design, layout, ppm, sigma)
    print(f"  thin ridges: {int(ridges['thin_bands'])} bands narrower than 2 sigma ({int(ridges['thin_texels'])} "
          f"texels, {int(ridges['thin_faces'])} faces); {ridges['share_within_sigma_of_other'] * 100:.1f}% of the "
          "pictures' texels lie within sigma of the other picture")
    if pictures is not None:
        pictures.mkdir(parents=True, exist_ok=True)
        err = np.abs(printed["uncompensated"] - want).sum(axis=2)
        err[~seen] = 0
        centre = np.unravel_index(int(np.argmax(ndimage_smooth(err))), err.shape)
        crops(pictures / f"{pair}_crops.png",
              [want, printed["uncompensated"], region(pages["on"]), printed["compensated"]],
              (int(centre[0]), int(centre[1])))
        print(f"  crops (intended | as printed | compensated page | compensated as printed) at texel {centre}: "
              f"{pictures / f'{pair}_crops.png'}")


def ndimage_smooth(a: np.ndarray) -> np.ndarray:
    """A 41-texel box mean of ``a``: where the error is large over an area, not at one texel."""
    from scipy import ndimage

    return ndimage.uniform_filter(a, 41)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pairs", default="heart-star,fish-moon", help=f"comma-separated: {', '.join(GRAPHIC_PAIRS)}")
    p.add_argument("--designs", type=Path, default=None,
                   help="folder of the designs (DIR/<pair>), made there when missing; default: a temporary one")
    p.add_argument("--pictures", type=Path, default=None, help="write crops of the pages here")
    args = p.parse_args()
    with tempfile.TemporaryDirectory(prefix="saucerfab-bleed-") as tmp_s:
        tmp = Path(tmp_s)
        designs = args.designs or tmp / "designs"
        for pair in args.pairs.split(","):
            print(f"{pair}:")
            bench_pair(pair, designs, tmp, args.pictures)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
