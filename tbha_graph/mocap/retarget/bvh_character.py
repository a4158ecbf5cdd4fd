"""Node ``retarget.bvh_character``: the captured motion written onto the user's character skeleton.

The character is a BVH file exported from the user's rig (only its hierarchy is used: joint names,
parents, rest offsets, End Sites; the rest pose need not be a T-pose). A skeleton mapping (bundled
``mixamo`` or ``cmu``, or a YAML path) names the character joint of each of the 16 TBHA joints and the
file's units and axes. The output BVH has the character's names, hierarchy and offsets; the rotations
are transferred through the rest poses (:mod:`.alignment`, :mod:`.transfer`): every mapped bone points
where the capture's bone points, joints the capture lacks stay at rest or share the spine bend, and the
root travels the capture's path scaled by the ratio of hip-to-ankle heights, so a child or a giant
keeps its feet on the floor.

``preset`` ``character`` (default) writes the file in the character's own axes, units and per-joint
Euler orders; ``blender``, ``y-up`` and ``mixamo`` (see :mod:`tbha_graph.mocap.export.presets`) set
those for an application (names and rest pose stay the character's; ``mixamo`` requires a
Mixamo-named character). The written file is read back and every joint must land within 0.1 mm of
the retargeted pose on every frame, and its rest pose must stand upright facing forward in the
preset's application; a failure is an error.
"""
from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.errors import NodeError
from ...core.node import InputPath, node
from ..bundles.rotations import checked_rotations
from ..export.bvh import placeholder_png
from ..export.presets import Preset, contact_sheet, get_preset, write_checked
from ..ports import BVH_FILE, IMAGE, REPORT, ROTATIONS
from ..skeleton import JOINT_INDEX, JOINT_NAMES
from .character import Character, load_character
from .transfer import retarget, segment_direction_errors

#: Allowed read-back error of the written file against the retargeted pose, metres.
TOLERANCE_M = 1e-4


class RetargetParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    character: InputPath = Field(
        description="the user's character skeleton as a BVH file (its hierarchy and rest offsets are used; "
        "relative paths start from the pipeline file's folder)"
    )
    mapping: str = Field(
        "mixamo", min_length=1,
        description="skeleton mapping TBHA joint -> character joint: a bundled name ('mixamo', 'cmu') or the "
        "path of a mapping YAML file (joints, units_to_metres, axes)",
    )
    units_to_metres: float | None = Field(
        None, gt=0, description="metres per character file unit; overrides the mapping's value",
        json_schema_extra={"unit": "m"},
    )
    preset: Literal["character", "blender", "y-up", "mixamo"] = Field(
        "character",
        description="file layout: 'character' (the character file's own axes, units and Euler orders) or an "
        "application preset ('blender', 'y-up', 'mixamo'; see tbha_graph/mocap/export/presets.py)",
    )
    between: Literal["distribute", "rest"] = Field(
        "distribute",
        description="character joints between two mapped spine/neck joints (e.g. Spine, Spine1): share the bend "
        "evenly ('distribute') or stay at rest with the whole bend at the mapped joint ('rest')",
    )
    floor: Literal["clip", "origin"] = Field(
        "clip",
        description="root height: 'clip' puts the character's planted ankles at their rest height above its floor "
        "(y = 0) when the capture's ankles are at their planted height (5th percentile over the clip); 'origin' "
        "scales the height about y = 0",
    )
    rotation_order: str | None = Field(
        None, pattern=r"^(XYZ|XZY|YXZ|YZX|ZXY|ZYX)$",
        description="Euler channel order for every joint; default: the preset's (or, for 'character', each "
        "joint's own order in the character file)",
    )
    precision: int = Field(6, ge=1, le=12, description="decimals written for offsets and channel values")
    sheet: bool = Field(True, description="draw the contact sheet (front and side views of a few frames); when "
                        "false the 'sheet' output is a small placeholder image")
    sheet_frames: int = Field(4, ge=1, le=12, description="frames drawn on the contact sheet")


def character_preset(char: Character) -> Preset:
    """The layout of the character's own file: its axes and units, viewed in its own (world) frame."""
    return Preset(
        name="character",
        summary=f"the character file's own axes ({char.mapping.axes}) and units ({char.units_to_metres:g} m)",
        file_axes=char.mapping.axes,
        units_per_metre=1.0 / char.units_to_metres,
        app="the character's own frame (y up, faces +z)",
        app_axes=char.mapping.axes,
        tolerance_m=TOLERANCE_M,
    )


