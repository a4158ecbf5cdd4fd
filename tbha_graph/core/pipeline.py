"""Building and running a pipeline from plain Python, without YAML (same checks, same cache)::

    from tbha_graph.core import Pipeline
    p = Pipeline("blur a signal")
    p.add("load", "io.signal", params={"path": "x.npy"})
    p.add("blur", blur_spec, x="load.signal", params={"sigma": 2})   # a NodeSpec or a type name
    p.output("y.npz", "blur.y")
    run = p.run(out_dir="runs/blur")
    y = run.output("y.npz")
"""
from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

from .errors import Location
from .graph import Graph, build_graph
from .node import NodeSpec
from .registry import Registry
from .scheduler import RunResult
from .spec import NodeDecl, PipelineDecl, Value


class Pipeline:
    """A pipeline declared in Python. Node ids are unique; inputs are ``"<node id>.<port>"`` strings."""

    def __init__(self, description: str = "", registry: Registry | None = None):
        self.decl = PipelineDecl(path="<python>", description=description)
        self.registry = registry
        self._cwd_str, self._cwd_path = "", Path()

    def _loc(self) -> Location:
        frame = sys._getframe(2)  # the caller of add()/output(); inspect.stack() is far too slow
        return Location(frame.f_code.co_filename, frame.f_lineno, 0)

    def _cwd(self) -> Path:
        cwd = os.getcwd()  # one Path per folder, not per node (building a 10,000-node pipeline)
        if cwd != self._cwd_str:
            self._cwd_str, self._cwd_path = cwd, Path(cwd)
        return self._cwd_path

    def add(self, node_id: str, node: str | NodeSpec, params: dict[str, Any] | None = None, **inputs: str) -> "Pipeline":
        """Add node ``node_id`` of type ``node`` (a registered type name or a NodeSpec)."""
        loc = self._loc()
        base = self._cwd()
        if node_id in self.decl.nodes:
            raise ValueError(f"node id '{node_id}' is used twice")
        self.decl.nodes[node_id] = NodeDecl(
            id=node_id,
            type=node,
            loc=loc,
            type_loc=loc,
            params={k: Value(v, loc, base) for k, v in (params or {}).items()},
            inputs={k: Value(v, loc, base) for k, v in inputs.items()},
        )
        return self

    def output(self, name: str, ref: str) -> "Pipeline":
        """Name an output (a file name in the run directory) for ``"<node id>.<port>"``."""
        self.decl.outputs[name] = Value(ref, self._loc(), self._cwd())
        return self

    def build(self) -> Graph:
        """Check everything (raises PipelineErrors listing all problems) and return the graph."""
        return build_graph(self.decl.copy(), self.registry)

    def run(self, out_dir: str | Path | None = None, **kwargs: Any) -> RunResult:
        """Build and run; see :func:`tbha_graph.core.runner.run_graph` for the options."""
        from .runner import run_graph

        return run_graph(self.build(), out_dir=out_dir, **kwargs)
