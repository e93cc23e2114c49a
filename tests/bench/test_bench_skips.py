"""The skip-event bench's classification, on made-up cycles."""

from __future__ import annotations

import numpy as np

from bench.bench_skips import classify


def test_each_skip_is_put_down_to_what_the_cycle_before_it_did() -> None:
    p = 0.002
    # per cycle: written, done, reads so far, frames skipped so far, thread CPU so far
    rows = np.array([
        (0.000, 0.0002, 0, 0, 0.0000),
        (0.002, 0.0022, 0, 0, 0.0003),
        (0.004, 0.0080, 1, 0, 0.0010),  # a read that ran 4 ms after its write
        (0.010, 0.0102, 1, 1, 0.0020),  # -> one frame skipped: "read"
        (0.012, 0.0160, 1, 1, 0.0060),  # 4 ms after its write, no read
        (0.018, 0.0182, 1, 2, 0.0065),  # -> "after write"
        (0.020, 0.0202, 1, 2, 0.0068),  # done in time
        (0.026, 0.0262, 1, 4, 0.0070),  # the thread barely ran for 6 ms: "host", 2 frames
        (0.028, 0.0282, 1, 4, 0.0073),
        (0.034, 0.0342, 1, 5, 0.0130),  # done in time but busy all along: "loop busy"
    ])
    got = classify(rows, p)
    assert [(c, n) for c, n, _, _ in got] == [
        ("read", 1), ("after write", 1), ("host", 2), ("loop busy", 1)]
    assert np.allclose([a for _, _, a, _ in got], [0.004, 0.004, 0.0002, 0.0002])
    shares = [share for _, _, _, share in got]
    assert shares[2] < 0.5 <= shares[3]  # the host's stall against the loop's own work
