"""Tracking-by-detection with a pluggable box filter: SORT-style association (optionally ByteTrack's two stages)
over the filters of :mod:`bboxtune.filters`, stock or tuned per track from its own past."""
