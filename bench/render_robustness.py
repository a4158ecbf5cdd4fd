"""Robustness of the default pipeline to renders unlike ours: each variant changes ONE thing from the
sample's render settings (body shape, suit, lighting, sensor, background, resolution, frame rate, camera,
codec), renders a short CMU clip with the project's renderer, captures it with ``pipelines/default.yaml``
and prints ``name=value`` lines per variant:

    <variant>_mpjpe_mm, _pa_mpjpe_mm, _focal_err_pct, _tracked_pct, _tracking_px (median, tracks vs the true
    patch centres), _doubtful_frames (frames in metrics.json's doubtful_ranges), _warnings, _verdict, _seconds
    (the capture alone; the render is not counted)

    python bench/render_robustness.py [--estimate] [--only NAME[,NAME...]] [--list] [--keep DIR] [--set NODE.PARAM=V]
        # default: the render's focal length is given (--var focal_px=F) so tracking and segmentation problems are
        # not hidden by the focal estimate's luck; --estimate: the focal length is estimated (the pipeline's default)
        # --keep DIR: keep each variant's render and run in DIR/<variant>/ (overlay.mp4, errors.png, ...)

Renders are 640x480, 30 fps, a 1 s T-pose, a 0.5 s blend and 3 s of the clip (4.5 s) unless the variant
changes that. ``H.264`` variants re-encode the rendered video with libx264 (PyAV, the ``av`` extra) at the
given CRF, and the ground truth is re-bound to the re-encoded file (its sha256, size and frame count).
"""
from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tbha_graph.mocap.camera import Camera  # noqa: E402
from tbha_graph.mocap.suit import SEED_SUIT_PATH, load_suit  # noqa: E402
from tbha_graph.mocap.synth.body import BodyShape  # noqa: E402
from tbha_graph.mocap.synth.render import RenderParams, render_video  # noqa: E402
from tbha_graph.mocap.synth.shading import Lighting  # noqa: E402
from tbha_graph.mocap.synth.tpose_lead_in import LeadInParams, lead_in_motion  # noqa: E402

CMU = ROOT / "data" / "mocap" / "cmu"
#: the sample's camera: eye, target (world metres), focal px, image size
EYE, TARGET, FOCAL, SIZE = (0.8, 1.45, 4.6), (0.0, 0.95, 0.0), 700.0, (640, 480)
THIN = dict(upper_arm_radius=0.034, forearm_radius=0.028, hand_radius=0.028, thigh_radius=0.05, shin_radius=0.036,
            neck_radius=0.04, torso_half_width=0.12, torso_half_depth=0.08, thorax_half_width=0.14,
            thorax_half_depth=0.09, pelvis_half_width=0.13, pelvis_half_depth=0.09)
HEAVY = dict(upper_arm_radius=0.065, forearm_radius=0.05, hand_radius=0.042, thigh_radius=0.095, shin_radius=0.065,
             neck_radius=0.06, shoulder_girdle_radius=0.07, hip_girdle_radius=0.095, torso_half_width=0.19,
             torso_half_depth=0.14, thorax_half_width=0.2, thorax_half_depth=0.14, pelvis_half_width=0.19,
             pelvis_half_depth=0.14)


def V(clip="131_02", render=None, body=None, light=None, eye=EYE, target=TARGET, focal=FOCAL, size=SIZE, scale=1.0,
      suit=None, patch_radius=None, h264=None, capture=(), seconds=3.0, tint=None):
    """A variant: ``render`` RenderParams fields, ``body`` BodyShape fields, ``light`` Lighting fields, camera,
    ``scale`` (the person's size: joints scaled about the floor point under the start), ``suit`` file,
    ``patch_radius`` (m), ``h264`` (CRF of a re-encode, None = the renderer's mp4v), ``capture`` extra args,
    ``tint`` (R, G, B gains applied to every rendered frame: a coloured light / an unbalanced camera)."""
    return dict(tint=tint, clip=clip, render=render or {}, body=body or {}, light=light or {}, eye=eye, target=target, focal=focal,
                size=size, scale=scale, suit=suit, patch_radius=patch_radius, h264=h264, capture=list(capture),
                seconds=seconds)


