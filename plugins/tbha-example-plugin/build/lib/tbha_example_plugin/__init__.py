"""Example tbha-graph plugin: nodes live in :mod:`tbha_example_plugin.nodes`."""
