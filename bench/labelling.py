"""Labelling through turns, occlusion and shared colours (issue 13), measured on the project's renderer.

Renders CMU clips that turn round (``synth.tpose_lead_in`` with an extra heading change where the clip
itself does not turn far enough), in both suit kinds (upper/lower limbs sharing a colour: the default
suit; left/right sharing: the seed-style ``suit_seed.yaml``), captures each with
``pipelines/evaluate_render.yaml`` (the default pipeline) and scores the 2D labelling against the
renderer's truth of which patch is where (``patch2d``, ``patch_visible``):

* ``identity_error_pct=``: of the visible patch-frames, % whose patch the tracker labelled with another
  joint, or whose joint the tracker marks tracked somewhere else than on its patch. A tracked point is on
  its own patch when within ``tol`` = 0.8 x the patch's projected radius + 3 px of its true centre (blob
  centres of partly hidden patches move; two touching patches make one blob between them); otherwise it
  is on the visible patch whose true centre is nearest, if within that patch's ``tol``.
* ``missed_pct=``: visible patch-frames the tracker did not mark tracked (for reference).
* ``reacquire_frames_p95=``: after a patch was out of sight for at least 2 frames, frames from its
  reappearance until the tracker labels it correctly (a patch never re-labelled before it hides again or
  the take ends counts its whole visible run, plus one). "In sight" = its centre visible in the render
  AND the segmenter found a blob of its colour there (a patch seen edge-on is often visible by its centre
  but too thin to be found: no tracker can label it); ``reacquire_frames_p95_truth_visible=`` counts
  reappearances by the render's visibility alone.
* ``off_body_pct=``: of all (frame, joint) 2D points the tracker output (tracked or predicted), % farther
  from their parent joint's point than the bone could reach in the image (bone length + 0.15 m of
  patch offsets, at the nearer of the two joints' true depths); ``off_body_placed_pct=``: the same over
  the bones with an end the tracker placed (not measured). The tracker knows no depth: it bounds placed
  points by the bone lengths seen at the start, scaled by the torso's size when last seen.
* ``seq_mpjpe_mm=``: the final 3D motion vs the truth after ONE rigid alignment over the whole take
  (rotation + translation, no scale), turn included; ``seq_mpjpe_true_camera_mm=``: the same capture
  given the render's camera (the true camera in place of a ``calibrate`` node, or the true focal length
  as the solver's ``focal_px``), to separate the labelling and 3D solver from the calibration;
  ``turn_deg=``: the truth's heading range.
* ``seq_mpjpe_seen_mm=``: the same, aligned and averaged over the frames where the torso's front is seen
  (at least 4 of its 7 patches visible in the render; ``seen_pct=`` of the frames): the suit's patches are
  on the body's front, so with the actor's back to the camera the tracker has the head alone and the 3D
  there comes from the priors. Separates what the solver makes of the patches from what no patch shows.

Run: ``python bench/labelling.py`` (all takes, both suits; a few seconds per take),
``python bench/labelling.py --held-out`` (three takes never used while tuning: other cameras, a full
360° turn, noise and motion blur),
``python bench/labelling.py --takes spin_131_03 --suits left_right``, ``--keep DIR`` to write the run folders
(overlay.mp4, errors.png, metrics.json) there.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tbha_graph.mocap.skeleton import JOINT_INDEX, JOINT_NAMES, PARENTS, PATCHED_JOINTS  # noqa: E402

#: name -> (clip, extra lead-in params). 131_03's spin turns ~150 deg within the bundled 6 s; 90 deg more
#: are added during it so that the take turns more than 180 deg. The walks get a full turn round.
TAKES: dict[str, tuple[str, dict]] = {
    "spin_131_03": ("131_03.bvh", {"turn_degrees": 90.0, "turn_start": 2.0, "turn_seconds": 2.0}),
    "walk_turn_131_01": ("131_01.bvh", {"turn_degrees": 200.0, "turn_start": 1.0, "turn_seconds": 3.0}),
    "walk_turn_131_02": ("131_02.bvh", {"turn_degrees": -220.0, "turn_start": 1.0, "turn_seconds": 3.5}),
}
#: Takes never used while tuning the tracker (other cameras, noise, motion blur): ``--held-out``.
HELD_OUT: dict[str, tuple[str, dict]] = {
    "held_131_03_high_left_camera": ("131_03.bvh", {"camera.eye": [-1.5, 1.9, 3.8]}),
    "held_131_01_full_turn_right_camera": ("131_01.bvh", {"camera.eye": [1.6, 1.3, 4.2], "turn_degrees": 360.0,
                                                          "turn_start": 0.5, "turn_seconds": 4.0}),
    "held_131_02_turn_noisy_blurred": ("131_02.bvh", {"turn_degrees": -150.0, "render.noise_sigma": 5.0,
                                                      "render.motion_blur_samples": 3}),
}
SUITS = {
    "upper_lower": ROOT / "tbha_graph" / "mocap" / "suit_default.yaml",
    "left_right": ROOT / "tbha_graph" / "mocap" / "suit_seed.yaml",
}
PATCH_IDX = np.array([JOINT_INDEX[j] for j in PATCHED_JOINTS])
#: The torso's patches (indices into PATCHED_JOINTS): hips, chest, neck, shoulders, hip joints.
TORSO_PATCHES = np.array([PATCHED_JOINTS.index(j) for j in ("hips", "chest", "neck", "left_shoulder", "right_shoulder",
                                                            "left_hip", "right_hip")])


def seen_seq_mpjpe(joints: np.ndarray, truth: dict, min_patches: int = 4) -> tuple[float, float]:
    """seq-MPJPE mm (one rigid alignment, no scale) over the frames where at least ``min_patches`` of the
    torso's patches are visible in the render, and the % of frames that is."""
    from tbha_graph.mocap.evaluate import measures as m

    seen = np.asarray(truth["patch_visible"], dtype=bool)[:, TORSO_PATCHES].sum(axis=1) >= min_patches
    if not seen.any():
        return float("nan"), 0.0
    gt = np.asarray(truth["joints3d_world"], dtype=np.float64)[seen]
    aligned, _ = m.align_clip(np.asarray(joints, dtype=np.float64)[seen], gt, "rigid")
    return float(np.nanmean(m.joint_distances(aligned, gt))) * 1000.0, 100.0 * float(seen.mean())


