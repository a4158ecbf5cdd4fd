from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

import testnodes
from tbha_graph.core.cache import Cache
from tbha_graph.core.registry import Registry


@pytest.fixture
def registry() -> Registry:
    reg = Registry()
    reg.add_module(testnodes, source="tests")
    return reg


@pytest.fixture
def cache(tmp_path) -> Cache:
    return Cache(tmp_path / "cache")


@pytest.fixture
def write(tmp_path):
    """write("name.yaml", text) -> path, dedented."""

    def _write(name: str, text: str) -> Path:
        p = tmp_path / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(textwrap.dedent(text).lstrip("\n"))
        return p

    return _write


CHAIN = """
description: a small chain
nodes:
  src:
    type: test.source
    params: {n: 5, value: 2.0}
  double:
    type: test.scale
    inputs: {x: src.x}
    params: {factor: 2}
  triple:
    type: test.scale
    inputs: {x: src.x}
    params: {factor: 3}
  sum:
    type: test.add
    inputs: {a: double.y, b: triple.y}
  stats:
    type: test.metrics
    inputs: {x: sum.y}
outputs:
  sum.npz: sum.y
  metrics.json: stats.metrics
"""
