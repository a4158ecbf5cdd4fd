"""Executors: the local one lives in :mod:`tbha_graph.core.scheduler`; optional ones here."""
