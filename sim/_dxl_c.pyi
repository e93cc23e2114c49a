"""Types of the compiled packet path (sim/_dxl_c.c)."""

from collections.abc import Sequence

from typing_extensions import Buffer

def crc16(data: Buffer, crc: int = 0, /) -> int: ...
def fill_fast_read(reply: bytearray, mems: Sequence[bytearray], address: int, length: int,
                   prefix: int, error_address: int, alert: int, /) -> None: ...
def write_goals(servos: Sequence[object], mems: Sequence[bytearray], body: Buffer,
                now: float, /) -> None: ...