def heading_range_deg(joints: np.ndarray) -> float:
    """Range of the body's facing over the take (degrees about the vertical), from hips and shoulders."""
    J = JOINT_INDEX
    left = (joints[:, J["left_hip"]] - joints[:, J["right_hip"]]) + (joints[:, J["left_shoulder"]] - joints[:, J["right_shoulder"]])
    front = np.cross(left, [0.0, 1.0, 0.0])
    h = np.degrees(np.unwrap(np.arctan2(front[:, 0], front[:, 2])))
    return float(np.ptp(h))


def patch_tolerance_px(truth: dict, radius_m: float) -> np.ndarray:
    """(n, 15) px: 0.8 x each patch's projected radius + 3 px."""
    z = (np.einsum("ij,ntj->nti", truth["R"], truth["patch_centers_world"]) + truth["t"])[..., 2]
    f = float(truth["K"][0, 0])
    return 0.8 * f * radius_m / np.maximum(z, 1e-3) + 3.0


def detected_patches(det: dict, truth: dict, suit, radius_m: float) -> np.ndarray:
    """(n, 15) bool: a candidate of the patch's colour lies within the tolerance of its true centre."""
    names = [str(c) for c in np.asarray(det["colour_names"]).reshape(-1)]
    centres = np.asarray(det["centres"], dtype=np.float64)
    gt = np.asarray(truth["patch2d"], dtype=np.float64)
    tol = patch_tolerance_px(truth, radius_m)
    out = np.zeros(gt.shape[:2], bool)
    for j, name in enumerate(PATCHED_JOINTS):
        c = names.index(suit.patches[name])
        d = np.linalg.norm(centres[:, c] - gt[:, j, None], axis=-1)  # (n, K), NaN for empty slots
        out[:, j] = (np.nan_to_num(d, nan=np.inf) <= tol[:, j, None]).any(axis=1)
    return out