def _preset(p: RetargetParams, char: Character) -> tuple[Preset, list[str]]:
    if p.preset == "character":
        preset = character_preset(char)
        orders = list(char.orders)
    else:
        preset = get_preset(p.preset).replace(tolerance_m=TOLERANCE_M)
        orders = [preset.rotation_order] * char.n_joints
        if preset.naming == "mixamo":
            from ..io.skeleton_map import load_mapping

            want = load_mapping("mixamo").joints
            wrong = [f"{n}: {char.names[t]}" for n, t in zip(JOINT_NAMES, char.mapped) if char.names[t] != want[n]]
            if wrong:
                raise NodeError(
                    f"preset 'mixamo' needs a Mixamo-named character, but {char.path.name} maps {', '.join(wrong[:3])}"
                    + (" ..." if len(wrong) > 3 else ""),
                    hint="retargeting keeps the character's own joint names: use preset 'y-up' (centimetres, y up) "
                    "for this character, or retarget onto a Mixamo rig with mapping 'mixamo'",
                )
    if p.rotation_order:
        orders = [p.rotation_order] * char.n_joints
    return preset, orders


def _sides(char: Character) -> tuple[list[int], list[int]]:
    """Character joints on the left (rest x > 2 cm) and right (x < -2 cm) side, for the contact sheet."""
    x = char.rest[:, 0] - char.rest[char.mapped[0], 0]
    return [int(j) for j in np.flatnonzero(x > 0.02)], [int(j) for j in np.flatnonzero(x < -0.02)]


@node(
    "retarget.bvh_character",
    version=1,
    inputs={"rotations": ROTATIONS},
    outputs={"bvh": BVH_FILE, "report": REPORT, "sheet": IMAGE},
    params=RetargetParams,
)
def bvh_character(ctx, rotations):
    """Write the motion onto the user's character skeleton (its names, hierarchy, rest pose) as a checked BVH."""
    p = ctx.params
    local16, root16, offsets16, ends16, fps = checked_rotations(rotations)
    char = load_character(p.character, p.mapping, p.units_to_metres)
    preset, orders = _preset(p, char)
    rot = {"local_quat": local16, "root_position": root16, "offsets": offsets16}
    ret = retarget(rot, char, p.between, p.floor)
    m = char.mapped
    orient = (int(m[JOINT_INDEX["hips"]]), int(m[JOINT_INDEX["head"]]), int(m[JOINT_INDEX["left_hip"]]),
              int(m[JOINT_INDEX["right_hip"]]))
    path, got, worst = write_checked(
        ctx.output_path("character.bvh"), preset, names=char.names, parents=char.parents, offsets=char.offsets,
        ends=char.ends, end_mask=char.end_mask, local=ret.local, root=ret.root, fps=fps, orders=orders,
        precision=p.precision, orient=orient,
    )
    directions = segment_direction_errors(ret, char)
    ctx.log(f"retargeted {local16.shape[0]} frames onto {char.path.name} (scale {ret.scale:.3f}); "
            f"self-check: worst joint off by {worst * 1000:.5f} mm")
    sheet = ctx.output_path("sheet.png")
    if p.sheet:
        left, right = _sides(char)
        contact_sheet(sheet, preset, got.app_positions, char.parents, left=left, right=right,
                      hips_pair=orient[2:], frames=p.sheet_frames, fps=fps,
                      title=f"{char.path.name} <- motion, preset '{preset.name}': {preset.app}; "
                      f"self-check {worst * 1000:.3f} mm")
    else:
        placeholder_png(sheet, "contact sheet disabled (retarget param sheet: false)")
    mapped_set = set(int(t) for t in m)
    report = {
        "character": char.path.name,
        "mapping": char.mapping._source,
        "preset": preset.name,
        "units_per_metre": preset.units_per_metre,
        "frames": int(local16.shape[0]),
        "fps": fps,
        "scale": ret.scale,
        "planted_ankle_height_m": None if ret.planted is None else {"capture": ret.planted[0], "character": ret.planted[1]},
        "mapped": {n: char.names[int(t)] for n, t in zip(JOINT_NAMES, m)},
        "distributed": ret.distributed,
        "at_rest": ret.at_rest,
        "unmapped": [n for i, n in enumerate(char.names) if i not in mapped_set],
        "self_check_worst_mm": worst * 1000.0,
        "bone_direction_error_deg": directions,
    }
    return {"bvh": path, "report": report, "sheet": sheet}
