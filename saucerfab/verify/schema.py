"""JSON Schema of ``saucerfab verify --json`` (``saucerfab.verify/3``); ``saucerfab verify --schema`` prints it.

``light`` and ``lit_views`` (issue 45) are optional: a verify under a real light (``--light room`` or
``lamp:...``) writes them, the emitted verify (the default) does not, so its document is the same as
before and the version stays ``/3``.
"""

from __future__ import annotations

from typing import Any

_NUM_OR_NULL = {"type": ["number", "null"]}

VIEW_SCORE: dict[str, Any] = {
    "type": "object",
    "required": ["view", "eye", "psnr_db", "psnr_unshifted_db", "ssim", "coverage", "pixels", "shift_px", "passed",
                 "reference", "psnr_shift_db"],
    "properties": {
        "view": {"enum": ["direct", "reflected", "reflected2"]},
        "eye": {"type": "string", "description": "design, left, right or box(+R,+U) (mm right, up of the design eye)"},
        "psnr_db": {**_NUM_OR_NULL, "description": "PSNR against `reference`; null when no pixel of the view shows the saucer"},
        "psnr_unshifted_db": {**_NUM_OR_NULL, "description": "PSNR against the reference picture, unshifted"},
        "reference": {"enum": ["picture", "flat print"],
                      "description": "picture: the reference picture (the design eye); flat print: the picture lying flat "
                                     "on the saucer, placed for the design eye, seen from this eye (a moved eye)"},
        "psnr_shift_db": {**_NUM_OR_NULL, "description": "a moved eye: PSNR against the reference picture after the best "
                                                         "whole-picture shift (`shift_px`); null from the design eye"},
        "ssim": _NUM_OR_NULL,
        "coverage": {"type": "number", "minimum": 0, "maximum": 1,
                     "description": "share of the picture's rectangle in the view's frame (its extent) where the saucer is seen (directly / in the mirror)"},
        "pixels": {"type": "integer", "minimum": 0, "description": "pixels compared (seen fully)"},
        "shift_px": {"type": "array", "items": {"type": "integer"}, "minItems": 2, "maxItems": 2,
                     "description": "reference picture moved right, down for psnr_shift_db, pixels"},
        "passed": {"type": "boolean"},
        "picture": {"type": ["string", "null"], "description": "side-by-side picture, relative to the pictures folder"},
    },
}

_SHARE_OR_NULL = {"type": ["number", "null"], "minimum": 0}

WHOLE_VIEW_SCORE: dict[str, Any] = {
    "type": "object",
    "required": ["eye", "psnr_db", "stray_direct", "stray_reflected", "width_share", "pixels", "surround_pixels",
                 "passed", "picture"],
    "properties": {
        "eye": {"type": "string"},
        "psnr_db": {**_NUM_OR_NULL, "description": "PSNR of everything the eye sees of the saucer against the ideal "
                                                   "whole view (each picture in its frame, its background elsewhere)"},
        "stray_direct": {**_SHARE_OR_NULL, "maximum": 1,
                         "description": "share of the saucer seen directly outside the direct frame whose colour is "
                                        "farther than 0.25 (sRGB, Euclidean) from the direct picture's background"},
        "stray_reflected": {**_SHARE_OR_NULL, "maximum": 1,
                            "description": "the same for the mirror's image of the saucer outside the reflected frame"},
        "width_share": {**_SHARE_OR_NULL, "description": "the reflected picture's width over the cup's visible width"},
        "pixels": {"type": "integer", "minimum": 0, "description": "pixels that see the saucer's top (scored)"},
        "surround_pixels": {"type": "array", "items": {"type": "integer", "minimum": 0}, "minItems": 2, "maxItems": 2,
                            "description": "pixels of the direct surround and of the mirror's surround"},
        "passed": {"type": "boolean", "description": "both stray shares at most max_stray"},
        "picture": {"type": ["string", "null"], "description": "whole view, ideal and stray map, relative to the pictures folder"},
    },
}

_RGB = {"type": "array", "items": {"type": ["number", "null"]}, "minItems": 3, "maxItems": 3}

