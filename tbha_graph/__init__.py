"""tbha-graph: a node-graph dataflow framework (:mod:`tbha_graph.core`) and tight-suit motion capture
built on it (:mod:`tbha_graph.mocap`)."""

__version__ = "0.1.0"
