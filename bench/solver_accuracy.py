"""Accuracy of the default pipeline (whole-take solver) on renders of CMU clips with other cameras than the
sample's: each clip is rendered by the project's renderer (``pipelines/evaluate_render.yaml``) and captured
by ``pipelines/default.yaml``; prints ``name=value`` per take:

    <take>_mpjpe_mm (one rigid alignment, no scale), <take>_pa_mpjpe_mm, <take>_root_mpjpe_mm, <take>_joint_angle_err_deg,
    <take>_focal_err_pct, <take>_floor_penetration_mm, <take>_seconds

    python bench/solver_accuracy.py [--focal-given] [--set node.param=value ...]
        # --focal-given: the render's focal length is given; --set: passed to the capture (e.g. solver settings)
"""
from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: (name, clip, seconds of clip, camera eye (m), camera target (m), focal px): heights 0.9-1.8 m, distances
#: 3.5-6 m, tilts up to about 12 degrees, focal 500-1200 px at 640x480
TAKES = (
    ("walk131_01_f500_low", "131_01.bvh", 5.0, (-1.0, 0.9, 5.0), (0.0, 0.9, 0.0), 500.0),
    ("hop131_03_f1000_high", "131_03.bvh", 5.0, (0.6, 1.8, 5.4), (0.0, 0.8, 0.0), 1000.0),
    ("walk131_02_f1200_far", "131_02.bvh", 5.0, (1.2, 1.3, 6.0), (0.0, 0.95, 0.0), 1200.0),
)


def render_graph(take: tuple, focal_given: bool = False, decl=None):
    """The default pipeline's graph on a render of ``take`` (an entry of :data:`TAKES`), the render's focal length
    given to the solver when ``focal_given``: one definition for the bench's sibling scripts and the tests; ``decl``:
    the pipeline as read (``bench/labelling.py``'s ``render_decl``) if not evaluate_render.yaml as it is."""
    from tbha_graph.core.runner import load_graph

    _, clip, seconds, eye, target, f = take
    vars = {"bvh": str(ROOT / "data" / "mocap" / "cmu" / clip)}
    if focal_given:
        vars["focal_px"] = f
    return load_graph(ROOT / "pipelines" / "evaluate_render.yaml", vars=vars, decl=decl,
                      sets={"lead_in.duration": seconds, "camera.eye": list(eye), "camera.target": list(target),
                            "camera.focal_px": f})


def main() -> None:
    given = "--focal-given" in sys.argv
    sets = [a for i, a in enumerate(sys.argv) if i > 0 and sys.argv[i - 1] == "--set"]
    for name, clip, seconds, eye, target, f in TAKES:
        out = Path(tempfile.mkdtemp(prefix=f"tbha-acc-{name}-"))
        cmd = [sys.executable, "-m", "tbha_graph.cli.run", str(ROOT / "pipelines" / "evaluate_render.yaml"),
               "--var", f"bvh={ROOT / 'data' / 'mocap' / 'cmu' / clip}", "--out", str(out / "run"),
               "--set", f"lead_in.duration={seconds}",
               "--set", f"camera.eye=[{eye[0]}, {eye[1]}, {eye[2]}]",
               "--set", f"camera.target=[{target[0]}, {target[1]}, {target[2]}]",
               "--set", f"camera.focal_px={f}"]
        if given:
            cmd += ["--var", f"focal_px={f}"]
        for s in sets:
            cmd += ["--set", s]
        t0 = time.perf_counter()
        run = subprocess.run(cmd, capture_output=True, text=True)
        dt = time.perf_counter() - t0
        if run.returncode != 0:
            print(f"{name}_error={run.stderr.strip().splitlines()[-1] if run.stderr.strip() else run.returncode}")
            continue
        m = json.loads((out / "run" / "metrics.json").read_text())
        for key in ("mpjpe_mm", "pa_mpjpe_mm", "root_mpjpe_mm", "joint_angle_err_deg", "focal_err_pct", "floor_penetration_mm"):
            print(f"{name}_{key}={m.get(key)}")
        print(f"{name}_seconds={dt:.1f}")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
