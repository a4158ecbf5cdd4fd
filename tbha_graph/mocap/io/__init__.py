"""Input/output nodes and readers: BVH files, skeleton mappings, videos."""
