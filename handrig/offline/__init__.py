"""Offline analysis: reading captures (BVH, mocap profiles), the paper's analysis,
map evaluation and reports."""
