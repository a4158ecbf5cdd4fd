"""Live keypoint detectors run on a video (optional extras, imported only when a node runs)."""
