"""Node ``export.bvh``: write joint rotations of the 16-joint model as a BVH file, and check it.

The file uses the names of :data:`tbha_graph.mocap.skeleton.JOINT_NAMES` (``ROOT hips``), y up, the
actor facing +z in the rest T-pose, one Euler order for every joint (``rotation_order``, default ZXY),
6 channels on the root and 3 on every other joint, End Sites on the leaf joints (head, wrists, ankles)
from ``end_offsets``. Lengths are metres times ``scale``. After writing, the node reads the file back
and compares forward kinematics of the file with that of its input: a joint off by more than 0.1 mm on
any frame fails the node (a self-check, not a warning).

``preset`` (``blender``, ``y-up``, ``mixamo``; see :mod:`.presets`) lays the file out for an
application instead: its units, Euler order and (``mixamo``) joint names, unless ``scale`` or
``rotation_order`` are set explicitly. With any preset the self-check also verifies that the rest pose
stands upright and faces forward in that application's axes. The ``sheet`` output is a contact-sheet
PNG of a few frames as the application will show them (front and side views).
"""
from __future__ import annotations

from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.atomic import atomic_write_bytes
from ...core.node import node
from ..bundles.rotations import checked_rotations
from ..ports import BVH_FILE, IMAGE, ROTATIONS
from ..skeleton import JOINT_INDEX, JOINT_NAMES, PARENTS
from .presets import contact_sheet, get_preset, write_checked

#: Largest allowed difference between the written file and the input, metres.
SELF_CHECK_TOLERANCE_M = 1e-4

#: Joints drawn as the actor's left / right side on the contact sheet.
LEFT_JOINTS = tuple(i for i, n in enumerate(JOINT_NAMES) if n.startswith("left_"))
RIGHT_JOINTS = tuple(i for i, n in enumerate(JOINT_NAMES) if n.startswith("right_"))
#: (hips, head, left, right) joints of the upright / facing self-check.
ORIENTATION_JOINTS = (JOINT_INDEX["hips"], JOINT_INDEX["head"], JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"])


class ExportBvhParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    preset: Literal["none", "blender", "y-up", "mixamo"] = Field(
        "none",
        description="target application layout: 'none' (y up, faces +z, scale/rotation_order as given), "
        "'blender' (metres, for Blender's default import), 'y-up' (Maya/MotionBuilder/Unity, centimetres), "
        "'mixamo' (Mixamo rig names, centimetres); see tbha_graph/mocap/export/presets.py",
    )
    rotation_order: str = Field(
        "ZXY",
        pattern=r"^(XYZ|XZY|YXZ|YZX|ZXY|ZYX)$",
        description="Euler channel order written for every joint (intrinsic, as in BVH), e.g. ZXY or ZYX; "
        "with a preset, the preset's order unless set explicitly",
    )
    precision: int = Field(6, ge=1, le=12, description="decimals written for offsets and channel values")
    scale: float = Field(
        1.0, gt=0, description="file units per metre: 1 writes metres, 100 centimetres; with a preset, the "
        "preset's units unless set explicitly",
        json_schema_extra={"unit": "file units / m"},
    )
    sheet: bool = Field(True, description="draw the contact sheet (a few frames, front and side views); when "
                        "false the 'sheet' output is a small placeholder image")
    sheet_frames: int = Field(4, ge=1, le=12, description="frames drawn on the contact sheet")

    def effective(self) -> dict:
        """What the outputs depend on, for the cache key: the resolved layout (a preset's values unless
        ``scale`` / ``rotation_order`` are set explicitly), not the params as written. The preset's name
        and application appear only in the contact sheet's title."""
        layout = preset_for(self)
        out = {
            "layout": {k: getattr(layout, k) for k in ("file_axes", "units_per_metre", "rotation_order", "naming",
                                                       "app_axes", "app_up", "app_forward", "tolerance_m")},
            "precision": self.precision,
            "sheet": self.sheet,
        }
        if self.sheet:
            out["sheet_frames"] = self.sheet_frames
            out["sheet_title"] = [layout.name, layout.app]
        return out



def preset_for(p: ExportBvhParams):
    """The :class:`.presets.Preset` these params ask for (explicit ``scale`` / ``rotation_order`` win)."""
    preset = get_preset(p.preset)
    changes = {"tolerance_m": SELF_CHECK_TOLERANCE_M}
    if p.preset == "none" or "scale" in p.model_fields_set:
        changes["units_per_metre"] = p.scale
    if p.preset == "none" or "rotation_order" in p.model_fields_set:
        changes["rotation_order"] = p.rotation_order
    return preset.replace(**changes)


def joint_names_for(naming: str) -> list[str]:
    """The 16 joint names written for a preset's ``naming`` (``"tbha"`` or ``"mixamo"``)."""
    if naming == "mixamo":
        from ..io.skeleton_map import load_mapping

        mapping = load_mapping("mixamo").joints
        return [mapping[n] for n in JOINT_NAMES]
    return list(JOINT_NAMES)


def placeholder_png(path: Path, text: str) -> Path:
    """A small PNG saying why there is no contact sheet (the output port always holds a file)."""
    import cv2

    img = np.full((40, 420, 3), 255, dtype=np.uint8)
    cv2.putText(img, text, (8, 26), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (60, 60, 60), 1, cv2.LINE_AA)
    _, buf = cv2.imencode(".png", img)
    atomic_write_bytes(path, buf.tobytes())
    return path


@node("export.bvh", version=2, inputs={"rotations": ROTATIONS},
      outputs={"bvh": BVH_FILE, "sheet": IMAGE},
      params=ExportBvhParams)
def export_bvh(ctx, rotations):
    """Write the 16-joint rotations as a BVH file (y up, facing +z, or an application preset) and verify it by reading it back."""
    p = ctx.params
    preset = preset_for(p)
    local, root, offsets, ends, fps = checked_rotations(rotations)
    names = joint_names_for(preset.naming)
    end_mask = [j not in set(PARENTS.tolist()) for j in range(len(JOINT_NAMES))]
    path, got, worst = write_checked(
        ctx.output_path("motion.bvh"), preset, names=names, parents=PARENTS, offsets=offsets, ends=ends,
        end_mask=end_mask, local=local, root=root, fps=fps, precision=p.precision, orient=ORIENTATION_JOINTS,
    )
    ctx.log(f"wrote {got.bvh.n_frames} frames (preset '{preset.name}'); self-check: worst joint off by {worst * 1000:.5f} mm")
    sheet = ctx.output_path("sheet.png")
    if p.sheet:
        contact_sheet(sheet, preset, got.app_positions, PARENTS, left=LEFT_JOINTS, right=RIGHT_JOINTS,
                      hips_pair=ORIENTATION_JOINTS[2:],
                      frames=p.sheet_frames, fps=fps,
                      title=f"{path.name}, preset '{preset.name}': {preset.app}; self-check {worst * 1000:.3f} mm")
    else:
        placeholder_png(sheet, "contact sheet disabled (export.bvh param sheet: false)")
    return {"bvh": path, "sheet": sheet}
