"""Converting a BVH file with Blender's own exporters, in a child process (``bpy``, the ``blender`` extra).

Game engines and most 3D tools import FBX or glTF, not BVH (Unity and Unreal have no BVH importer). Blender reads
the project's BVH exactly (``docs/blender.md``: every joint within 0.004 mm of the project's forward kinematics)
and writes both formats, so the conversion is Blender's: the BVH imported with the settings of
``docs/blender.md`` (one bone per joint, named like it; ``scale`` metres per BVH unit), then exported with every
frame keyed. ``bpy`` is a whole Blender in one module with global state and its own libraries, so it runs in a
child process (``python -c``), never in the pipeline's.
"""
from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import textwrap
from pathlib import Path

from ...core.errors import NodeError

INSTALL_HINT = ("install Blender's Python module: pip install -e \".[blender]\" && pip install --no-deps bpy==5.0.1 "
                "(docs/blender.md: bpy declares numpy<2, which its BVH import does not need)")

#: Runs in the child: argv[1] a JSON job {bvh, out, format, scale}; prints one JSON line {bones, frames, fps}.
CHILD = textwrap.dedent(r"""
    import json, sys
    import bpy

    job = json.loads(sys.argv[1])
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_anim.bvh(filepath=job["bvh"], axis_forward="-Z", axis_up="Y", global_scale=job["scale"],
                            rotate_mode="NATIVE", frame_start=1, use_fps_scale=False, update_scene_fps=True,
                            update_scene_duration=True)
    (arm,) = [o for o in bpy.data.objects if o.type == "ARMATURE"]
    first, last = (int(round(f)) for f in arm.animation_data.action.frame_range)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = first, last
    if job["format"] == "fbx":
        status = bpy.ops.export_scene.fbx(filepath=job["out"], object_types={"ARMATURE"}, add_leaf_bones=False,
                                          bake_anim=True, bake_anim_use_all_actions=False,
                                          bake_anim_use_nla_strips=False, bake_anim_simplify_factor=0.0)
    else:
        status = bpy.ops.export_scene.gltf(filepath=job["out"], export_format="GLB", export_animations=True,
                                           export_force_sampling=True, export_frame_range=True)
    print(json.dumps({"status": sorted(status), "bones": [b.name for b in arm.data.bones],
                      "frames": last - first + 1, "fps": scene.render.fps / scene.render.fps_base}))
""")


def convert_bvh(bvh: Path, out: Path, fmt: str, scale: float, timeout_s: float) -> dict:
    """Write ``out`` (``fmt``: ``"fbx"`` or ``"glb"``) from the BVH file ``bvh`` with Blender; returns the child's
    report ``{"bones": [...], "frames": n, "fps": f}``. NodeError when ``bpy`` is missing or Blender fails."""
    if importlib.util.find_spec("bpy") is None:
        raise NodeError(f"writing {fmt.upper()} needs Blender (the bpy module), which is not installed", hint=INSTALL_HINT)
    job = {"bvh": str(Path(bvh).resolve()), "out": str(Path(out).resolve()), "format": fmt, "scale": float(scale)}
    try:
        proc = subprocess.run([sys.executable, "-c", CHILD, json.dumps(job)], capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        raise NodeError(f"Blender did not finish writing {Path(out).name} within {timeout_s:g} s",
                        hint="raise the node's timeout_s for a very long take") from None
    lines = [line for line in proc.stdout.splitlines() if line.startswith("{")]
    if proc.returncode != 0 or not lines or not Path(out).is_file():
        tail = "\n".join((proc.stderr or proc.stdout).strip().splitlines()[-6:])
        raise NodeError(f"Blender could not write {Path(out).name} from {Path(bvh).name} (exit {proc.returncode}):\n{tail}",
                        hint="check that the BVH file opens in Blender (File > Import > Motion Capture)")
    report = json.loads(lines[-1])
    if report.get("status") != ["FINISHED"]:
        raise NodeError(f"Blender's {fmt.upper()} exporter did not finish: {report.get('status')}")
    return report


def write_with_blender(ctx, bvh: Path, fmt: str) -> Path:
    """A node's body: ``motion.<fmt>`` in the node's work folder from ``bvh`` (``ctx.params``: ``scale``,
    ``timeout_s``), and a log line saying what Blender wrote."""
    out = ctx.output_path(f"motion.{fmt}")
    rep = convert_bvh(bvh, out, fmt, ctx.params.scale, ctx.params.timeout_s)
    ctx.log(f"{'FBX' if fmt == 'fbx' else 'glTF'}: {len(rep['bones'])} bones, {rep['frames']} frames at {rep['fps']:g} fps (Blender)")
    return out
