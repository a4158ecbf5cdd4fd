"""Sample a suit's real colours from a take: ``python -m tbha_graph.mocap.color.sample_suit``.

A real fabric under real light is not the nominal sRGB colour of its spec. This tool tracks the patches
over the take's opening frames (the T-pose: every patch faces the camera), reads the pixels around each
tracked patch centre, and writes a suit file whose colours are the median colour measured for each
colour name (patches sharing a colour are pooled); joints, sharing and patch radius stay the nominal
suit's. Use the written file with ``--set colors.suit=my_suit.yaml``.

    python -m tbha_graph.mocap.color.sample_suit my_take.mp4 --suit nominal.yaml --frames 0:30 --out my_suit.yaml

It never overwrites an existing file (``--force`` to allow it).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import yaml

from ...core.atomic import atomic_path
from ...core.errors import NodeFailed, TbhaError
from ..skeleton import JOINT_NAMES
from ..suit import DEFAULT_SUIT_PATH, load_suit


def track_opening(video: Path, suit: Path, start: int, stop: int) -> dict:
    """2D tracks of frames ``[start, stop)`` of ``video`` with the default segmenter and tracker."""
    from ...core.pipeline import Pipeline

    p = Pipeline("sample suit colours")
    p.add("decode", "io.video", params={"path": str(video), "start": start, "stop": stop})
    p.add("colors", "color.rg_chromaticity", params={"suit": str(suit)})
    p.add("segment", "segment.hierarchical", video="decode.video", colors="colors.model")
    p.add("track", "track.posture_kalman", detections="segment.detections", colors="colors.model")
    run = p.run(outputs=["track"], cache=False)
    return run.output("track.tracks")


def read_frames(video: Path, start: int, stop: int) -> list[np.ndarray]:
    import cv2

    cap = cv2.VideoCapture(str(video))
    try:
        cap.set(cv2.CAP_PROP_POS_FRAMES, start)
        frames = []
        for _ in range(start, stop):
            ok, f = cap.read()
            if not ok:
                break
            frames.append(f)
        return frames
    finally:
        cap.release()


def sample_colours(frames: list[np.ndarray], tracks: dict, patches: dict[str, str], radius_px: int = 3) -> dict[str, tuple[str, int]]:
    """Colour name -> (sRGB hex of the median pixel, number of pixels used) over every tracked patch centre."""
    pts = np.asarray(tracks["points"], dtype=np.float64)
    tracked = np.asarray(tracks["tracked"], dtype=bool)
    yy, xx = np.mgrid[-radius_px : radius_px + 1, -radius_px : radius_px + 1]
    disc = (xx**2 + yy**2) <= radius_px**2
    pooled: dict[str, list[np.ndarray]] = {}
    for f, img in enumerate(frames[: pts.shape[0]]):
        h, w = img.shape[:2]
        for joint, name in patches.items():
            j = JOINT_NAMES.index(joint)
            if not tracked[f, j] or not np.isfinite(pts[f, j]).all():
                continue
            x, y = int(round(pts[f, j, 0])), int(round(pts[f, j, 1]))
            if radius_px <= x < w - radius_px and radius_px <= y < h - radius_px:
                pooled.setdefault(name, []).append(img[y - radius_px : y + radius_px + 1, x - radius_px : x + radius_px + 1][disc])
    out = {}
    for name, parts in pooled.items():
        px = np.concatenate(parts)
        b, g, r = np.median(px, axis=0)
        out[name] = (f"#{int(round(r)):02x}{int(round(g)):02x}{int(round(b)):02x}", int(px.shape[0]))
    return out


def write_suit(nominal_path: Path, measured: dict[str, tuple[str, int]], out: Path, source: str, force: bool = False) -> Path:
    suit = load_suit(nominal_path)
    missing = sorted(set(suit.colors) - set(measured))
    if missing:
        raise TbhaError(f"no tracked pixels for colour(s) {', '.join(missing)} in the sampled frames",
                        hint="sample frames where every patch faces the camera (the opening T-pose), e.g. --frames 0:30")
    if out.exists() and not force:
        raise TbhaError(f"{out} exists; nothing was written", hint="choose another --out, or --force to replace it")
    data = suit.model_dump(mode="json", exclude_none=True)
    data["colors"] = {name: measured[name][0] for name in suit.colors}
    head = (f"# suit colours sampled from {source} by tbha_graph.mocap.color.sample_suit\n"
            f"# nominal suit: {nominal_path}; nominal colours: "
            + ", ".join(f"{k} {v}" for k, v in suit.colors.items()) + "\n")
    text = head + yaml.safe_dump(data, sort_keys=False)
    with atomic_path(out) as tmp:
        tmp.write_text(text, encoding="utf-8")
        load_suit(tmp)  # the written file must be a valid suit (else nothing is written)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, prog="python -m tbha_graph.mocap.color.sample_suit",
                                 description="Write a suit file with the colours measured on a take's opening T-pose frames.")
    ap.add_argument("video", help="the take (it must open with the actor in a T-pose facing the camera)")
    ap.add_argument("--suit", default=str(DEFAULT_SUIT_PATH), help="the nominal suit file (default: the bundled suit)")
    ap.add_argument("--frames", default="0:30", metavar="START:STOP", help="frames of the T-pose (default 0:30)")
    ap.add_argument("--radius-px", type=int, default=3, help="radius of the disc read around each patch centre")
    ap.add_argument("--out", required=True, help="suit file to write")
    ap.add_argument("--force", action="store_true", help="replace --out if it exists")
    args = ap.parse_args(argv)
    try:
        start, stop = (int(x) for x in args.frames.split(":"))
        if not 0 <= start < stop:
            raise ValueError
    except ValueError:
        print(f"error: --frames {args.frames!r} must be START:STOP with 0 <= START < STOP", file=sys.stderr)
        return 2
    video, suit, out = Path(args.video), Path(args.suit), Path(args.out)
    try:
        if not video.is_file():
            raise TbhaError(f"video not found: {video}")
        tracks = track_opening(video, suit, start, stop)
        measured = sample_colours(read_frames(video, start, stop), tracks, load_suit(suit).patches, args.radius_px)
        write_suit(suit, measured, out, f"{video} frames {start}:{stop}", args.force)
    except (TbhaError, NodeFailed) as e:
        print(f"error: {e.format()}", file=sys.stderr)
        return 2
    for name, (hx, n) in measured.items():
        print(f"  {name:<10} {hx}  ({n} pixels)")
    print(f"wrote {out}: use it with --set colors.suit={out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
