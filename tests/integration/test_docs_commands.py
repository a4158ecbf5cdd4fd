"""Commands in the README and docs name real options, nodes, params and variables (issue 14, item 7)."""
from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from tbha_graph.cli.run import build_parser
from tbha_graph.core.runner import load_graph
from tbha_graph.core.spec import _referenced_vars, parse_assignment, read_pipeline

ROOT = Path(__file__).resolve().parents[2]


def _commands() -> list[tuple[str, str]]:
    out = []
    for doc in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        text = doc.read_text().replace("\\\n", " ")
        for m in re.finditer(r"tbha-run (pipelines/[a-z_]+\.yaml[^`\n#]*)", text):
            out.append((doc.name, m.group(1).strip()))
    return out


COMMANDS = _commands()


def test_the_docs_have_commands():
    assert len(COMMANDS) >= 5


@pytest.mark.parametrize("doc, cmd", COMMANDS, ids=[f"{d}:{c[:50]}" for d, c in COMMANDS])
def test_command_names_real_nodes_params_and_vars(doc, cmd):
    args = build_parser().parse_args(shlex.split(cmd))
    decl = read_pipeline(ROOT / args.pipeline)
    graph = load_graph(ROOT / args.pipeline)
    for item in args.set or []:
        name, _ = parse_assignment(item, "--set")
        node_id, param = name.split(".")[:2]
        assert node_id in graph.nodes, f"{doc}: {cmd}: no node {node_id}"
        assert param in graph.nodes[node_id].spec.params.model_fields, f"{doc}: {cmd}: node {node_id} has no param {param}"
    for item in args.var or []:
        name, _ = parse_assignment(item, "--var")
        assert name in set(decl.vars) | _referenced_vars(decl), f"{doc}: {cmd}: no variable {name}"
