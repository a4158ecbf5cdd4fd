"""Bundled skeleton mapping files (YAML): source BVH joint names -> the 16 TBHA joints."""
