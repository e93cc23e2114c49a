"""OSC 1.0 packets: messages and bundles, bytes to values and back (pure, no I/O).

A message is an address (an OSC-string: ASCII, NUL-terminated, padded with NULs to a
multiple of 4 bytes), a type tag string (``,`` then one tag per argument) and the
arguments: ``i`` a 32-bit big-endian two's complement integer, ``f`` a 32-bit big-endian
IEEE 754 float, ``s`` an OSC-string. A bundle is ``#bundle``, an 8-byte time tag and
elements, each a 32-bit size (a multiple of 4) and a message or a bundle. Cues take only
these three tags: a message with any other tag (``b`` blobs, ``T``/``F``, ``h``, ...),
without a type tag string, or cut short is malformed (:class:`MalformedOsc`), and in a
bundle only that element is lost. Time tags are not waited on: a bundle acts when it
arrives (a show controller sends "now", 1).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from handrig.errors import ProtocolError

OscArg = int | float | str
BUNDLE_HEAD = b"#bundle\x00"
MAX_DEPTH = 8
"""Bundles nested deeper than this are malformed (a packet is at most a datagram)."""
_INT = struct.Struct(">i")
_FLOAT = struct.Struct(">f")


class MalformedOsc(ProtocolError):
    """Bytes that are not an OSC 1.0 message or bundle of the kind cues take."""


@dataclass(frozen=True, slots=True)
class OscMessage:
    address: str
    args: tuple[OscArg, ...] = ()


def _string(data: bytes, at: int) -> tuple[str, int]:
    end = data.find(b"\x00", at)
    if end < 0:
        raise MalformedOsc(f"an OSC-string at byte {at} has no terminating NUL")
    nxt = (end + 4) & ~3
    if nxt > len(data) or data[end:nxt].strip(b"\x00"):
        raise MalformedOsc(f"the OSC-string at byte {at} is not padded to 4 bytes")
    try:
        return data[at:end].decode("ascii"), nxt
    except UnicodeDecodeError:
        raise MalformedOsc(f"the OSC-string at byte {at} is not ASCII") from None


def parse_message(data: bytes) -> OscMessage:
    """One OSC message; :class:`MalformedOsc` when it is not one cues take."""
    if len(data) % 4:
        raise MalformedOsc(f"a message of {len(data)} bytes (not a multiple of 4)")
    address, at = _string(data, 0)
    if not address.startswith("/"):
        raise MalformedOsc(f"the address {address!r} does not start with '/'")
    if at >= len(data):
        raise MalformedOsc(f"{address}: no type tag string")
    tags, at = _string(data, at)
    if not tags.startswith(","):
        raise MalformedOsc(f"{address}: no type tag string")
    args: list[OscArg] = []
    for tag in tags[1:]:
        if tag == "s":
            text, at = _string(data, at)
            args.append(text)
            continue
        if tag not in "if":
            raise MalformedOsc(f"{address}: argument type {tag!r} (cues take s, i and f)")
        if at + 4 > len(data):
            raise MalformedOsc(f"{address}: the message ends inside its arguments")
        args.append((_INT if tag == "i" else _FLOAT).unpack_from(data, at)[0])
        at += 4
    if at != len(data):
        raise MalformedOsc(f"{address}: {len(data) - at} bytes after the arguments")
    return OscMessage(address, tuple(args))


def parse_packet(data: bytes) -> tuple[list[OscMessage], int]:
    """A datagram's messages (a message, or a bundle's, nested bundles in order) and how
    many of its messages or elements were malformed (those are left out)."""
    out: list[OscMessage] = []
    bad = _parse(data, out, 0)
    return out, bad


def _parse(data: bytes, out: list[OscMessage], depth: int) -> int:
    if not data.startswith(BUNDLE_HEAD):
        try:
            out.append(parse_message(data))
        except MalformedOsc:
            return 1
        return 0
    if depth >= MAX_DEPTH or len(data) < 16:
        return 1
    bad, at = 0, 16  # the head and the 8-byte time tag
    while at < len(data):
        if at + 4 > len(data):
            return bad + 1
        size = _INT.unpack_from(data, at)[0]
        at += 4
        if size <= 0 or size % 4 or at + size > len(data):
            return bad + 1  # the rest of the bundle cannot be framed
        bad += _parse(data[at:at + size], out, depth + 1)
        at += size
    return bad


def _pad(raw: bytes) -> bytes:
    return raw + b"\x00" * (4 - len(raw) % 4)


def encode_message(address: str, *args: OscArg) -> bytes:
    """An OSC message (a show controller's side: tests and the benchmark)."""
    tags, body = ",", b""
    for a in args:
        if isinstance(a, bool) or not isinstance(a, int | float | str):
            raise TypeError(f"an OSC argument must be int, float or str, not {type(a)}")
        if isinstance(a, str):
            tags, body = tags + "s", body + _pad(a.encode("ascii"))
        elif isinstance(a, int):
            tags, body = tags + "i", body + _INT.pack(a)
        else:
            tags, body = tags + "f", body + _FLOAT.pack(a)
    return _pad(address.encode("ascii")) + _pad(tags.encode("ascii")) + body


def encode_bundle(*elements: bytes, time_tag: int = 1) -> bytes:
    """An OSC bundle of encoded messages or bundles (time tag 1: "now")."""
    return BUNDLE_HEAD + time_tag.to_bytes(8, "big") + b"".join(
        _INT.pack(len(e)) + e for e in elements)
