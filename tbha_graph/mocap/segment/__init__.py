"""Patch segmenters: find the suit's coloured patches (and the dark head) in every video frame."""
