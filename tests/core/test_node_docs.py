"""Discoverability (issue 14, item 13): params with type, default and unit; `tbha-graph show TYPE`."""
from __future__ import annotations

import re

from tbha_graph.cli import graph as graph_cli
from tbha_graph.core.registry import default_registry

RAW = re.compile(r"\b(Ge|Gt|Le|Lt|MultipleOf)\(|annotated_types|FieldInfo|typing\.|<class ")


def test_nodes_lists_every_param_with_type_default_and_unit(capsys):
    assert graph_cli.main(["nodes", "--plugin", "testnodes"]) == 0
    out = capsys.readouterr().out
    assert "test.source" in out and "params: n: int = 4; value: float = 1.0 m" in out
    assert "test.read_numbers" in out and "path: path (required)" in out
    assert not RAW.search(out)


def test_show_type_prints_the_full_doc(capsys):
    assert graph_cli.main(["show", "test.scale", "--plugin", "testnodes"]) == 0
    out = capsys.readouterr().out
    assert "Multiply by a factor." in out and "inputs:" in out and "outputs:" in out
    assert re.search(r"sleep\s+float\s+default 0\.0\s+\(>= 0\.?0?\)", out)
    assert "seconds to sleep" in out


def test_show_unknown_name_is_a_clear_error(capsys):
    assert graph_cli.main(["show", "test.scael", "--plugin", "testnodes"]) == 2
    assert "did you mean 'test.scale'" in capsys.readouterr().err


def test_no_node_description_shows_raw_reprs():
    reg = default_registry()
    for spec in reg.specs():
        text = graph_cli.describe_node(spec)
        assert not RAW.search(text), (spec.type, RAW.search(text).group(0))
        for name, f in spec.params.model_fields.items():
            assert re.search(rf"^  {re.escape(name)}\s+\S", text, re.M), (spec.type, name)
