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