def reacquire_delays(vis: np.ndarray, correct: np.ndarray, min_hidden: int = 2) -> list[int]:
    """Frames from each reappearance (after ``min_hidden`` frames unseen) to the first correct label."""
    delays = []
    n = len(vis)
    for j in range(vis.shape[1]):
        v = vis[:, j]
        t = 1
        while t < n:
            if v[t] and not v[t - 1]:
                h = t - 1
                while h >= 0 and not v[h]:
                    h -= 1
                e = t
                while e < n and v[e]:
                    e += 1
                if (t - 1) - h >= min_hidden and h >= 0:
                    ok = np.flatnonzero(correct[t:e, j])
                    delays.append(int(ok[0]) if ok.size else e - t + 1)
                t = e
            else:
                t += 1
    return delays


def label_scores(tracks: dict, truth: dict, radius_m: float, detected: np.ndarray | None = None) -> dict:
    """identity errors, misses and re-acquisition delays of the tracks against the render's truth."""
    pts = np.asarray(tracks["points"], dtype=np.float64)[:, PATCH_IDX]  # (n, 15, 2)
    trk = np.asarray(tracks["tracked"], dtype=bool)[:, PATCH_IDX]
    gt = np.asarray(truth["patch2d"], dtype=np.float64)
    vis = np.asarray(truth["patch_visible"], dtype=bool)
    n = len(pts)
    tol = patch_tolerance_px(truth, radius_m)
    d = np.linalg.norm(pts[:, :, None, :] - gt[:, None, :, :], axis=-1)  # (n, joint, patch)
    d = np.where(vis[:, None, :], d, np.inf)
    nearest = np.argmin(d, axis=2)
    dmin = np.take_along_axis(d, nearest[..., None], axis=2)[..., 0]
    own = np.arange(15)[None, :]
    own_d = d[:, np.arange(15), np.arange(15)]  # to its own patch (inf when hidden)
    correct = trk & (own_d <= tol)  # on its own patch (a merged blob may be as near another)
    matched_other = trk & ~correct & (dmin <= np.take_along_axis(tol, nearest, axis=1)) & (nearest != own)
    # a visible patch is wrong when its joint is tracked elsewhere, or another joint is tracked on it
    taken_by_other = np.zeros((n, 15), bool)
    t_idx, j_idx = np.nonzero(matched_other)
    taken_by_other[t_idx, nearest[t_idx, j_idx]] = True
    wrong = vis & ((trk & ~correct) | taken_by_other)
    missed = vis & ~trk & ~taken_by_other
    delays = reacquire_delays(vis, correct)
    seen = vis if detected is None else vis & detected
    delays_detected = reacquire_delays(seen, correct)
    return {
        "visible": int(vis.sum()),
        "wrong": int(wrong.sum()),
        "missed": int(missed.sum()),
        "delays": delays,
        "delays_detected": delays_detected,
        "wrong_frames": np.flatnonzero(wrong.any(axis=1)),
    }


