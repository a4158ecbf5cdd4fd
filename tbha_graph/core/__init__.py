"""The framework core: nodes, port types, registry, pipeline spec, scheduler, cache, executors.

Knows nothing about motion capture. Node authors need only::

    from tbha_graph.core import node, Array, Arrays, Json, Model, File, AnyOf, optional, InputPath, NodeError

What declaring a node needs is imported here; ``Pipeline`` and ``Cache`` (which bring the graph
checker, registry and scheduler) on first use (PEP 562), so a node module does not import the scheduler.
"""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from .errors import NodeError, PipelineError, PipelineErrors, TbhaError
from .node import Context, Input, InputPath, NodeSpec, NoParams, node, optional
from .types import AnyOf, AnyType, Array, Arrays, File, Json, Model, PortType

_WHERE = {"Pipeline": "pipeline", "Cache": "cache"}

__all__ = [
    "AnyOf", "AnyType", "Array", "Arrays", "Context", "File", "Input", "InputPath", "Json", "Model",
    "NodeError", "NodeSpec", "Pipeline", "Cache", "NoParams", "PipelineError", "PipelineErrors", "PortType", "TbhaError",
    "node", "optional",
]


def __getattr__(name: str) -> Any:
    where = _WHERE.get(name)
    if where is None:
        raise AttributeError(f"module 'tbha_graph.core' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{where}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))


if TYPE_CHECKING:  # for type checkers and editors
    from .cache import Cache
    from .pipeline import Pipeline
