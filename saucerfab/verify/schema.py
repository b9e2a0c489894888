"""JSON Schema of ``saucerfab verify --json`` (``saucerfab.verify/2``); ``saucerfab verify --schema`` prints it."""

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
                     "description": "share of the view's frame where the saucer is seen (directly / in the mirror)"},
        "pixels": {"type": "integer", "minimum": 0, "description": "pixels compared (seen fully)"},
        "shift_px": {"type": "array", "items": {"type": "integer"}, "minItems": 2, "maxItems": 2,
                     "description": "reference picture moved right, down for psnr_shift_db, pixels"},
        "passed": {"type": "boolean"},
        "picture": {"type": ["string", "null"], "description": "side-by-side picture, relative to the pictures folder"},
    },
}

JSON_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "saucerfab verify report",
    "type": "object",
    "required": ["schema", "saucerfab_version", "folder", "renderer", "res", "spp", "min_psnr_db", "min_coverage",
                 "passed", "exit_code", "eyes", "where_to_stand", "files"],
    "properties": {
        "schema": {"const": "saucerfab.verify/2"},
        "saucerfab_version": {"type": "string"},
        "folder": {"type": "string"},
        "renderer": {"type": "object", "required": ["name", "version", "variant", "integrator"]},
        "res": {"type": "integer", "description": "render size, pixels per side"},
        "spp": {"type": "integer", "description": "samples per pixel"},
        "min_psnr_db": {"type": "number"},
        "min_coverage": {"type": "number"},
        "passed": {"type": "boolean", "description": "every view of every file from every eye passed"},
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
        "seconds": {"type": "number"},
    },
}
