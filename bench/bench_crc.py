"""The driver's CRC called from Python, against fastcrc (if installed) and the SDK's loop.

The cycle's own CRCs (goal Sync Write, whole Fast Sync Read reply) are computed
inside the compiled kernels; a CRC called from Python is paid per status packet
on the Sync Read fallback (one per servo per read) and per command.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from handrig.devices.servo import codec


def _per_call_ns(fn: Callable[[], object], n: int = 20_000, repeats: int = 5) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        best = min(best, (time.perf_counter() - t0) / n)
    return best * 1e9


def main() -> None:
    from dynamixel_sdk.protocol2_packet_handler import Protocol2PacketHandler

    sdk = Protocol2PacketHandler()
    codec.warm_up()
    try:
        from fastcrc import crc16 as fast16
    except ImportError:
        fast16 = None
    print("CRC-16 per call from Python, best of 5 (ns):")
    print(f"  {'bytes':>6} {'codec.crc16':>12} {'fastcrc':>9} {'SDK updateCRC':>14}")
    for n in (21, 168):  # a Sync Read status of 10 bytes; a Fast Sync Read reply, 20 servos
        data = bytes(np.random.default_rng(n).integers(0, 256, n, dtype=np.uint8))
        ours = _per_call_ns(lambda d=data: codec.crc16(d))
        fast = _per_call_ns(lambda d=data: fast16.umts(d, 0)) if fast16 else float("nan")
        ref = _per_call_ns(lambda d=data: sdk.updateCRC(0, list(d), len(d)), n=2_000)
        print(f"  {n:>6} {ours:>12.0f} {fast:>9.0f} {ref:>14.0f}")
    print("  (the cycle's CRCs run inside the compiled kernels: none of these per cycle "
          "on the Fast Sync Read path; one per servo per read on the Sync Read fallback)")


if __name__ == "__main__":
    main()
