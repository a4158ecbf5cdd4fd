"""2D trackers: turn per-frame patch detections into identified joint tracks."""
