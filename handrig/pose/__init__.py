"""The pose layer, pure numpy and numba: maps, expansion, sag, forearm orientation,
retargeting, the compiled per-cycle pipeline. No device or wire code."""
