"""``export.fbx`` and ``export.gltf`` (Blender's exporters, run by the project in a child process): each file,
read back into a fresh real Blender with Blender's own FBX / glTF importer, puts every joint where the project's
forward kinematics of the exported rotations puts it, on every frame, within 1 mm.

The BVH they convert is checked the same way by ``test_blender_import.py`` (whose helpers this file uses); here
the chain BVH -> Blender -> FBX / glTF -> Blender is closed against the FK directly. Blender's world axes after
either importer are those of its BVH import with the defaults: file (x, y, z) -> Blender (x, -z, y).
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
from test_blender_import import DEFAULT_AXES, _bpy_missing, cmu_motion, expected_points

from tbha_graph.core.errors import NodeError
from tbha_graph.core.testing import run_node
from tbha_graph.mocap.export.bvh import export_bvh
from tbha_graph.mocap.export.fbx import export_fbx
from tbha_graph.mocap.export.gltf import export_gltf
from tbha_graph.mocap.skeleton import JOINT_NAMES

TOLERANCE_MM = 1.0

# Runs in the child: read each file with Blender's importer into an empty scene, record every bone's head in world
# space on every frame of the scene's range.
READ_BACK = textwrap.dedent(r"""
    import json, sys
    import bpy

    out = {}
    job = json.loads(sys.argv[1])
    for label, path in job["files"].items():
        bpy.ops.wm.read_factory_settings(use_empty=True)
        bpy.context.scene.render.fps = job["fps"]  # glTF keeps seconds: its importer keys them at the scene's rate
        if path.endswith(".fbx"):
            bpy.ops.import_scene.fbx(filepath=path)
        else:
            bpy.ops.import_scene.gltf(filepath=path)
        (arm,) = [o for o in bpy.data.objects if o.type == "ARMATURE"]
        scene = bpy.context.scene
        first, last = (int(round(f)) for f in arm.animation_data.action.frame_range)
        heads = []
        for frame in range(first, last + 1):
            scene.frame_set(frame)
            heads.append([list(arm.matrix_world @ pb.head) for pb in arm.pose.bones])
        out[label] = {"bones": [pb.name for pb in arm.pose.bones], "heads": heads, "fps": scene.render.fps}
    print(json.dumps(out))
""")


@pytest.fixture(scope="module")
def blender() -> None:
    reason = _bpy_missing()
    if reason:
        pytest.skip(reason)


@pytest.fixture(scope="module")
def cmu_rotations() -> dict[str, np.ndarray]:
    return cmu_motion()


def read_back(files: dict[str, Path], fps: int) -> dict:
    job = {"files": {k: str(v) for k, v in files.items()}, "fps": fps}
    proc = subprocess.run([sys.executable, "-c", READ_BACK, json.dumps(job)],
                          capture_output=True, text=True, timeout=300, env=dict(os.environ, PYTHONNOUSERSITE="1"))
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads([line for line in proc.stdout.splitlines() if line.startswith("{")][-1])


def test_fbx_and_gltf_read_back_into_blender_where_the_fk_puts_the_joints(blender, cmu_rotations, tmp_path):
    rot = cmu_rotations
    bvh = run_node(export_bvh, {"sheet": False}, work_dir=tmp_path / "bvh", rotations=rot)["bvh"]
    files = {"fbx": run_node(export_fbx, {}, work_dir=tmp_path / "fbx", bvh=bvh)["fbx"],
             "glb": run_node(export_gltf, {}, work_dir=tmp_path / "glb", bvh=bvh)["glb"]}
    assert files["fbx"].read_bytes()[:18] == b"Kaydara FBX Binary" and files["glb"].read_bytes()[:4] == b"glTF"
    back = read_back(files, round(float(rot["fps"])))
    want, _ = expected_points(rot)
    want = want @ DEFAULT_AXES.T  # (n, 16, 3) metres, Blender's axes
    for label, got in back.items():
        assert sorted(got["bones"]) == sorted(JOINT_NAMES), label  # one bone per joint, named like it, no leaf bones
        heads = np.asarray(got["heads"])[:, [got["bones"].index(n) for n in JOINT_NAMES]]
        assert heads.shape == want.shape, f"{label}: every frame keyed ({heads.shape[0]} of {want.shape[0]})"
        err = np.linalg.norm(heads - want, axis=-1) * 1000.0
        print(f"{label}: worst joint {err.max():.4f} mm")
        assert err.max() < TOLERANCE_MM, label
    assert np.ptp(want, axis=0).max() > 0.5  # the walk covers metres: the comparison can tell


def test_without_blender_the_node_says_how_to_install_it(tmp_path, monkeypatch, cmu_rotations):
    import importlib.util

    bvh = run_node(export_bvh, {"sheet": False}, work_dir=tmp_path / "bvh", rotations=cmu_rotations)["bvh"]
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "bpy" else real(name, *a))
    with pytest.raises(NodeError) as e:
        run_node(export_fbx, {}, work_dir=tmp_path / "fbx", bvh=bvh)
    assert "bpy" in e.value.format() and "pip install --no-deps bpy==5.0.1" in e.value.format()


def test_a_file_blender_cannot_read_is_a_clear_error(blender, tmp_path):
    bad = tmp_path / "broken.bvh"
    bad.write_text("HIERARCHY\nROOT hips\n{\n  OFFSET 0 0\n")
    with pytest.raises(NodeError) as e:
        run_node(export_gltf, {}, work_dir=tmp_path / "glb", bvh=Path(bad))
    assert "Blender could not write motion.glb from broken.bvh" in e.value.format()
