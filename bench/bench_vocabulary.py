"""Vocabulary lookups: name -> index and mirroring, which configs and the CLI use."""

from __future__ import annotations

import timeit

import numpy as np

from handrig import hand


def main() -> None:
    n = 100_000
    t = timeit.timeit(lambda: hand.curve_index("lePinkyDIPy"), number=n)
    print(f"curve_index lookup: {t / n * 1e9:.0f} ns")
    pose = np.zeros(50)
    t = timeit.timeit(lambda: hand.mirror_pose(pose), number=n)
    print(f"mirror_pose (50 curves): {t / n * 1e6:.2f} us")
