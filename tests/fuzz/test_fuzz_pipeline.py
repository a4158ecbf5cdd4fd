"""Fuzzing the pipeline reader (``tbha_graph.core.runner.load_graph``: YAML, ``extends``, vars, node
types, params, wiring, outputs) with damaged copies of a small pipeline of real node types
(io.bvh_load -> filter.butterworth -> rotations.quaternion -> export.bvh).

Property, per mutated file: ``load_graph`` either returns a graph that says what the file says
(compared with a plain ``yaml.safe_load`` of the same text: node ids, types, params, wiring, outputs),
or raises ``PipelineErrors`` whose every error names the pipeline file (or the file it extends) and a
line; never another exception, never a hang. The graph is only built and checked, not run.
"""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from hypothesis import given

from fuzzlib import CASES, case, fuzz_settings, mutated, time_limit, vocabulary
from tbha_graph.core.errors import PipelineErrors, TbhaError
from tbha_graph.core.registry import default_registry
from tbha_graph.core.runner import load_graph

CLIP = Path(__file__).resolve().parents[2] / "data" / "mocap" / "cmu" / "131_01.bvh"

PIPELINE = f"""\
description: CMU walk -> smoothed -> joint rotations -> BVH
vars:
  clip: {CLIP}
  order: ZXY
nodes:
  load:
    type: io.bvh_load
    params: {{path: "${{clip}}", mapping: cmu}}
  smooth:
    type: filter.butterworth
    inputs: {{motion: load.motion}}
    params:
      cutoff: 6.0
      order: 4
  solve:
    type: rotations.quaternion
    inputs:
      motion: smooth.motion
  export:
    type: export.bvh
    inputs: {{rotations: solve.rotations}}
    params: {{rotation_order: "${{order}}", precision: 6, scale: 1.0}}
outputs:
  motion.bvh: export.bvh
""".encode()

# the same pipeline split in two: a base file and one that extends it
BASE_PART = f"""\
description: load and smooth
vars: {{clip: {CLIP}}}
nodes:
  load:
    type: io.bvh_load
    params: {{path: "${{clip}}"}}
  smooth:
    type: filter.butterworth
    inputs: {{motion: load.motion}}
    params: {{cutoff: 6.0, order: 4}}
""".encode()
CHILD_PART = b"""\
extends: base.yaml
nodes:
  solve: {type: rotations.quaternion, inputs: {motion: smooth.motion}}
  export: {type: export.bvh, inputs: {rotations: solve.rotations}}
outputs: {motion.bvh: export.bvh}
"""
VOCAB = vocabulary(PIPELINE) + (b"extends:", b"remove: true", b"type:", b"params:", b"inputs:", b"${nope}", b"&x", b"*x", b"<<:")


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    default_registry()  # import every node module once, outside the per-case time limit
    return tmp_path_factory.mktemp("fuzz_pipeline")


def _same(declared, got) -> bool:
    """A param value as written in YAML against the validated one (lax pydantic coercion allowed)."""
    if isinstance(got, Path):
        return Path(str(declared)) == got
    if isinstance(got, bool) or isinstance(declared, bool):
        return declared == got
    if isinstance(got, (int, float)) and isinstance(declared, (int, float)):
        return float(declared) == float(got)
    if isinstance(got, (int, float)) and isinstance(declared, str):
        try:
            return float(declared) == float(got)
        except ValueError:
            return False
    return declared == got


def check_graph_says_what_file_says(text: bytes, graph) -> None:
    data = yaml.safe_load(text)
    vars_ = {str(k): v for k, v in (data.get("vars") or {}).items()}
    nodes = {str(k): v for k, v in (data.get("nodes") or {}).items() if not (isinstance(v, dict) and v.get("remove"))}
    assert nodes, "a pipeline without nodes was accepted"
    assert set(graph.nodes) == set(nodes)
    for nid, body in nodes.items():
        b = graph.nodes[nid]
        assert b.spec.type == body["type"]
        for k, v in (body.get("params") or {}).items():
            if isinstance(v, str) and v.startswith("${") and v.endswith("}") and v[2:-1] in vars_:
                v = vars_[v[2:-1]]
            assert _same(v, getattr(b.params, str(k))), f"{nid}.{k}: file says {v!r}, graph has {getattr(b.params, str(k))!r}"
        for port, ref in (body.get("inputs") or {}).items():
            assert b.inputs[str(port)] == tuple(str(ref).split(".", 1))
        assert set(b.inputs) == {str(p) for p in (body.get("inputs") or {})}
    assert {k: f"{n}.{p}" for k, (n, p) in graph.outputs.items()} == {str(k): str(v) for k, v in (data.get("outputs") or {}).items()}


