"""The values the mocap stages exchange, with their readers: one module per bundle.

:mod:`tbha_graph.mocap.ports` declares each port type once and imports its value class and reader from
here (the body's are :mod:`tbha_graph.mocap.body`); a stage imports the port from
:mod:`~tbha_graph.mocap.ports` and the reader from here. These modules depend only on the layers below
them (:mod:`~tbha_graph.mocap.skeleton`, :mod:`~tbha_graph.core`), never on a stage.
"""