VARIANTS: dict[str, dict] = {
    "base_131_02": V(),
    "base_131_01": V("131_01"),
    "base_131_03": V("131_03"),
    "body_thin": V(body=THIN),
    "body_heavy": V(body=HEAVY),
    "tall_1.15": V(scale=1.15),
    "tall_1.15_height": V(scale=1.15, capture=["--set", "body.height={stature}"]),
    "short_0.88": V(scale=0.88),
    "short_0.88_height": V(scale=0.88, capture=["--set", "body.height={stature}"]),
    "patch_r0.03": V(patch_radius=0.03),
    "patch_r0.065": V(patch_radius=0.065),
    "light_dim": V(light=dict(key=0.35, fill=0.08, ambient=0.1)),
    "light_harsh": V(light=dict(key=1.6, fill=0.05, ambient=0.05, specular=1.0, shininess=12.0)),
    "light_bright": V(light=dict(key=1.2, specular=0.6)),
    "tint_warm": V(tint=(1.0, 0.82, 0.6)),
    "tint_cool": V(tint=(0.75, 0.9, 1.0)),
    "tint_green": V(tint=(0.85, 1.0, 0.8)),
    "light_side": V(light=dict(direction=(1.0, 0.3, -0.2), key=1.0, fill=0.1, ambient=0.12)),
    "noise_6": V(render=dict(noise_sigma=6.0)),
    "noise_8": V(render=dict(noise_sigma=8.0)),
    "blur_1.5": V(render=dict(optics_blur_px=1.5)),
    "motion_blur_4": V(render=dict(motion_blur_samples=4)),
    "motion_blur_8": V(render=dict(motion_blur_samples=8, shutter=1.0)),
    "exposure_0.05": V(render=dict(exposure_jitter=0.05)),
    "plain_bg": V(render=dict(background="plain")),
    "res_1280x720": V(size=(1280, 720), focal=FOCAL * 2.0),
    "res_960x540": V(size=(960, 540), focal=FOCAL * 1.5),
    "fps_25": V(render=dict(fps=25.0)),
    "fps_60": V(render=dict(fps=60.0)),
    "cam_low_0.8": V(eye=(0.8, 0.8, 4.6), target=(0.0, 1.0, 0.0)),
    "cam_high_1.8_tilt15": V(eye=(0.8, 1.8, 4.6), target=(0.0, 0.55, 0.0)),
    "cam_near_3m": V(eye=(0.5, 1.45, 3.0), focal=480.0),
    "suit_seed": V(suit=str(SEED_SUIT_PATH), capture=["--set", f"colors.suit={SEED_SUIT_PATH}"]),
    "h264_crf23": V(h264=23),
    "h264_crf30": V(h264=30),
}


def stature(scale: float) -> float:
    from tbha_graph.mocap.body import DEFAULT_STATURE

    return DEFAULT_STATURE * scale


def render(name: str, v: dict, folder: Path) -> tuple[Path, Path]:
    """Render variant ``v`` into ``folder``; returns (video, ground truth npz)."""
    from tbha_graph.mocap.io.video_identity import video_identity

    joints, fps = lead_in_motion(LeadInParams(path=CMU / f"{v['clip']}.bvh", hold_seconds=1.0, blend_seconds=0.5,
                                              duration=v["seconds"]))
    if v["scale"] != 1.0:
        base = joints[0, 0] * np.array([1.0, 0.0, 1.0])
        joints = base + (joints - base) * v["scale"]
    w, h = v["size"]
    cam = Camera.look_at(v["eye"], v["target"], focal_px=v["focal"], width=w, height=h)
    suit = load_suit(v["suit"])
    if v["patch_radius"] is not None:
        suit = suit.model_copy(update={"patch_radius": float(v["patch_radius"])})
    body = BodyShape(**v["body"]) if v["body"] else BodyShape()
    if v["scale"] != 1.0:  # a bigger person is bigger all over
        body = BodyShape(**{k: (tuple(x * v["scale"] for x in val) if isinstance(val, tuple) else val * v["scale"])
                            for k, val in body.model_dump().items()})
    params = RenderParams(width=w, height=h, lighting=Lighting(**v["light"]), body=body, **v["render"])
    video = folder / "video.mp4"
    gt = render_video(joints, fps, cam, suit, params, video)
    if v["tint"] is not None:  # a coloured light on everything (or a camera's white balance off): gains per channel
        import cv2

        from tbha_graph.mocap.io.video_writer import open_video_writer

        gains = np.array(v["tint"], dtype=np.float32)[::-1]  # BGR
        tinted = folder / "video_tint.mp4"
        cap = cv2.VideoCapture(str(video))
        with open_video_writer(tinted, params.fps, w, h, codec="h264", crf=10, preset="medium") as wr:
            while True:
                ok, frame = cap.read()
                if not ok:
                    break
                wr.write(np.clip(frame * gains + 0.5, 0, 255).astype(np.uint8))
        cap.release()
        tinted.replace(video)
        gt.update(video_identity(video, frames=int(gt["video_frames"])))
    if v["h264"] is not None:
        import cv2

        from tbha_graph.mocap.io.video_writer import open_video_writer

        enc = folder / "video_h264.mp4"
        cap = cv2.VideoCapture(str(video))
        n = 0
        with open_video_writer(enc, params.fps, w, h, codec="h264", crf=int(v["h264"]), preset="medium") as wr:
            while True:
                ok, frame = cap.read()
                if not ok:
                    break
                wr.write(frame)
                n += 1
        cap.release()
        video = enc
        gt.update(video_identity(video, frames=n))
    npz = folder / "ground_truth.npz"
    np.savez_compressed(npz, **gt)
    return video, npz


