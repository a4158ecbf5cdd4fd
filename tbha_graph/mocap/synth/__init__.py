"""Synthetic tight-suit video: a shaded body of volumes with coloured patches, rendered from real motion
with a known camera, plus the ground truth the tracker and solvers are judged against.

Nodes: ``synth.render_suit_video``, ``synth.camera``, ``synth.tpose_lead_in``.
"""
