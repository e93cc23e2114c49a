"""``sim.bake.plot`` leaves no garbage behind for a later ``gc.collect()`` to pay for.

Regression: ``handrig bake --plot`` in the same process as the rig left the sheet's
reference cycles (about 90 000 objects) to the rig's pre-loop ``gc.collect()``,
which then took over 0.1 s; the emulated servos' 100 ms Bus Watchdog tripped and
they refused every goal (the puppet's index MCP stayed at 1 deg).
"""

from __future__ import annotations

import gc
from pathlib import Path

import numpy as np

from handrig.hand import DOF_NAMES, dof_limits_deg
from sim import bake

# The old pyplot sheet left about 8 600 here (90 000 for a real grid); the fixed one 0.
MAX_UNREACHABLE = 500


def _tiny_grid() -> bake.BakedGrid:
    inc = np.linspace(-90.0, 90.0, 4)
    rot = np.linspace(-180.0, 90.0, 4)
    inc_g, rot_g = np.meshgrid(inc, rot, indexing="ij")
    n = len(DOF_NAMES["ri"])
    dofs = np.arange(len(inc) * len(rot) * n, dtype=float).reshape(len(inc), len(rot), n)
    return bake.BakedGrid(inc_g, rot_g, dofs, np.zeros(n), dof_limits_deg("ri"),
                          {"solver": "test", "step_deg": 60.0, "hand_length_m": 0.19})


def test_plot_leaves_no_reference_cycles(tmp_path: Path) -> None:
    grid = _tiny_grid()
    gc.collect()
    enabled = gc.isenabled()
    gc.disable()  # nothing collects behind the test's back: what plot leaves, stays
    try:
        png = bake.plot(grid, tmp_path / "sheet.png")
        left = gc.collect()
    finally:
        if enabled:
            gc.enable()
    assert png.stat().st_size > 10_000
    assert left < MAX_UNREACHABLE, f"plot left {left} objects in reference cycles"