def check_pipeline(path: Path, allowed_files: set[str], oracle: bytes | None) -> None:
    with time_limit(what=f"load_graph({path.name})"):
        try:
            graph = load_graph(path)
        except PipelineErrors as e:
            assert e.errors, "PipelineErrors with no error in it"
            for err in e.errors:
                assert err.location is not None, f"error without a location: {err.format()}"
                assert err.location.file in allowed_files, f"error located in {err.location.file}: {err.format()}"
                assert err.location.line > 0, f"error without a line: {err.format()}"
            return
        except TbhaError as e:
            pytest.fail(f"load_graph raised {type(e).__name__}, not PipelineErrors: {e}")
        except Exception as e:  # noqa: BLE001
            pytest.fail(f"load_graph raised a bare {type(e).__name__}: {e!r}")
        if oracle is not None:
            check_graph_says_what_file_says(oracle, graph)


def test_unmutated_pipelines_load(work) -> None:
    p = work / "ok.yaml"
    p.write_bytes(PIPELINE)
    graph = load_graph(p)
    assert graph.order == ["load", "smooth", "solve", "export"]
    check_graph_says_what_file_says(PIPELINE, graph)
    (work / "base.yaml").write_bytes(BASE_PART)
    (work / "child.yaml").write_bytes(CHILD_PART)
    assert load_graph(work / "child.yaml").order == ["load", "smooth", "solve", "export"]


# cases the fuzzer found (kept as explicit examples)
FOUND = [
    case(PIPELINE.replace(b"  smooth:\n", b"  ? [smooth]\n"), "a list as a node id (unhashable key)"),
    case(PIPELINE.replace(b"      cutoff: 6.0\n", b"      ? {a: 1}\n      : 6.0\n"), "a mapping as a param name"),
    case(PIPELINE.replace(b"  clip: ", b"  clip: \"\\0\"\n  x: "), "a NUL character in a path"),
    case(PIPELINE.replace(b"cutoff: 6.0", b"cutoff: \"\\0\""), "a NUL character in a number param"),
    case(PIPELINE.replace(b"description:", b"extends: \"a\\0b\"\ndescription:"), "a NUL character in 'extends'"),
    case(b"\x00" + PIPELINE, "a control character (YAML reader error, no mark)"),
    case(PIPELINE.replace(b"order: 4", b"order: \xe9"), "a byte that is not UTF-8"),
    case(b"", "an empty file"),
    case(PIPELINE[:23], "truncated after the description"),
]


@pytest.mark.parametrize("raw", FOUND, ids=lambda c: c.what[0])
def test_found_cases(raw, work) -> None:
    p = work / "found.yaml"
    p.write_bytes(raw)
    check_pipeline(p, {str(p)}, raw)


@given(raw=mutated(PIPELINE, VOCAB))
@fuzz_settings(max_examples=250)
def test_fuzz_pipeline_file(raw, work) -> None:
    CASES["pipeline file"] += 1
    p = work / "case.yaml"
    p.write_bytes(raw)
    check_pipeline(p, {str(p)}, raw)


@given(raw=mutated(BASE_PART, VOCAB))
@fuzz_settings(max_examples=100)
def test_fuzz_extended_base_file(raw, work) -> None:
    """Errors in a file reached through ``extends`` name that file (or the one extending it)."""
    CASES["pipeline base file (extends)"] += 1
    d = work / "ext"
    d.mkdir(exist_ok=True)
    (d / "base.yaml").write_bytes(raw)
    (d / "child.yaml").write_bytes(CHILD_PART)
    check_pipeline(d / "child.yaml", {str(d / "base.yaml"), str(d / "child.yaml")}, None)