def off_body(tracks: dict, truth: dict, placed_only: bool = False) -> tuple[int, int]:
    """(count, total) of 2D points farther from their parent's point than the bone can reach
    (``placed_only``: bones with an end the tracker placed, not measured)."""
    pts = np.asarray(tracks["points"], dtype=np.float64)
    trk = np.asarray(tracks["tracked"], dtype=bool)
    z = (np.einsum("ij,ntj->nti", truth["R"], truth["joints3d_world"]) + truth["t"])[..., 2]
    f = float(truth["K"][0, 0])
    L = np.asarray(truth["bone_lengths"], dtype=np.float64)
    count = total = 0
    for j in range(1, len(JOINT_NAMES)):
        p = PARENTS[j]
        dist = np.linalg.norm(pts[:, j] - pts[:, p], axis=1)
        reach = f * (L[j] + 0.15) / np.maximum(np.minimum(z[:, j], z[:, p]) - 0.15, 0.3)
        ok = np.isfinite(dist)
        use = ~(trk[:, j] & trk[:, p]) if placed_only else np.ones(len(dist), bool)
        count += int((dist[ok & use] > reach[ok & use]).sum()) + int((~ok & use).sum())
        total += int(use.sum())
    return count, total


def true_camera_seq_mpjpe(sets: dict, vars: dict, truth: dict, keypoints: bool = True) -> float:
    """seq-MPJPE (mm) of the same capture given the render's camera: with a ``calibrate`` node (the seed's
    chain) the true camera replaces the T-pose calibration (``calibrate.known``); with a solver that
    estimates the camera itself (``reconstruct.solve_take``), its ``focal_px`` var is set to the true focal
    length. What the labelling and the 3D solver give without calibration error."""
    import tempfile

    decl = render_decl(keypoints)
    if "calibrate" not in decl.nodes:
        from tbha_graph.core.runner import load_graph, run_graph
        from tbha_graph.mocap.evaluate import measures as m

        if "focal_px" not in (decl.vars or {}):
            return float("nan")
        run = run_graph(load_graph(ROOT / "pipelines" / "evaluate_render.yaml", sets=sets, decl=decl,
                                   vars={**vars, "focal_px": float(np.asarray(truth["K"])[0, 0])}),
                        outputs=["metrics.json"], cache=False)
        gt = truth["joints3d_world"]
        aligned, _ = m.align_clip(np.asarray(run.output("smooth.motion")["joints"], dtype=np.float64), gt, "rigid")
        return float(np.nanmean(m.joint_distances(aligned, gt))) * 1000.0

    from tbha_graph.core.runner import run_graph
    from tbha_graph.core.runner import load_graph
    from tbha_graph.mocap.evaluate import measures as m

    with tempfile.TemporaryDirectory() as d:
        cam = Path(d) / "camera.json"
        cam.write_text(json.dumps({k: np.asarray(truth[k]).tolist() for k in ("K", "R", "t", "width", "height")}))
        pipe = Path(d) / "true_camera.yaml"
        pipe.write_text(
            f"extends: {ROOT / 'pipelines' / 'evaluate_render.yaml'}\n"
            "nodes:\n"
            f"  calibrate: {{type: calibrate.known, params: {{path: {cam}}}, inputs: {{tracks: null, body: null}}}}\n"
        )
        run = run_graph(load_graph(pipe, sets=sets, vars=vars), outputs=["metrics.json"], cache=False)
    gt = truth["joints3d_world"]
    aligned, _ = m.align_clip(np.asarray(run.output("smooth.motion")["joints"], dtype=np.float64), gt, "rigid")
    return float(np.nanmean(m.joint_distances(aligned, gt))) * 1000.0


def render_decl(keypoints: bool = True, sets: dict | None = None):
    """``pipelines/evaluate_render.yaml`` read (a ``PipelineDecl`` for ``load_graph(..., decl=...)``): as the default
    pipeline, with MediaPipe's keypoints where no torso patch is seen (its node ``detect``; the mediapipe extra),
    or without them (``keypoints`` False: ``detect.frames: none``), to compare; ``sets`` ``{"node.param": value}``
    overrides params as ``--set`` does."""
    from tbha_graph.core.errors import Location, PipelineErrors
    from tbha_graph.core.spec import merge_node_override, read_pipeline

    path = ROOT / "pipelines" / "evaluate_render.yaml"
    decl = read_pipeline(path)
    by_node: dict = {}
    for key, value in {**({} if keypoints else {"detect.frames": "none"}), **(sets or {})}.items():
        nid, _, param = key.partition(".")
        by_node.setdefault(nid, {})[param] = value
    errors: list = []
    for nid, params in by_node.items():
        merge_node_override(decl, nid, {"params": params}, Location(str(path), 1, 1), path.parent, errors)
    if errors:
        raise PipelineErrors(errors)
    return decl


