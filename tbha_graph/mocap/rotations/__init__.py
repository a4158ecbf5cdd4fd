"""Joint rotations from 3D joint positions: the seed 002 quaternion solver and a Kabsch alternative."""
