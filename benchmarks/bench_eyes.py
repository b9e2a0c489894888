"""What any print can score from a moved eye under the whole-picture-shift score (issue 19).

    .venv/bin/python benchmarks/bench_eyes.py                  # the graphic pairs
    .venv/bin/python benchmarks/bench_eyes.py --pairs all

No optimisation and no export: for each pair (the default design's scene,
frames fitted as ``saucerfab design`` fits them) and each of a viewer's two
eyes, the picture each view shows that eye is computed for two prints, and
scored against the reference as ``saucerfab verify`` scored a moved eye
before the flat print (``saucerfab.verify/1``; now its ``psnr_shift_db``:
256 px, best integer whole-picture shift within 10 % of the frame). This
measurement is why verify/2 scores a moved eye against the flat print:

* **flat decal**: the ideal print for every eye at once if the saucer were
  flat: each picture lying on the saucer's mean plane as the design eye
  sees it (:func:`saucerfab.optimize.viewpoints.decal_images`);
* **on the relief**: the picture painted onto the base shape's relief from
  the design eye (what the paper's texturing does), seen from the moved eye.

It also prints how the picture moves across the frame from that eye: the
horizontal shift of the decal at the top, middle and bottom rows (px at
256), and the relief's parallax against the decal (median / 99th
percentile, px): what a whole-picture shift cannot undo.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from saucerfab.samples import GRAPHIC_PAIRS, PAIRS, PHOTO_PAIRS, SAMPLES  # noqa: E402

RES = 256


def _seen(view, heights, coords: np.ndarray, size: int):  # type: ignore[no-untyped-def]
    """Per pixel of ``view`` at ``size``: hit mask and the design-frame pixel (column, row) each pixel shows."""
    from saucerfab.render import rasterize_hard

    faces = np.asarray(view.faces)
    fid, bary, _ = rasterize_hard(view.vertices_np(heights), faces, view.camera.with_size(size))
    hit = fid >= 0
    ndc = np.einsum("kc,kcd->kd", bary[hit], coords[faces[fid[hit]]])
    return hit, np.stack([(ndc[:, 0] + 1) * size / 2, (1 - ndc[:, 1]) * size / 2], axis=-1)


def run_pair(pair: str) -> list[dict]:
    from saucerfab.optimize.prepare import prepare
    from saucerfab.optimize.request import DesignRequest
    from saucerfab.optimize.targets import sample_bilinear
    from saucerfab.optimize.viewpoints import decal_height, design_frame_ndc, eye_rigs
    from saucerfab.verify.core import MAX_SHIFT_FRACTION, resize_box
    from saucerfab.verify.metrics import best_shift

    direct, reflected = PAIRS[pair]
    req = DesignRequest(SAMPLES / direct, SAMPLES / reflected, eyes="both")
    prep = prepare(req)
    base = prep.base
    eyes = eye_rigs(prep.scene, base, req.eye_spec())
    z0 = decal_height(base)
    rows = []
    for eye in eyes[1:]:
        for view in eye.rig.views:
            ref = resize_box(prep.texture[view.name], RES)
            dview = eyes[0].rig.view(view.name)
            own = np.full((base.size, 2), np.nan)
            own[np.asarray(dview.vert_src)] = dview.camera.project(dview.vertices_np(base))[:, :2]
            row = {"pair": pair, "eye": eye.eye.name, "view": view.name}
            pics = {}
            for label, coords in (("decal", design_frame_ndc(prep.scene, eye.scene, view, base, z0)),
                                  ("relief", own[np.asarray(view.vert_src)])):
                hit, px = _seen(view, base, coords, RES)
                ok = np.isfinite(px).all(axis=1) & (px >= 0).all(axis=1) & (px < RES).all(axis=1)
                img = np.ones((RES, RES, 3), np.float32)
                t = prep.texture[view.name].shape[0]
                vals = np.ones((hit.sum(), 3))
                vals[ok] = sample_bilinear(prep.texture[view.name], px[ok] * (t / RES))
                img[hit] = vals
                region = hit.copy()
                region[hit] = ok
                sh = best_shift(img, ref, region, round(MAX_SHIFT_FRACTION * RES))
                row[label] = sh.psnr_db
                row[label + "_shift"] = (sh.dx, sh.dy)
                pics[label] = (hit, px, ok)
            hit, px, ok = pics["decal"]
            r_idx, c_idx = np.nonzero(hit)
            dx = px[:, 0] - (c_idx + 0.5)
            bands = [np.median(dx[ok & (r_idx >= a) & (r_idx < a + 16)]) for a in (8, RES // 2 - 8, RES - 24)]
            row["shift_top_mid_bottom"] = [round(float(b), 1) for b in bands]
            _, px_r, ok_r = pics["relief"]
            both = ok & ok_r
            d = np.linalg.norm(px_r[both] - px[both], axis=1)
            row["relief_parallax_px"] = (float(np.median(d)), float(np.percentile(d, 99)))
            rows.append(row)
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pairs", default="graphics", help="comma-separated, or graphics, photos, all")
    args = ap.parse_args()
    named = {"graphics": list(GRAPHIC_PAIRS), "photos": list(PHOTO_PAIRS), "all": list(PAIRS)}
    pairs = named.get(args.pairs) or args.pairs.split(",")
    print("| pair | eye | view | flat decal dB (shift) | on the relief dB (shift) | decal's x-shift top / mid / bottom px "
          "| relief parallax median / p99 px |")
    print("|---|---|---|---|---|---|---|")
    for pair in pairs:
        for r in run_pair(pair):
            top, mid, bot = r["shift_top_mid_bottom"]
            print(f"| {r['pair']} | {r['eye']} | {r['view']} | {r['decal']:.1f} ({r['decal_shift'][0]:+d},"
                  f"{r['decal_shift'][1]:+d}) | {r['relief']:.1f} ({r['relief_shift'][0]:+d},{r['relief_shift'][1]:+d}) "
                  f"| {top:+.1f} / {mid:+.1f} / {bot:+.1f} | {r['relief_parallax_px'][0]:.2f} / "
                  f"{r['relief_parallax_px'][1]:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


def decal_scores(design_dir: Path, renders: dict, res: int, max_shift: int = 2) -> dict[str, dict]:
    """Each moved eye's verify render against what a print lying flat would show that eye (the decal).

    ``renders``: :attr:`saucerfab.verify.VerifyResult.renders` of the design's export (``(eye, view)`` ->
    rgb, ``(eye, view + ":region")`` -> the pixels verify compared). The decal is the design's
    reference picture on the saucer's mean plane, seen from the eye
    (:func:`saucerfab.optimize.viewpoints.decal_images`): where the perspective of a tilted saucer
    moves the picture, the decal moves with it, so what is left is what the print adds: the
    relief's parallax, the texture, the conflicts. Scored over the pixels verify compared, after the best integer shift within ``max_shift`` px (rounding of the eye's frame).

    Returns ``"view/eye"`` -> ``{"psnr_db", "shift_px"}``.
    """
    from saucerfab.model.design_folder import load_design
    from saucerfab.model.eyes import EyeSpec
    from saucerfab.optimize.viewpoints import decal_height, decal_images, eye_rigs
    from saucerfab.verify.metrics import best_shift

    d = load_design(design_dir)
    eyes = eye_rigs(d.scene, d.heights, EyeSpec("both"))
    pictures = {k: v.astype(np.float64) / 255.0 for k, v in d.references.items()}
    out = {}
    for eye in eyes[1:]:
        decal = decal_images(d.scene, eye, d.heights, pictures, decal_height(d.base_heights), size=res)
        for view in eye.rig.views:
            rgb = renders.get((eye.eye.name, view.name))
            if rgb is None:
                continue
            region = renders[(eye.eye.name, view.name + ":region")]
            sh = best_shift(np.asarray(rgb, np.float32), decal[view.name].astype(np.float32), region, max_shift)
            out[f"{view.name}/{eye.eye.name}"] = {"psnr_db": sh.psnr_db, "shift_px": [sh.dx, sh.dy]}
    return out
