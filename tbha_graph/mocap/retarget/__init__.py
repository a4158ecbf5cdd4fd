"""Retargeting: the 16-joint motion written onto a user's character skeleton (its names, hierarchy, rest pose)."""
