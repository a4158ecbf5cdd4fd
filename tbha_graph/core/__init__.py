"""The framework core: nodes, port types, registry, pipeline spec, scheduler, cache, executors.

Knows nothing about motion capture. Node authors need only::

    from tbha_graph.core import node, Array, Arrays, Json, Model, File, AnyOf, optional, InputPath, NodeError
"""
from .errors import NodeError, PipelineError, PipelineErrors, TbhaError
from .node import Context, Input, InputPath, NodeSpec, NoParams, node, optional
from .types import AnyOf, AnyType, Array, Arrays, File, Json, Model, PortType
from .pipeline import Pipeline
from .cache import Cache

__all__ = [
    "AnyOf", "AnyType", "Array", "Arrays", "Context", "File", "Input", "InputPath", "Json", "Model",
    "NodeError", "NodeSpec", "Pipeline", "Cache", "NoParams", "PipelineError", "PipelineErrors", "PortType", "TbhaError",
    "node", "optional",
]
