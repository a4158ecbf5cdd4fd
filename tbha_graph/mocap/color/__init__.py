"""Colour models: the suit's patch colours expressed in a colour space, consumed by the segmenters."""
