"""Pipelines are checked before anything runs; every problem names file, line, node and a fix."""
from __future__ import annotations

import pytest
from testnodes import CHAIN

from tbha_graph.core.errors import PipelineErrors
from tbha_graph.core.runner import load_graph


def problems(path, registry, **kw) -> list[str]:
    with pytest.raises(PipelineErrors) as ei:
        load_graph(path, registry=registry, **kw)
    return [e.format() for e in ei.value.errors]


def test_valid_chain_builds_in_topological_order(write, registry):
    g = load_graph(write("p.yaml", CHAIN), registry=registry)
    assert g.order.index("src") < g.order.index("double") < g.order.index("sum") < g.order.index("stats")
    assert g.outputs["sum.npz"] == ("sum", "y")


def test_unknown_type_names_file_line_node_and_suggestion(write, registry):
    p = write("p.yaml", """
        nodes:
          src:
            type: test.sourse
        outputs: {}
    """)
    (msg,) = problems(p, registry)
    assert f"{p}:3" in msg and "node 'src'" in msg and "did you mean 'test.source'" in msg


def test_all_errors_reported_at_once(write, registry):
    p = write("p.yaml", """
        nodes:
          src:
            type: test.source
            params: {n: 0, valeu: 3}
          double:
            type: test.scale
            inputs: {xx: src.x}
          triple:
            type: test.scale
            inputs: {x: scr.x}
          four:
            type: test.scale
            inputs: {x: src.y}
        outputs:
          out.npz: nothing.y
    """)
    msgs = problems(p, registry)
    text = "\n".join(msgs)
    assert "unknown param 'valeu'" in text and "did you mean 'value'" in text
    assert "no input port 'xx'" in text and "did you mean 'x'" in text
    assert "unknown node 'scr'" in text and "did you mean 'src'" in text
    assert "has no output 'y'" in text and "did you mean 'x'" in text
    assert "required input 'x'" in text and "node 'double'" in text
    assert "output 'out.npz' names unknown node 'nothing'" in text
    assert len(msgs) >= 6
    # each error carries its own line
    assert f"{p}:4" in text and f"{p}:7" in text and f"{p}:10" in text


def test_invalid_param_value_is_a_pydantic_error_with_line(write, registry):
    p = write("p.yaml", """
        nodes:
          src:
            type: test.source
            params:
              n: 0
        outputs: {}
    """)
    (msg,) = problems(p, registry)
    assert f"{p}:5" in msg and "invalid param 'n'" in msg and "greater than or equal to 1" in msg


def test_type_mismatch(write, registry):
    p = write("p.yaml", """
        nodes:
          src: {type: test.source}
          m: {type: test.metrics, inputs: {x: src.x}}
          s: {type: test.scale, inputs: {x: m.metrics}}
        outputs: {}
    """)
    (msg,) = problems(p, registry)
    assert "type mismatch" in msg and "Json" in msg and "Array" in msg and "node 's'" in msg


def test_cycle_is_printed(write, registry):
    p = write("p.yaml", """
        nodes:
          a: {type: test.scale, inputs: {x: b.y}}
          b: {type: test.scale, inputs: {x: a.y}}
        outputs: {}
    """)
    (msg,) = problems(p, registry)
    assert "cycle" in msg and ("a -> b -> a" in msg or "b -> a -> b" in msg)


def test_duplicate_node_ids(write, registry):
    p = write("p.yaml", """
        nodes:
          a: {type: test.source}
          a: {type: test.source}
        outputs: {}
    """)
    (msg,) = problems(p, registry)
    assert "duplicate key 'a'" in msg and f"{p}:3" in msg


def test_yaml_syntax_error_has_line_and_column(write, registry):
    p = write("p.yaml", "nodes:\n  a: {type: test.source\noutputs: {}\n")
    (msg,) = problems(p, registry)
    assert "YAML syntax error" in msg and str(p) in msg


def test_unknown_top_level_key_suggests(write, registry):
    p = write("p.yaml", "node:\n  a: {type: test.source}\n")
    (msg,) = problems(p, registry)
    assert "unknown key 'node'" in msg and "did you mean 'nodes'" in msg


def test_yaml_is_loaded_safely(write, registry):
    p = write("p.yaml", "nodes: !!python/object/apply:os.system ['echo hacked']\n")
    (msg,) = problems(p, registry)
    assert "could not determine a constructor" in msg or "YAML" in msg


def test_missing_input_file_param(write, registry, tmp_path):
    p = write("p.yaml", """
        nodes:
          r: {type: test.read_numbers, params: {path: nowhere.txt}}
        outputs: {}
    """)
    (msg,) = problems(p, registry)
    assert "file does not exist" in msg and str(tmp_path / "nowhere.txt") in msg and "--set r.path" in msg


def test_extends_overrides_type_and_params(write, registry):
    write("base.yaml", CHAIN)
    p = write("child.yaml", """
        extends: base.yaml
        nodes:
          double: {params: {factor: 5}}
          triple: {type: test.counted, params: {counter: c.txt}}
    """)
    g = load_graph(p, registry=registry)
    assert g.nodes["double"].params.factor == 5
    assert g.nodes["triple"].spec.type == "test.counted"
    assert g.nodes["triple"].inputs == {"x": ("src", "x")}  # wiring kept across a type swap
    assert g.nodes["sum"].spec.type == "test.add"


def test_vars_and_sets(write, registry):
    p = write("p.yaml", """
        vars: {n: 7}
        nodes:
          src: {type: test.source, params: {n: "${n}"}}
        outputs: {}
    """)
    assert load_graph(p, registry=registry).nodes["src"].params.n == 7
    assert load_graph(p, registry=registry, vars={"n": 9}).nodes["src"].params.n == 9
    assert load_graph(p, registry=registry, sets={"src.n": 3}).nodes["src"].params.n == 3
    (msg,) = problems(p, registry, sets={"scr.n": 3})
    assert "unknown node 'scr'" in msg and "did you mean 'src'" in msg


def test_unknown_var(write, registry):
    p = write("p.yaml", """
        vars: {count: 7}
        nodes:
          src: {type: test.source, params: {n: "${cuont}"}}
        outputs: {}
    """)
    (msg,) = problems(p, registry)
    assert "unknown variable" in msg and "did you mean 'count'" in msg
