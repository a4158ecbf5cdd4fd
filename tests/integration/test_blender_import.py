"""BVH files written by ``export.bvh``, imported into real Blender (``bpy`` 5.0.1, headless), land where
the project's own forward kinematics of the exported rotations puts them: every joint and every End
Site within 1 mm on every frame.

Blender runs in a child process (``python -c`` with ``bpy``): ``bpy`` is a whole Blender in one module
(0.5 s to import, global state of its own), kept out of pytest's process. The child imports each file
with ``bpy.ops.import_anim.bvh`` into an empty scene, steps through the frames (the importer keys BVH
frame ``i``, 0-based, at Blender frame ``frame_start + i``, ``frame_start=1``) and records, per bone,
``matrix_world @ pose_bone.head`` and ``matrix_world @ pose_bone.tail`` in world space. Blender makes
one bone per BVH joint, named like the joint, from the joint to its only child (or to its End Site for
a leaf): a bone's head is its joint, a leaf bone's tail its End Site.

Import settings: the importer's defaults (``axis_forward='-Z', axis_up='Y'``) bake the axis change
BVH (x, y, z) -> Blender (x, -z, y) into the armature (``matrix_world`` stays identity);
``axis_forward='Y', axis_up='Z'`` means no conversion. Files in centimetres (presets ``y-up``,
``mixamo``) are imported with ``global_scale=0.01``. Blender ignores a non-zero root OFFSET and takes
the root position channels as absolute, as the project's reader does. See docs/blender.md.
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
from tbha_graph.mocap.export.bvh import export_bvh, joint_names_for
from tbha_graph.mocap.export.presets import get_preset
from tbha_graph.mocap.io.skeleton_map import rotations16_from_bvh
from tbha_graph.mocap.kinematics import forward_kinematics
from tbha_graph.mocap.quat import quat_apply
from tbha_graph.mocap.skeleton import JOINT_NAMES, PARENTS

REPO = Path(__file__).resolve().parents[2]
CMU_CLIP = REPO / "data" / "mocap" / "cmu" / "131_02.bvh"
DEFAULT_PIPELINE = REPO / "pipelines" / "default.yaml"
SAMPLE_VIDEO = REPO / "data" / "sample" / "sample.mp4"
TOLERANCE_MM = 1.0
#: frames of the CMU clip used (every 15th of 720: 48 frames spanning the whole 6 s walk)
FRAME_STEP = 15
#: frames of the bundled sample video run through the default pipeline (T-pose lead-in, then walking)
DEFAULT_PIPELINE_FRAMES = 60

#: Blender coordinates of a point with BVH coordinates (x, y, z), importer defaults: (x, -z, y).
DEFAULT_AXES = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
NO_CONVERSION = {"axis_forward": "Y", "axis_up": "Z"}
LEAVES = [j for j in range(len(JOINT_NAMES)) if j not in set(PARENTS.tolist())]

# Runs inside the child process: import each BVH of a job list into an empty scene, sample every
# frame, write one JSON report.
BLENDER_SCRIPT = textwrap.dedent(
    r"""
    import json, sys
    import bpy

    jobs = json.load(open(sys.argv[1]))
    result = {"version": bpy.app.version_string, "imports": {}}
    for job in jobs:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        status = bpy.ops.import_anim.bvh(filepath=job["bvh"], **job["settings"])
        (arm,) = bpy.data.objects
        action = arm.animation_data.action
        first, last = (int(round(f)) for f in action.frame_range)
        heads, tails = [], []
        for frame in range(first, last + 1):
            scene.frame_set(frame)
            mw = arm.matrix_world
            heads.append([list(mw @ pb.head) for pb in arm.pose.bones])
            tails.append([list(mw @ pb.tail) for pb in arm.pose.bones])
        result["imports"][job["label"]] = {
            "status": sorted(status),
            "object_type": arm.type,
            "matrix_world": [list(r) for r in arm.matrix_world],
            "frame_range": [first, last],
            "bones": [pb.name for pb in arm.pose.bones],
            "heads": heads,
            "tails": tails,
        }
    json.dump(result, open(sys.argv[2], "w"))
    """
)


BPY_INSTALL = "pip install --no-deps bpy==5.0.1"


def _bpy_missing() -> str:
    """'' when a child Python can import bpy, else why not."""
    probe = subprocess.run([sys.executable, "-c", "import bpy"], capture_output=True, text=True, timeout=120)
    if probe.returncode == 0:
        return ""
    last = (probe.stderr.strip().splitlines() or ["(no message)"])[-1]
    return (f"bpy (Blender as a Python module) is not importable: {last}; "
            f"install it with `{BPY_INSTALL}` (not a plain `pip install bpy`, which downgrades numpy below 2 "
            f"and breaks OpenCV; see docs/blender.md)")


@pytest.fixture(scope="module")
def blender() -> None:
    reason = _bpy_missing()
    if reason:
        pytest.skip(reason)


def import_in_blender(jobs: list[dict], work: Path) -> dict:
    """Run BLENDER_SCRIPT on ``jobs`` ({label, bvh, settings}) in a child process; returns its report."""
    (work / "jobs.json").write_text(json.dumps(jobs))
    proc = subprocess.run(
        [sys.executable, "-c", BLENDER_SCRIPT, str(work / "jobs.json"), str(work / "blender.json")],
        capture_output=True, text=True, timeout=300, env=dict(os.environ, PYTHONNOUSERSITE="1"), cwd=work,
    )
    assert proc.returncode == 0, f"Blender import failed:\n{proc.stdout[-2000:]}\n{proc.stderr[-4000:]}"
    report = json.loads((work / "blender.json").read_text())
    assert report["version"].startswith("5.0")
    return report


def import_settings(preset: str, convert: bool = True) -> dict:
    s = {"target": "ARMATURE", "frame_start": 1, "use_fps_scale": False, "update_scene_fps": False,
         "rotate_mode": "NATIVE", "global_scale": 1.0 / get_preset(preset).units_per_metre}
    return s if convert else {**s, **NO_CONVERSION}


def expected_points(rot: dict[str, np.ndarray]) -> tuple[np.ndarray, dict[int, np.ndarray]]:
    """FK of a ROTATIONS bundle: joints (n, 16, 3) and End Sites {leaf: (n, 3)}, metres, world axes."""
    pos, world = forward_kinematics(PARENTS, rot["offsets"], rot["local_quat"], rot["root_position"])
    return pos, {j: pos[:, j] + quat_apply(world[:, j], rot["end_offsets"][j]) for j in LEAVES}


def blender_errors_mm(imp: dict, rot: dict[str, np.ndarray], axes: np.ndarray, names: list[str]) -> tuple[float, float]:
    """Worst joint (bone head) and End Site (leaf bone tail) distance, mm, of one import from FK."""
    want_pos, want_ends = expected_points(rot)
    n = want_pos.shape[0]
    assert imp["status"] == ["FINISHED"] and imp["object_type"] == "ARMATURE"
    assert imp["frame_range"] == [1, n], "BVH frame i is keyed at Blender frame 1 + i"
    assert np.allclose(imp["matrix_world"], np.eye(4)), "the axis conversion is baked into the armature"
    bones = imp["bones"]
    assert sorted(bones) == sorted(names), "one Blender bone per BVH joint, named like the joint"
    order = [bones.index(nm) for nm in names]
    heads = np.asarray(imp["heads"])[:, order]  # (n, 16, 3) metres, Blender axes, our joint order
    tails = np.asarray(imp["tails"])[:, order]
    head_err = np.linalg.norm(heads - want_pos @ axes.T, axis=-1) * 1000.0
    end_err = max(float(np.linalg.norm(tails[:, j] - want_ends[j] @ axes.T, axis=-1).max()) for j in LEAVES) * 1000.0
    f, j = np.unravel_index(int(np.argmax(head_err)), head_err.shape)
    print(f"blender: worst joint {JOINT_NAMES[j]} frame {f}: {head_err[f, j]:.5f} mm; worst End Site {end_err:.5f} mm")
    return float(head_err.max()), end_err


@pytest.fixture(scope="module")
def cmu_rotations() -> dict[str, np.ndarray]:
    return cmu_motion()


def cmu_motion() -> dict[str, np.ndarray]:
    """The ROTATIONS bundle of the CMU walk, every :data:`FRAME_STEP`-th frame."""
    rot = rotations16_from_bvh(CMU_CLIP)
    sl = slice(0, None, FRAME_STEP)
    return {**rot, "local_quat": rot["local_quat"][sl], "root_position": rot["root_position"][sl],
            "fps": np.asarray(float(rot["fps"]) / FRAME_STEP)}


PRESETS = ["none", "blender", "y-up", "mixamo"]


def test_exported_cmu_motion_matches_fk_in_blender(blender, cmu_rotations, tmp_path) -> None:
    """Every export preset, imported the way docs/blender.md says, puts every joint within 1 mm; and a
    non-zero root offset, written to the root OFFSET, moves nothing (Blender and the project both take
    the root position channels as absolute). One Blender process imports all the files."""
    rot = cmu_rotations
    assert rot["local_quat"].shape[0] >= 40
    jobs = []
    for preset in PRESETS:
        d = tmp_path / preset
        d.mkdir()
        path = run_node(export_bvh, {"preset": preset, "sheet": False}, work_dir=d, rotations=rot)["bvh"]
        jobs.append({"label": preset, "bvh": str(path), "settings": import_settings(preset)})
    jobs.append({"label": "none, no conversion", "bvh": jobs[0]["bvh"], "settings": import_settings("none", convert=False)})
    shifted = {**rot, "local_quat": rot["local_quat"][:8], "root_position": rot["root_position"][:8],
               "offsets": rot["offsets"].copy()}
    shifted["offsets"][0] = [0.3, -0.2, 0.5]
    (tmp_path / "offset").mkdir()
    path = run_node(export_bvh, {"sheet": False}, work_dir=tmp_path / "offset", rotations=shifted)["bvh"]
    assert Path(path).read_text().splitlines()[3].split() == ["OFFSET", "0.300000", "-0.200000", "0.500000"]
    jobs.append({"label": "root offset", "bvh": str(path), "settings": import_settings("none")})
    report = import_in_blender(jobs, tmp_path)["imports"]

    for preset in PRESETS:
        head_mm, end_mm = blender_errors_mm(report[preset], rot, DEFAULT_AXES, joint_names_for(get_preset(preset).naming))
        assert head_mm < TOLERANCE_MM and end_mm < TOLERANCE_MM, preset
    head_mm, end_mm = blender_errors_mm(report["none, no conversion"], rot, np.eye(3), list(JOINT_NAMES))
    assert head_mm < TOLERANCE_MM and end_mm < TOLERANCE_MM
    head_mm, end_mm = blender_errors_mm(report["root offset"], shifted, DEFAULT_AXES, list(JOINT_NAMES))
    assert head_mm < TOLERANCE_MM and end_mm < TOLERANCE_MM

    # the comparison discriminates: the walk covers metres, and the other axis convention is far off
    pos, _ = expected_points(rot)
    assert np.ptp(pos[:, 0], axis=0).max() > 0.5
    imp = report["none"]
    heads = np.asarray(imp["heads"])[:, [imp["bones"].index(nm) for nm in JOINT_NAMES]]
    assert np.linalg.norm(heads - pos, axis=-1).max() * 1000.0 > 100.0


def test_default_pipeline_bvh_matches_fk_in_blender(blender, tmp_path) -> None:
    """``pipelines/default.yaml`` on the first frames of the bundled sample video: its ``motion.bvh``,
    imported with Blender's defaults, against FK of the pipeline's own ``rotations`` output."""
    if not (DEFAULT_PIPELINE.is_file() and SAMPLE_VIDEO.is_file()):
        pytest.skip("pipelines/default.yaml or data/sample/sample.mp4 is missing")
    from tbha_graph.core.runner import load_graph, run_graph

    graph = load_graph(DEFAULT_PIPELINE, sets={"decode.stop": DEFAULT_PIPELINE_FRAMES})
    run = run_graph(graph, outputs=["motion.bvh"], cache=False, out_dir=tmp_path / "run")
    rid = graph.outputs["motion.bvh"][0]
    src, port = graph.nodes[rid].inputs["rotations"]
    rot = run.results[src].value(port, graph.nodes[src])
    assert rot["local_quat"].shape[0] == DEFAULT_PIPELINE_FRAMES
    bvh = tmp_path / "run" / "motion.bvh"
    preset = graph.nodes[rid].params.preset
    report = import_in_blender([{"label": "default", "bvh": str(bvh), "settings": import_settings(preset)}], tmp_path)
    head_mm, end_mm = blender_errors_mm(report["imports"]["default"], rot, DEFAULT_AXES,
                                       joint_names_for(get_preset(preset).naming))
    assert head_mm < TOLERANCE_MM and end_mm < TOLERANCE_MM
