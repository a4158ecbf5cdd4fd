"""Pictures and text of a pipeline's DAG: plain text, Mermaid, Graphviz DOT, or a PNG (matplotlib)."""
from __future__ import annotations

from pathlib import Path

from .graph import Graph


def as_text(g: Graph) -> str:
    lines = [f"pipeline {g.path}" + (f": {g.description}" if g.description else "")]
    for nid in g.order:
        b = g.nodes[nid]
        ins = ", ".join(f"{p}<-{s}.{sp}" for p, (s, sp) in b.inputs.items())
        lines.append(f"  {nid} [{b.spec.type}]" + (f"  ({ins})" if ins else ""))
    for name, (n, p) in g.outputs.items():
        lines.append(f"  output {name} <- {n}.{p}")
    return "\n".join(lines)


def _safe(s: str) -> str:
    return s.replace("-", "_").replace(".", "_")


def as_mermaid(g: Graph) -> str:
    lines = ["flowchart LR"]
    for nid in g.order:
        lines.append(f'  {_safe(nid)}["{nid}<br/><small>{g.nodes[nid].spec.type}</small>"]')
    for nid in g.order:
        for port, (src, sport) in g.nodes[nid].inputs.items():
            lines.append(f"  {_safe(src)} -- {sport} --> {_safe(nid)}")
    for name, (n, _) in g.outputs.items():
        lines.append(f'  out_{_safe(name)}[("{name}")]')
        lines.append(f"  {_safe(n)} --> out_{_safe(name)}")
    return "\n".join(lines)


def as_dot(g: Graph) -> str:
    lines = ["digraph pipeline {", "  rankdir=LR; node [shape=box, fontname=Helvetica];"]
    for nid in g.order:
        lines.append(f'  "{nid}" [label="{nid}\\n{g.nodes[nid].spec.type}"];')
    for nid in g.order:
        for port, (src, sport) in g.nodes[nid].inputs.items():
            lines.append(f'  "{src}" -> "{nid}" [label="{sport}"];')
    for name, (n, _) in g.outputs.items():
        lines.append(f'  "{name}" [shape=note];')
        lines.append(f'  "{n}" -> "{name}";')
    lines.append("}")
    return "\n".join(lines)


def save_png(g: Graph, path: Path) -> None:
    """Draw the DAG left to right (layers by longest path) and save a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import networkx as nx

    G = g.to_networkx()
    for nid in G:
        G.nodes[nid]["layer"] = 0
    for nid in nx.topological_sort(G):
        for succ in G.successors(nid):
            G.nodes[succ]["layer"] = max(G.nodes[succ]["layer"], G.nodes[nid]["layer"] + 1)
    pos = nx.multipartite_layout(G, subset_key="layer")
    layers = max((d["layer"] for _, d in G.nodes(data=True)), default=0) + 1
    fig, ax = plt.subplots(figsize=(max(6, 2.6 * layers), max(3, 0.9 * len(G) / max(1, layers) + 2)))
    nx.draw_networkx_edges(G, pos, ax=ax, arrows=True, arrowsize=14, node_size=2600, edge_color="#888")
    for nid, (x, y) in pos.items():
        ax.text(x, y, f"{nid}\n{g.nodes[nid].spec.type}", ha="center", va="center", fontsize=8,
                bbox=dict(boxstyle="round,pad=0.4", fc="#eef3fb", ec="#3a6fb0"))
    ax.set_axis_off()
    ax.set_title(g.description or g.path, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
