"""``export.gltf``: the motion as a binary glTF 2.0 file (``.glb``), written by Blender.

glTF is the open format of web viewers, Godot and three.js (y up, metres). The BVH is imported into Blender and
exported with Blender's glTF exporter (:mod:`.blender_child`), every frame sampled. Needs the ``blender`` extra
(``bpy``); ``tests/integration/test_blender_export.py`` reads the file back into Blender and compares every bone
with the BVH's.
"""
from __future__ import annotations

from ...core.node import node
from ..ports import BVH_FILE, GLB_FILE
from .blender_child import write_with_blender
from .fbx import BlenderExportParams


@node("export.gltf", version=1, inputs={"bvh": BVH_FILE}, outputs={"glb": GLB_FILE}, params=BlenderExportParams)
def export_gltf(ctx, bvh):
    """Convert the BVH into a binary glTF file with Blender (every frame sampled, bones named like the joints).

    Output ``glb``: the file (``motion.glb``)."""
    return write_with_blender(ctx, bvh, "glb")
