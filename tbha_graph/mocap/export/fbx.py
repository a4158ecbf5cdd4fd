"""``export.fbx``: the motion as an FBX file for game engines (Unity, Unreal) and 3D tools, written by Blender.

The BVH (``export.bvh``'s, or any BVH) is imported into Blender and exported with Blender's FBX exporter
(:mod:`.blender_child`): an armature with one bone per joint, named like it, every frame keyed (no curve
simplification), no leaf bones added, Blender's default axes (-Z forward, Y up) and units. Needs the ``blender``
extra (``bpy``); ``tests/integration/test_blender_export.py`` reads the file back into Blender and compares every
bone with the BVH's.
"""
from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from ...core.node import node
from ..ports import BVH_FILE, FBX_FILE
from .blender_child import write_with_blender


class BlenderExportParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    scale: float = Field(1.0, gt=0, description="metres per BVH unit: 1 for export.bvh's presets none and blender, "
                         "0.01 for y-up and mixamo (centimetres)", json_schema_extra={"unit": "m"})
    timeout_s: float = Field(600.0, gt=0, description="longest Blender may take", json_schema_extra={"unit": "s"})


@node("export.fbx", version=1, inputs={"bvh": BVH_FILE}, outputs={"fbx": FBX_FILE}, params=BlenderExportParams)
def export_fbx(ctx, bvh):
    """Convert the BVH into an FBX file with Blender (every frame keyed, bones named like the joints).

    Output ``fbx``: the file (``motion.fbx``)."""
    return write_with_blender(ctx, bvh, "fbx")
