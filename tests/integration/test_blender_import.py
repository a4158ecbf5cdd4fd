"""The BVH written by ``export.bvh`` imported into real Blender (``bpy`` 5.0.1, headless) lands where the
project's own forward kinematics puts it: every joint within 1 mm on every frame.

Blender runs in a child process (``python -c`` with ``bpy``): ``bpy`` is a whole Blender in one module
(0.5 s to import, its own global state), kept out of pytest's process. The child imports the file with
``bpy.ops.import_anim.bvh`` twice:

* with the importer's defaults (``axis_forward='-Z', axis_up='Y'``), which bake the axis change
  BVH (x, y, z) -> Blender (x, -z, y) into the armature (its ``matrix_world`` stays identity);
* with ``axis_forward='Y', axis_up='Z'`` (no conversion): Blender coordinates equal BVH coordinates.

Then it steps through the frames (the importer keys BVH frame ``i``, 0-based, at Blender frame
``frame_start + i``, ``frame_start=1``) and records, per bone, ``matrix_world @ pose_bone.head`` and
``matrix_world @ pose_bone.tail`` in world space. Blender makes one bone per BVH joint, named like the
joint, running from the joint to its only child (or to its End Site for a leaf): a bone's head is its
joint; a leaf bone's tail is the End Site. Blender ignores a non-zero root OFFSET and treats the root
position channels as absolute, as the project's reader does.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from tbha_graph.core.testing import run_node
from tbha_graph.mocap.export.bvh import export_bvh
from tbha_graph.mocap.io.skeleton_map import rotations16_from_bvh
from tbha_graph.mocap.kinematics import forward_kinematics, quat_apply
from tbha_graph.mocap.skeleton import JOINT_NAMES, PARENTS

REPO = Path(__file__).resolve().parents[2]
CMU_CLIP = REPO / "data" / "mocap" / "cmu" / "131_02.bvh"
TOLERANCE_MM = 1.0
#: frames of the CMU clip used (every 15th of 720: 48 frames spanning the whole 6 s walk)
FRAME_STEP = 15

#: Blender coordinates of a point with BVH coordinates (x, y, z), importer defaults: (x, -z, y).
DEFAULT_AXES = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])

# Runs inside the child process: import the BVH twice, sample every frame, write JSON.
BLENDER_SCRIPT = textwrap.dedent(
    r"""
    import json, sys
    import bpy

    bvh_path, out_path = sys.argv[1], sys.argv[2]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    result = {"version": bpy.app.version_string, "imports": {}}
    settings = {
        "default": {},  # the importer's own defaults: axis_forward='-Z', axis_up='Y'
        "no_conversion": {"axis_forward": "Y", "axis_up": "Z"},
    }
    for label, axes in settings.items():
        before = set(bpy.data.objects)
        status = bpy.ops.import_anim.bvh(
            filepath=bvh_path, target="ARMATURE", global_scale=1.0, frame_start=1,
            use_fps_scale=False, update_scene_fps=False, update_scene_duration=True,
            rotate_mode="NATIVE", **axes)
        (arm,) = [o for o in bpy.data.objects if o not in before]
        action = arm.animation_data.action
        first, last = (int(round(f)) for f in action.frame_range)
        heads, tails = [], []
        for frame in range(first, last + 1):
            scene.frame_set(frame)
            mw = arm.matrix_world
            names = [pb.name for pb in arm.pose.bones]
            heads.append([list(mw @ pb.head) for pb in arm.pose.bones])
            tails.append([list(mw @ pb.tail) for pb in arm.pose.bones])
        result["imports"][label] = {
            "status": sorted(status),
            "object_type": arm.type,
            "matrix_world": [list(r) for r in arm.matrix_world],
            "frame_range": [first, last],
            "bones": names,
            "heads": heads,
            "tails": tails,
        }
    with open(out_path, "w") as f:
        json.dump(result, f)
    """
)


def _bpy_available() -> str:
    """'' when a child Python can import bpy, else the reason it cannot."""
    probe = subprocess.run([sys.executable, "-c", "import bpy"], capture_output=True, text=True, timeout=120)
    if probe.returncode == 0:
        return ""
    last = (probe.stderr.strip().splitlines() or ["(no message)"])[-1]
    return f"bpy (Blender as a Python module) is not importable here: {last}; install it with `pip install bpy==5.0.1` (see docs/blender.md)"


@pytest.fixture(scope="module")
def blender() -> None:
    reason = _bpy_available()
    if reason:
        pytest.skip(reason)


def blender_import(bvh_path: Path, out_json: Path) -> dict:
    """Import ``bvh_path`` in a Blender child process; returns its JSON report (see BLENDER_SCRIPT)."""
    env = dict(os.environ, PYTHONNOUSERSITE="1")
    proc = subprocess.run(
        [sys.executable, "-c", BLENDER_SCRIPT, str(bvh_path), str(out_json)],
        capture_output=True, text=True, timeout=300, env=env, cwd=out_json.parent,
    )
    assert proc.returncode == 0, f"Blender import failed:\n{proc.stdout[-2000:]}\n{proc.stderr[-4000:]}"
    return json.loads(out_json.read_text())


def expected_points(rot: dict[str, np.ndarray]) -> tuple[np.ndarray, dict[int, np.ndarray]]:
    """Forward kinematics of a ROTATIONS bundle: joints (n, 16, 3) and End Sites {leaf: (n, 3)}, metres, BVH axes."""
    pos, world = forward_kinematics(PARENTS, rot["offsets"], rot["local_quat"], rot["root_position"])
    leaves = [j for j in range(len(JOINT_NAMES)) if j not in set(PARENTS.tolist())]
    ends = {j: pos[:, j] + quat_apply(world[:, j], rot["end_offsets"][j]) for j in leaves}
    return pos, ends


def compare(report: dict, rot: dict[str, np.ndarray], axes: np.ndarray) -> tuple[float, float]:
    """Worst joint (head) and End Site (leaf tail) error in mm of one Blender import against FK."""
    want_pos, want_ends = expected_points(rot)
    n = want_pos.shape[0]
    assert report["frame_range"] == [1, n], "the importer keys BVH frame i at Blender frame 1 + i"
    assert report["object_type"] == "ARMATURE"
    assert np.allclose(report["matrix_world"], np.eye(4)), "the axis conversion is baked into the armature"
    bones = report["bones"]
    assert sorted(bones) == sorted(JOINT_NAMES), "one Blender bone per BVH joint, named like the joint"
    heads = np.asarray(report["heads"])  # (n, 16, 3) metres, Blender axes, bone order
    tails = np.asarray(report["tails"])
    order = [bones.index(name) for name in JOINT_NAMES]
    got_pos = heads[:, order]
    head_err = np.linalg.norm(got_pos - want_pos @ axes.T, axis=-1) * 1000.0
    end_err = max(
        float(np.max(np.linalg.norm(tails[:, bones.index(JOINT_NAMES[j])] - e @ axes.T, axis=-1))) * 1000.0
        for j, e in want_ends.items()
    )
    worst = np.unravel_index(int(np.argmax(head_err)), head_err.shape)
    print(f"blender: worst joint {JOINT_NAMES[worst[1]]} on frame {worst[0]}: {head_err[worst]:.5f} mm; "
          f"worst End Site {end_err:.5f} mm")
    return float(head_err.max()), end_err


@pytest.fixture(scope="module")
def cmu_rotations() -> dict[str, np.ndarray]:
    rot = rotations16_from_bvh(CMU_CLIP)
    sl = slice(0, None, FRAME_STEP)
    return {**rot, "local_quat": rot["local_quat"][sl], "root_position": rot["root_position"][sl],
            "fps": np.asarray(float(rot["fps"]) / FRAME_STEP)}


def test_exported_cmu_bvh_matches_forward_kinematics_in_blender(blender, cmu_rotations, tmp_path) -> None:
    rot = cmu_rotations
    n = rot["local_quat"].shape[0]
    assert n >= 40
    path = run_node(export_bvh, {}, work_dir=tmp_path, rotations=rot)["bvh"]
    report = blender_import(Path(path), tmp_path / "blender.json")
    assert report["version"].startswith("5.0")

    # importer defaults: BVH (x, y, z) -> Blender (x, -z, y)
    head_mm, end_mm = compare(report["imports"]["default"], rot, DEFAULT_AXES)
    assert head_mm < TOLERANCE_MM and end_mm < TOLERANCE_MM
    # axis_forward='Y', axis_up='Z': no conversion
    head_mm2, end_mm2 = compare(report["imports"]["no_conversion"], rot, np.eye(3))
    assert head_mm2 < TOLERANCE_MM and end_mm2 < TOLERANCE_MM

    # the comparison discriminates: the motion moves metres, and the wrong axis convention is far off
    pos, _ = expected_points(rot)
    assert np.ptp(pos[:, 0], axis=0).max() > 0.5, "the clip should travel (a walk)"
    heads = np.asarray(report["imports"]["default"]["heads"])
    order = [report["imports"]["default"]["bones"].index(nm) for nm in JOINT_NAMES]
    wrong = np.linalg.norm(heads[:, order] - pos, axis=-1).max() * 1000.0
    assert wrong > 100.0, "without the axis change the default import must not match"


def test_non_zero_root_offset_is_ignored_like_blender(blender, cmu_rotations, tmp_path) -> None:
    """A ROTATIONS bundle whose root offset is non-zero: the file's root OFFSET must not move anything
    (Blender and the project both treat the root position channels as absolute)."""
    rot = dict(cmu_rotations)
    rot["local_quat"] = rot["local_quat"][:8]
    rot["root_position"] = rot["root_position"][:8]
    offsets = rot["offsets"].copy()
    offsets[0] = [0.3, -0.2, 0.5]
    rot["offsets"] = offsets
    path = run_node(export_bvh, {}, work_dir=tmp_path, rotations=rot)["bvh"]
    text = Path(path).read_text()
    assert "OFFSET 0.300000 -0.200000 0.500000" in text.splitlines()[3]
    report = blender_import(Path(path), tmp_path / "blender.json")
    head_mm, end_mm = compare(report["imports"]["default"], rot, DEFAULT_AXES)
    assert head_mm < TOLERANCE_MM and end_mm < TOLERANCE_MM
