"""Evaluation: accuracy and quality figures of a capture (with or without ground truth)."""
