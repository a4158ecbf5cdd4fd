"""Run one node directly, as the scheduler would (params validated, outputs checked). For tests."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from .node import Context, NodeSpec


def run_node(spec: NodeSpec, params: dict | None = None, work_dir: Path | None = None, **inputs: Any) -> dict[str, Any]:
    """Validate ``params`` with the node's model, call it, check every output against its port type.

    Returns ``{output_port: value}``.
    """
    p = spec.params.model_validate(params or {})
    ctx = Context(spec.type, p, work_dir=work_dir)  # without one: a scratch folder removed at exit
    for name, port in spec.inputs.items():
        if name not in inputs:
            if port.required:
                raise TypeError(f"{spec.type}: required input {name!r} not given")
            inputs[name] = None
    out = spec.fn(ctx, **inputs)
    if len(spec.outputs) == 1 and not (isinstance(out, dict) and set(out) == set(spec.outputs)):
        out = {next(iter(spec.outputs)): out}
    missing = set(spec.outputs) - set(out)
    if missing:
        raise TypeError(f"{spec.type}: did not return output(s) {sorted(missing)}")
    return {k: spec.outputs[k].validate(v, f"{spec.type}.{k}") for k, v in out.items()}
