"""3D reconstruction nodes: bone lengths (``reconstruct.bone_lengths``), the seed's ray-sphere expansion
(``reconstruct.ray_sphere``) and windowed least squares (``reconstruct.sequence_lsq``)."""