def take_config(take: str, suit: str) -> tuple[dict, dict]:
    """``(sets, vars)`` of ``pipelines/evaluate_render.yaml`` rendering ``take`` (of :data:`TAKES` or
    :data:`HELD_OUT`) in ``suit`` (of :data:`SUITS`)."""
    clip, lead = {**TAKES, **HELD_OUT}[take]
    sets = {(k if "." in k else f"lead_in.{k}"): v for k, v in lead.items()}
    sets["colors.suit"] = sets["render.suit"] = str(SUITS[suit])
    return sets, {"bvh": str(ROOT / "data" / "mocap" / "cmu" / clip)}


def run_take(take: str, suit: str, keep: Path | None, keypoints: bool = True) -> dict:
    from tbha_graph.core.runner import load_graph, run_graph
    from tbha_graph.mocap.evaluate import measures as m
    from tbha_graph.mocap.suit import load_suit

    sets, vars = take_config(take, suit)
    graph = load_graph(ROOT / "pipelines" / "evaluate_render.yaml", sets=sets, vars=vars, decl=render_decl(keypoints))
    out = None if keep is None else keep / f"{take}-{suit}"
    outputs = ["metrics.json"] if keep is None else None
    t0 = time.perf_counter()
    run = run_graph(graph, out_dir=out, outputs=outputs, cache=False)
    seconds = time.perf_counter() - t0
    tracks = run.output("track.tracks")
    truth = {k: np.asarray(v) for k, v in run.output("render.ground_truth").items()}
    motion = run.output("smooth.motion")
    metrics = run.output("metrics.metrics")
    gt = truth["joints3d_world"]
    aligned, _ = m.align_clip(np.asarray(motion["joints"], dtype=np.float64), gt, "rigid")
    seq = float(np.nanmean(m.joint_distances(aligned, gt))) * 1000.0
    seq_seen, seen_pct = seen_seq_mpjpe(motion["joints"], truth)
    spec = load_suit(SUITS[suit])
    det = {k: np.asarray(v) for k, v in run.output("segment.detections").items()}
    s = label_scores(tracks, truth, spec.patch_radius, detected_patches(det, truth, spec, spec.patch_radius))
    ob, tot = off_body(tracks, truth)
    obp, totp = off_body(tracks, truth, placed_only=True)
    return {
        "take": take, "suit": suit, "frames": len(gt), "turn_deg": heading_range_deg(gt), "seq_mpjpe_mm": seq,
        "seq_mpjpe_seen_mm": seq_seen, "seen_pct": seen_pct,
        "seq_mpjpe_true_camera_mm": true_camera_seq_mpjpe(sets, vars, truth, keypoints),
        "visible": s["visible"], "wrong": s["wrong"], "missed": s["missed"], "delays": s["delays"],
        "delays_detected": s["delays_detected"],
        "off_body": ob, "points": tot, "off_body_placed": obp, "points_placed": totp, "seconds": seconds,
        "doubtful_ranges": metrics.get("doubtful_ranges"), "wrong_frames": s["wrong_frames"].tolist(),
    }


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.split("\n")[0])
    ap.add_argument("--takes", nargs="*", default=None, choices=list(TAKES) + list(HELD_OUT))
    ap.add_argument("--held-out", action="store_true", help="run the held-out takes instead of the tuning ones")
    ap.add_argument("--suits", nargs="*", default=list(SUITS), choices=list(SUITS))
    ap.add_argument("--keep", type=Path, default=None, help="write each take's run folder under this folder")
    ap.add_argument("--verbose", action="store_true", help="also print the frames with identity errors")
    ap.add_argument("--no-keypoints", dest="keypoints", action="store_false", help="capture without MediaPipe's "
                    "keypoints where no torso patch is seen (default.yaml's node detect off), to compare")
    a = ap.parse_args(argv)
    if a.takes is None:
        a.takes = list(HELD_OUT) if a.held_out else list(TAKES)
    rows = []
    for suit in a.suits:
        for take in a.takes:
            r = run_take(take, suit, a.keep, a.keypoints)
            rows.append(r)
            d = np.asarray(r["delays_detected"]) if r["delays_detected"] else np.zeros(0)
            dv = np.asarray(r["delays"]) if r["delays"] else np.zeros(0)
            print(f"take={take} suit={suit} frames={r['frames']} turn_deg={r['turn_deg']:.0f} "
                  f"identity_error_pct={100.0 * r['wrong'] / max(r['visible'], 1):.2f} "
                  f"missed_pct={100.0 * r['missed'] / max(r['visible'], 1):.2f} "
                  f"reacquire_events={d.size} reacquire_frames_p95={np.percentile(d, 95) if d.size else 0:.1f} "
                  f"reacquire_frames_p95_truth_visible={np.percentile(dv, 95) if dv.size else 0:.1f} "
                  f"off_body_pct={100.0 * r['off_body'] / r['points']:.2f} "
                  f"off_body_placed_pct={100.0 * r['off_body_placed'] / max(r['points_placed'], 1):.2f} "
                  f"seq_mpjpe_mm={r['seq_mpjpe_mm']:.1f} "
                  f"seq_mpjpe_true_camera_mm={r['seq_mpjpe_true_camera_mm']:.1f} "
                  f"seq_mpjpe_seen_mm={r['seq_mpjpe_seen_mm']:.1f} seen_pct={r['seen_pct']:.0f} "
                  f"seconds={r['seconds']:.0f}", flush=True)
            if a.verbose:
                print(f"  wrong_frames={r['wrong_frames']}\n  doubtful_ranges={json.dumps(r['doubtful_ranges'])}", flush=True)
    for suit in a.suits:  # per suit kind
        rs = [r for r in rows if r["suit"] == suit]
        d = np.asarray([x for r in rs for x in r["delays_detected"]])
        print(f"suit={suit} identity_error_pct={100.0 * sum(r['wrong'] for r in rs) / max(sum(r['visible'] for r in rs), 1):.2f} "
              f"reacquire_frames_p95={np.percentile(d, 95) if d.size else 0:.1f}")
    vis = sum(r["visible"] for r in rows)
    delays = np.asarray([x for r in rows for x in r["delays_detected"]])
    delays_v = np.asarray([x for r in rows for x in r["delays"]])
    print(f"identity_error_pct={100.0 * sum(r['wrong'] for r in rows) / max(vis, 1):.2f}")
    print(f"missed_pct={100.0 * sum(r['missed'] for r in rows) / max(vis, 1):.2f}")
    print(f"reacquire_frames_p95={np.percentile(delays, 95) if delays.size else 0:.1f}")
    print(f"reacquire_frames_p95_truth_visible={np.percentile(delays_v, 95) if delays_v.size else 0:.1f}")
    print(f"off_body_pct={100.0 * sum(r['off_body'] for r in rows) / sum(r['points'] for r in rows):.2f}")
    print(f"off_body_placed_pct={100.0 * sum(r['off_body_placed'] for r in rows) / max(sum(r['points_placed'] for r in rows), 1):.2f}")
    print(f"seq_mpjpe_mm_max={max(r['seq_mpjpe_mm'] for r in rows):.1f}")
    print(f"seq_mpjpe_true_camera_mm_max={max(r['seq_mpjpe_true_camera_mm'] for r in rows):.1f}")
    print(f"seq_mpjpe_seen_mm_max={max(r['seq_mpjpe_seen_mm'] for r in rows):.1f}")


if __name__ == "__main__":
    main()
