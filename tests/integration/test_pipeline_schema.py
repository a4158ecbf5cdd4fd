"""Every bundled pipeline validates against ``tbha-graph schema`` (issue 14, item 9)."""
from __future__ import annotations

from pathlib import Path

import jsonschema
import pytest
import yaml

from tbha_graph.core.registry import default_registry
from tbha_graph.core.schema import pipeline_schema

ROOT = Path(__file__).resolve().parents[2]
PIPELINES = sorted((ROOT / "pipelines").glob("*.yaml"))


@pytest.fixture(scope="module")
def validator():
    schema = pipeline_schema(default_registry())
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


@pytest.mark.parametrize("path", PIPELINES, ids=lambda p: p.name)
def test_bundled_pipeline_validates(validator, path):
    errors = [f"{'/'.join(map(str, e.absolute_path))}: {e.message}" for e in validator.iter_errors(yaml.safe_load(path.read_text()))]
    assert errors == []


def test_there_are_pipelines_that_extend_and_that_use_vars_for_typed_params():
    texts = [p.read_text() for p in PIPELINES]
    assert len(PIPELINES) >= 6 and any("extends:" in t for t in texts) and "focal_px: \"${focal_px}\"" in (ROOT / "pipelines" / "default.yaml").read_text()


@pytest.mark.parametrize("doc, what", [
    ({"nodes": {"a": {"type": "segment.hierarchical", "params": {"nope": 1}}}}, "nope"),
    ({"nodes": {"a": {"type": "segment.hierarchical"}}}, "required"),  # its video input is not wired
    ({"nodes": {"a": {"params": {}}}}, "'type' is a required property"),
    ({"extends": "default.yaml", "nodes": {"segment": {"type": "segment.hierarchical", "params": {"nope": 1}}}}, "nope"),
    ({"extends": "default.yaml", "nodes": {"segment": {"paramz": {}}}}, "paramz"),
    ({"nodes": {"a": {"type": "io.video", "params": {"start": "${not a var"}}}}, "start"),
])
def test_wrong_files_are_still_rejected(validator, doc, what):
    messages = " ".join(e.message + str(list(e.absolute_path)) for e in validator.iter_errors(doc))
    assert messages and what in messages