def capture(name: str, v: dict, video: Path, npz: Path, out: Path, estimate: bool, sets: list[str] = ()) -> dict:
    """Runs ``pipelines/default.yaml`` on a variant's render (``sets``: ``NODE.PARAM=VALUE`` for every variant, as
    ``tbha-run --set``) and returns its figures from ``metrics.json`` (or ``error``)."""
    cmd = [sys.executable, "-m", "tbha_graph.cli.run", str(ROOT / "pipelines" / "default.yaml"), "--quiet",
           "--var", f"video={video}", "--var", f"ground_truth={npz}", "--out", str(out),
           "--cache-dir", str(out.parent / "cache")]
    if not estimate:
        cmd += ["--var", f"focal_px={v['focal']}"]
    cmd += [a.format(stature=f"{stature(v['scale']):.4f}") for a in v["capture"]]
    for item in sets:
        cmd += ["--set", item]
    t0 = time.perf_counter()
    run = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    dt = time.perf_counter() - t0
    if run.returncode != 0:
        lines = [ln for ln in run.stderr.strip().splitlines() if ln.strip()]
        err = next((ln for ln in lines if ln.startswith("error")), lines[-1] if lines else str(run.returncode))
        return {"error": err.replace("\n", " ")[:300], "seconds": round(dt, 1)}
    m = json.loads((out / "metrics.json").read_text())
    doubtful = sum(int(r[1]) - int(r[0]) + 1 for r in m.get("doubtful_ranges") or [])
    return {
        "mpjpe_mm": m.get("mpjpe_mm"), "pa_mpjpe_mm": m.get("pa_mpjpe_mm"), "focal_err_pct": m.get("focal_err_pct"),
        "tracked_pct": m.get("tracked_pct"), "tracking_px": m.get("tracking_2d_px_median"),
        "doubtful_frames": doubtful, "warnings": len(m.get("warnings") or []), "verdict": m.get("verdict"),
        "seconds": round(dt, 1),
    }


def fmt(x) -> str:
    if isinstance(x, float):
        return f"{x:.2f}" if abs(x) < 10 else f"{x:.1f}"
    return str(x)


def set_suffix(sets: list[str]) -> str:
    """The run folder's suffix for these ``--set`` items: ``""`` without any, else ``_set_`` and 8 hex digits of a
    hash of them (order-free), so runs with different settings do not replace each other."""
    if not sets:
        return ""
    return "_set_" + hashlib.sha256("\n".join(sorted(sets)).encode()).hexdigest()[:8]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--estimate", action="store_true", help="estimate the focal length (default: given)")
    ap.add_argument("--only", help="comma-separated variant names")
    ap.add_argument("--list", action="store_true", help="list the variants and stop")
    ap.add_argument("--keep", type=Path, help="keep renders and runs in DIR/<variant>/ (reused when present)")
    ap.add_argument("--set", action="append", default=[], metavar="NODE.PARAM=VALUE",
                    help="a node's param for every variant's capture (tbha-run --set); with --keep its runs go to "
                         "run_set_<hash>/ or run_est_set_<hash>/ (one folder per combination of settings, named by "
                         "a hash of them and listing them in settings.txt), beside those without")
    args = ap.parse_args()
    if args.list:
        print("\n".join(VARIANTS))
        return
    names = args.only.split(",") if args.only else list(VARIANTS)
    unknown = [n for n in names if n not in VARIANTS]
    if unknown:
        sys.exit(f"unknown variant(s) {unknown}; --list shows them")
    for name in names:
        v = VARIANTS[name]
        tmp = None
        if args.keep:
            folder = args.keep / name
        else:
            tmp = Path(tempfile.mkdtemp(prefix=f"tbha-robust-{name}-"))
            folder = tmp
        folder.mkdir(parents=True, exist_ok=True)
        video = folder / ("video_h264.mp4" if v["h264"] is not None else "video.mp4")
        npz = folder / "ground_truth.npz"
        if not (video.is_file() and npz.is_file()):
            video, npz = render(name, v, folder)
        out = folder / (("run_est" if args.estimate else "run") + set_suffix(args.set))
        if out.exists():  # this bench's own earlier output
            shutil.rmtree(out)
        res = capture(name, v, video, npz, out, args.estimate, args.set)
        if args.set and out.is_dir():
            (out / "settings.txt").write_text("\n".join(args.set) + "\n")
        for k, val in res.items():
            print(f"{name}_{k}={fmt(val)}")
        sys.stdout.flush()
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
