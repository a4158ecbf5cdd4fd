"""SMPL body model: 24-joint tree, conversion of the 16-joint rotations to SMPL pose parameters (AMASS-style
``.npz``), a numpy SMPL model (blend shapes + linear blend skinning) and mesh export."""