LIT_VIEW_SCORE: dict[str, Any] = {
    "type": "object",
    "required": ["view", "eye", "lit_psnr_db", "gain_rgb", "white_level", "shading_pattern_db", "shading_p5", "shading_p95",
                 "flat_pattern_db", "flat_p5", "flat_p95", "pixels", "picture"],
    "properties": {
        "view": {"enum": ["direct", "reflected", "reflected2"]},
        "eye": {"type": "string"},
        "lit_psnr_db": {**_NUM_OR_NULL, "description": "PSNR of the lit render against the reference lit by the light's "
                                                       "smooth part (one best gain per channel), same pixels as psnr_db"},
        "flat_print_lit_psnr_db": {**_NUM_OR_NULL, "description": "the same score of a flat plate printed with the "
                                                                  "view's reference under the same light: what a print "
                                                                  "without relief reaches (absent from older documents)"},
        "against_flat_print_psnr_db": {**_NUM_OR_NULL, "description": "PSNR of the lit render against the flat "
                                                                      "print's, both under the light, no gain: how far "
                                                                      "the relief makes the print look from a flat one "
                                                                      "(absent from older documents)"},
        "gain_rgb": {**_RGB, "description": "that gain per channel: the plastic against the texture (about 0.8-1)"},
        "white_level": {**_NUM_OR_NULL, "description": "mean of the white render over the compared pixels: how bright "
                                                       "a white print looks in this view (the cup's metal darkens "
                                                       "the reflected views)"},
        "shading_pattern_db": {**_NUM_OR_NULL, "description": "PSNR of 0.5 * white / smooth against 0.5: the relief's "
                                                              "own shading on a mid-grey picture (99: none above the noise)"},
        "shading_p5": _NUM_OR_NULL,
        "shading_p95": {**_NUM_OR_NULL, "description": "5th and 95th percentiles of white / smooth, the noise taken out"},
        "flat_pattern_db": {**_NUM_OR_NULL, "description": "the same for a flat plate at the top's mean height"},
        "flat_p5": _NUM_OR_NULL,
        "flat_p95": _NUM_OR_NULL,
        "pixels": {"type": "integer", "minimum": 0},
        "picture": {"type": ["string", "null"], "description": "lit view, reference under the smooth light, "
                                                                "shading alone, the flat print lit"},
    },
}

LIGHT: dict[str, Any] = {
    "type": "object",
    "required": ["kind", "lamp", "ambient", "cup_metal", "plastic", "integrator", "smooth_sigma_px"],
    "properties": {
        "kind": {"enum": ["room", "lamp"]},
        "lamp": {"type": ["object", "null"], "required": ["xyz_mm", "size_mm", "power"],
                 "description": "a square lamp facing the cup's foot; xyz_mm from the cup's foot: x to the viewer's "
                                "right, y towards the viewer, z up; power: a white paper at the cup's foot reads it"},
        "ambient": {"type": "number", "minimum": 0, "description": "the room's uniform radiance (a white paper reads it)"},
        "cup_metal": {"type": "object", "required": ["name", "n_rgb", "k_rgb", "reflectance_rgb", "source"]},
        "plastic": {"type": "object", "required": ["bsdf", "alpha", "ior"]},
        "integrator": {"type": "object", "required": ["type", "max_depth"]},
        "smooth_sigma_px": {"type": "number", "description": "the smooth part's Gaussian, pixels"},
        "seconds": {"type": "number"},
    },
}

JSON_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "saucerfab verify report",
    "type": "object",
    "required": ["schema", "saucerfab_version", "folder", "renderer", "res", "spp", "min_psnr_db", "min_coverage",
                 "passed", "exit_code", "eyes", "where_to_stand", "files", "max_stray", "whole_views"],
    "properties": {
        "schema": {"const": "saucerfab.verify/3"},
        "saucerfab_version": {"type": "string"},
        "folder": {"type": "string"},
        "renderer": {"type": "object", "required": ["name", "version", "variant", "integrator"]},
        "res": {"type": "integer", "description": "render size, pixels per side"},
        "spp": {"type": "integer", "description": "samples per pixel"},
        "min_psnr_db": {"type": "number"},
        "min_coverage": {"type": "number"},
        "passed": {"type": "boolean", "description": "every view of every file from every eye passed, and every whole view"},
        "max_stray": {**_NUM_OR_NULL, "description": "the highest stray share a whole view passes with"},
        "whole_views": {"type": "array", "items": WHOLE_VIEW_SCORE,
                        "description": "the primary file's whole view from each eye (/3)"},
        "exit_code": {"enum": [0, 1]},
        "eyes": {
            "type": "array",
            "items": {
                "type": "object",
                "required": ["name", "position_mm", "offset_mm"],
                "properties": {
                    "name": {"type": "string"},
                    "position_mm": {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3},
                    "offset_mm": {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2},
                },
            },
        },
        "where_to_stand": {
            "type": "object",
            "required": ["distance_mm", "height_mm", "straight_line_mm", "direction_xy", "cup_width_mm"],
        },
        "files": {
            "type": "array",
            "items": {
                "type": "object",
                "required": ["path", "format", "views"],
                "properties": {
                    "path": {"type": "string", "description": "the file's name in the folder"},
                    "format": {"enum": ["obj", "zip", "3mf", "glb"]},
                    "views": {"type": "array", "items": VIEW_SCORE},
                },
            },
        },
        "bleed_mm": {"type": "number", "exclusiveMinimum": 0,
                     "description": "under --bleed only: the colour bleed the textures were blurred by, mm "
                                    "(the point spread's standard deviation)"},
        "light": {**LIGHT, "description": "a verify under a real light (--light room or lamp:...) only"},
        "lit_views": {"type": "array", "items": LIT_VIEW_SCORE,
                      "description": "the primary file's views from each eye under that light"},
        "seconds": {"type": "number"},
    },
}
