"""JSON Schema for pipeline files, built from the registered nodes (for editor validation and
autocompletion: point the YAML language server at the output of ``tbha-graph schema``)."""
from __future__ import annotations

from typing import Any

from .registry import Registry


#: a whole-string pipeline variable, e.g. "${focal_px}": it may stand for a param of any type
VAR_PATTERN = r"^\$\{[A-Za-z_][A-Za-z0-9_]*\}$"


def _allow_vars(params: dict[str, Any]) -> dict[str, Any]:
    """Each param may also be written as a ``${var}`` string (substituted before checking)."""
    for name, prop in list(params.get("properties", {}).items()):
        params["properties"][name] = {"anyOf": [prop, {"type": "string", "pattern": VAR_PATTERN}],
                                      **({"description": prop["description"]} if "description" in prop else {})}
    return params


def node_schema(spec, partial: bool = False) -> dict[str, Any]:
    """Schema of one node entry of type ``spec``. ``partial``: an entry of a file that ``extends`` another,
    which overrides only what it names (no param or input is required; the type may stay inherited)."""
    params = _allow_vars(spec.params.model_json_schema())
    defs = params.pop("$defs", {})
    params["additionalProperties"] = False
    if partial:
        params.pop("required", None)
    return {
        "type": "object",
        "description": spec.summary,
        "properties": {
            "type": {"const": spec.type},
            "params": params,
            "inputs": {
                "type": "object",
                "additionalProperties": False,
                "properties": {p: {"type": "string", "pattern": r"^[^.]+\..+$", "description": f"{i.type.describe()} (<node id>.<port>)"} for p, i in spec.inputs.items()},
                "required": [] if partial else [p for p, i in spec.inputs.items() if i.required],
            },
            **({"remove": {"type": "boolean"}} if partial else {}),
        },
        "required": [] if partial else ["type"] + (["inputs"] if any(i.required for i in spec.inputs.values()) else []),
        "additionalProperties": False,
        **({"$defs": defs} if defs else {}),
    }


def _variants(registry: Registry, partial: bool, all_defs: dict[str, Any]) -> list[dict[str, Any]]:
    import json

    variants = []
    for spec in registry.specs():
        s = node_schema(spec, partial)
        defs = s.pop("$defs", None)
        if defs:  # inline local refs under a per-node name to keep them unique
            s = json.loads(json.dumps(s).replace("#/$defs/", f"#/$defs/{spec.type}."))
            all_defs.update({f"{spec.type}.{k}": v for k, v in defs.items()})
        variants.append({"if": {"required": ["type"], "properties": {"type": {"const": spec.type}}}, "then": s})
    return variants


def pipeline_schema(registry: Registry) -> dict[str, Any]:
    all_defs: dict[str, Any] = {}
    entry = {"type": "object", "properties": {"type": {"enum": registry.types()}, "params": {"type": "object"},
                                              "inputs": {"type": "object"}, "remove": {"type": "boolean"}}}
    full = {**entry, "required": ["type"], "allOf": _variants(registry, False, all_defs)}
    partial = {**entry, "additionalProperties": False, "allOf": _variants(registry, True, all_defs)}
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "tbha-graph pipeline",
        "type": "object",
        "additionalProperties": False,
        "properties": {
            "description": {"type": "string"},
            "jobs": {"type": "integer", "minimum": 1, "description": "nodes the local executor runs at once (tbha-run --jobs overrides)"},
            "extends": {"type": "string", "description": "path of a pipeline file this one overrides"},
            "vars": {"type": "object"},
            "outputs": {"type": "object", "additionalProperties": {"type": "string", "pattern": r"^[^.]+\..+$"}},
            "nodes": {"type": "object"},
        },
        # a file that extends another overrides only what it names; any other file declares whole nodes
        "if": {"required": ["extends"]},
        "then": {"properties": {"nodes": {"additionalProperties": partial}}},
        "else": {"properties": {"nodes": {"additionalProperties": full}}},
        "$defs": all_defs,
    }
