"""JSON Schema (2020-12) of ``saucerfab.check/1``: what ``--json`` prints and ``Report.to_dict()`` gives.

``saucerfab check --schema`` prints :data:`JSON_SCHEMA`. Stats keys are all
optional (an unreadable file has only ``file_bytes``); lengths are
millimetres, areas mm2, volumes mm3. Within version 1 keys are only added.
"""

from __future__ import annotations

from typing import Any

from saucerfab.check.report import CODES, SCHEMA_ID

_NUM_OR_NULL = {"type": ["number", "null"]}
_INT_OR_NULL = {"type": ["integer", "null"], "minimum": 0}
_VEC3 = {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3}

STATS_SCHEMA: dict[str, Any] = {
    "type": "object",
    "additionalProperties": False,
    "properties": {
        "file_bytes": _INT_OR_NULL,
        "units": {"type": "string", "description": "unit the coordinates were read in"},
        "unit_mm": {"type": "number", "exclusiveMinimum": 0, "description": "millimetres per file unit"},
        "units_stated": {"type": "boolean", "description": "the file states its unit (3MF, glTF) vs assumed"},
        "parts": {"type": "integer", "minimum": 0, "description": "mesh parts instanced"},
        "triangles": {"type": "integer", "minimum": 0},
        "vertices": {"type": "integer", "minimum": 0, "description": "as stored in the file"},
        "welded_vertices": _INT_OR_NULL,
        "shells": _INT_OR_NULL,
        "bbox_mm": {
            "oneOf": [
                {"type": "null"},
                {"type": "object", "additionalProperties": False, "required": ["min", "max", "size"],
                 "properties": {"min": _VEC3, "max": _VEC3, "size": _VEC3}},
            ]
        },
        "volume_mm3": _NUM_OR_NULL,
        "area_mm2": _NUM_OR_NULL,
        "boundary_edges": _INT_OR_NULL,
        "non_manifold_edges": _INT_OR_NULL,
        "non_manifold_vertices": _INT_OR_NULL,
        "flipped_edges": _INT_OR_NULL,
        "degenerate_faces": _INT_OR_NULL,
        "duplicate_faces": _INT_OR_NULL,
        "unreferenced_vertices": _INT_OR_NULL,
        "self_intersecting_pairs": _INT_OR_NULL,
        "self_intersection_check": {"enum": ["full", "partial", "skipped"]},
        "min_wall_mm": _NUM_OR_NULL,
        "min_wall_required_mm": _NUM_OR_NULL,
        "thin_wall_samples": {"type": "integer", "minimum": 0},
        "thin_wall_fraction": _NUM_OR_NULL,
        "relief_thin_samples": {"type": "integer", "minimum": 0},
        "manifold3d_status": {"type": ["string", "null"]},
        "textures": {
            "type": "array",
            "items": {
                "type": "object", "additionalProperties": False,
                "required": ["name", "status", "width", "height", "format"],
                "properties": {
                    "name": {"type": "string"},
                    "status": {"enum": ["ok", "missing", "unreadable", "too_large", "unsafe_path"]},
                    "width": _INT_OR_NULL, "height": _INT_OR_NULL, "format": {"type": ["string", "null"]},
                },
            },
        },
        "texture_px": _INT_OR_NULL,
        "texture_dpi": _NUM_OR_NULL,
        "texture_detailed_fraction": _NUM_OR_NULL,
        "uv_outside_faces": _INT_OR_NULL,
        "coloured_fraction": {"type": "number", "minimum": 0, "maximum": 1},
        "colour": {"type": "array", "items": {"enum": ["texture", "vertex", "face", "material"]}},
    },
}

FINDING_SCHEMA: dict[str, Any] = {
    "type": "object",
    "additionalProperties": False,
    "required": ["severity", "code", "message", "where"],
    "properties": {
        "severity": {"enum": ["error", "warning", "info"]},
        "code": {"enum": sorted(CODES)},
        "message": {"type": "string", "pattern": "^[^\\n\\r]*$"},
        "where": {
            "oneOf": [
                {"type": "null"},
                {
                    "type": "object", "additionalProperties": False,
                    "properties": {
                        "point_mm": _VEC3,
                        "faces": {"type": "array", "items": {"type": "integer", "minimum": 0}, "maxItems": 10},
                        "vertices": {"type": "array", "items": {"type": "integer", "minimum": 0}, "maxItems": 10},
                        "count": {"type": "integer", "minimum": 0},
                        "entry": {"type": "string"},
                    },
                },
            ]
        },
    },
}

REPORT_DEF: dict[str, Any] = {
    "type": "object",
    "additionalProperties": False,
    "required": ["schema", "path", "format", "verdict", "exit_code", "printer", "strict", "elapsed_s",
                 "findings", "stats"],
    "properties": {
        "schema": {"const": SCHEMA_ID},
        "path": {"type": "string"},
        "format": {"enum": ["3mf", "obj", "stl", "ply", "glb", "gltf", "wrl", None]},
        "verdict": {"enum": ["printable", "not printable", "unreadable"]},
        "exit_code": {"enum": [0, 1, 2]},
        "printer": {"type": ["string", "null"]},
        "strict": {"type": "boolean"},
        "elapsed_s": {"type": "number", "minimum": 0},
        "findings": {"type": "array", "items": {"$ref": "#/$defs/finding"}},
        "stats": {"$ref": "#/$defs/stats"},
    },
}

_DEFS = {"report": REPORT_DEF, "finding": FINDING_SCHEMA, "stats": STATS_SCHEMA}

#: the document ``saucerfab check --json`` prints (many files)
JSON_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "$id": "https://saucerfab.invalid/schemas/check-1.json",
    "title": SCHEMA_ID,
    "type": "object",
    "additionalProperties": False,
    "required": ["schema", "saucerfab_version", "strict", "printer", "files", "summary"],
    "properties": {
        "schema": {"const": SCHEMA_ID},
        "saucerfab_version": {"type": "string"},
        "strict": {"type": "boolean"},
        "printer": {"type": ["string", "null"]},
        "files": {"type": "array", "items": {"$ref": "#/$defs/report"}},
        "summary": {
            "type": "object", "additionalProperties": False,
            "required": ["files", "printable", "not_printable", "unreadable", "exit_code"],
            "properties": {
                "files": {"type": "integer", "minimum": 0},
                "printable": {"type": "integer", "minimum": 0},
                "not_printable": {"type": "integer", "minimum": 0},
                "unreadable": {"type": "integer", "minimum": 0},
                "exit_code": {"enum": [0, 1, 2]},
            },
        },
    },
    "$defs": _DEFS,
}

#: one file's report (``Report.to_dict()``)
REPORT_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "$ref": "#/$defs/report",
    "$defs": _DEFS,
}
