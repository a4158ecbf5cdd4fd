"""Single-camera tight-suit motion capture, as nodes of the :mod:`tbha_graph.core` framework.

One subpackage per stage; a node of YAML type ``stage.name`` lives in ``tbha_graph/mocap/stage/``.
Shared conventions: :mod:`.skeleton` (16 joints, world frame) and :mod:`.camera` (camera frame, pixels).
"""
