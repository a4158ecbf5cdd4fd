"""Smoothing and constraint filters on 3D motion (MOTION in, MOTION out)."""
