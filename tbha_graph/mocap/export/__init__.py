"""Export nodes: write results in formats other software reads (BVH, ...)."""
