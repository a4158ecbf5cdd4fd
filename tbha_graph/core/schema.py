"""JSON Schema for pipeline files, built from the registered nodes (for editor validation and
autocompletion: point the YAML language server at the output of ``tbha-graph schema``)."""
from __future__ import annotations

from typing import Any

from .registry import Registry


def node_schema(spec) -> dict[str, Any]:
    params = spec.params.model_json_schema()
    defs = params.pop("$defs", {})
    params["additionalProperties"] = False
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
                "required": [p for p, i in spec.inputs.items() if i.required],
            },
        },
        "required": ["type"],
        "additionalProperties": False,
        **({"$defs": defs} if defs else {}),
    }


def pipeline_schema(registry: Registry) -> dict[str, Any]:
    variants = []
    for spec in registry.specs():
        s = node_schema(spec)
        defs = s.pop("$defs", None)
        if defs:  # inline local refs under a per-node name to keep them unique
            import json

            text = json.dumps(s).replace("#/$defs/", f"#/$defs/{spec.type}.")
            s = json.loads(text)
            s["$defs"] = {f"{spec.type}.{k}": v for k, v in defs.items()}
        variants.append({"if": {"properties": {"type": {"const": spec.type}}}, "then": s})
    all_defs: dict[str, Any] = {}
    for v in variants:
        all_defs.update(v["then"].pop("$defs", {}))
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "tbha-graph pipeline",
        "type": "object",
        "additionalProperties": False,
        "properties": {
            "description": {"type": "string"},
            "extends": {"type": "string", "description": "path of a pipeline file this one overrides"},
            "vars": {"type": "object"},
            "outputs": {"type": "object", "additionalProperties": {"type": "string", "pattern": r"^[^.]+\..+$"}},
            "nodes": {
                "type": "object",
                "additionalProperties": {
                    "type": "object",
                    "properties": {"type": {"enum": registry.types()}, "params": {"type": "object"}, "inputs": {"type": "object"}, "remove": {"type": "boolean"}},
                    "allOf": variants,
                },
            },
        },
        "$defs": all_defs,
    }
