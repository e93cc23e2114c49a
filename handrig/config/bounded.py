"""Reading files with bounded memory and bounded messages.

Every file handrig reads may be anything: a 2 GB sparse file of NULs, one endless
line, random bytes. The readers here refuse what cannot be the file they expect
within a fixed amount of memory: a file over its kind's size, a line over its kind's
length, bytes that are not UTF-8; and an error quotes at most :data:`EXCERPT_CHARS`
characters of what it found, escaped (:func:`excerpt`), so a message stays a line.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from handrig.errors import ConfigError, DataError, HandrigError

EXCERPT_CHARS = 32
"""Characters of a file's content an error message quotes at most."""
MAX_CONFIG_BYTES = 4 << 20
"""A TOML file handrig reads (rig, glove, map, show, limits): a few kilobytes; this is
far above any real one and far below what would take seconds or much memory to parse."""
MAX_LINE_BYTES = 64 << 10
"""A line of a take or a recording: a frame of 55 numbers is about 600 bytes."""


def excerpt(data: bytes | str, limit: int = EXCERPT_CHARS) -> str:
    """``data``'s first ``limit`` characters, escaped and quoted (at most about four
    times ``limit`` characters), with the whole length when it was cut."""
    head = data[:limit]
    text = head.decode("utf-8", errors="backslashreplace") if isinstance(head, bytes) else head
    if len(data) <= limit:
        return repr(text)
    return f"{text!r}... ({len(data)} {'bytes' if isinstance(data, bytes) else 'characters'})"


def fail(p: Path, message: str, error: type[HandrigError] = DataError) -> HandrigError:
    """``error`` naming the file ``p`` (a ConfigError carries it as its file)."""
    if issubclass(error, ConfigError):
        return error(message, file=str(p))
    return error(f"{p}: {message}")


def size_of(p: Path, error: type[HandrigError] = DataError) -> int:
    """The size of ``p``; the error names the file when it is missing or unreadable."""
    try:
        return p.stat().st_size
    except FileNotFoundError:
        raise fail(p, "file not found", error) from None
    except OSError as exc:
        raise fail(p, f"cannot read: {exc.strerror}", error) from None


def check_size(p: Path, max_bytes: int, what: str,
               error: type[HandrigError] = DataError) -> int:
    """``p``'s size, or the error when it is over ``max_bytes`` (not a ``what``)."""
    size = size_of(p, error)
    if size > max_bytes:
        raise fail(p, f"{_mb(size)}, and {what} is at most {_mb(max_bytes)}: not {what},"
                   " or the wrong file", error)
    return size


def read_text(p: Path, max_bytes: int, what: str,
              error: type[HandrigError] = DataError) -> str:
    """The whole of a small file as UTF-8 text: refused over ``max_bytes`` or when it is
    not UTF-8 (the message says where, with an excerpt)."""
    check_size(p, max_bytes, what, error)
    try:
        with p.open("rb") as f:
            data = f.read(max_bytes + 1)
    except FileNotFoundError:
        raise fail(p, "file not found", error) from None
    except OSError as exc:
        raise fail(p, f"cannot read: {exc.strerror}", error) from None
    if len(data) > max_bytes:  # grew since the stat
        raise fail(p, f"over {_mb(max_bytes)}: not {what}", error)
    return decode(data, p, what, error)


def decode(data: bytes, p: Path, what: str, error: type[HandrigError] = DataError,
           line: int | None = None) -> str:
    """``data`` as UTF-8; the error names the byte (and line) and quotes a little."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        where = f"byte {exc.start + 1}"
        if line is not None:
            where = f"line {line}, {where}"
        raise fail(p, f"{where}: not text (UTF-8) near "
                   f"{excerpt(data[max(0, exc.start - 8):exc.start + 8])}: not {what}",
                   error) from None


def lines(f: BinaryIO, p: Path, what: str, max_line_bytes: int = MAX_LINE_BYTES,
          error: type[HandrigError] = DataError, first_line: int = 1
          ) -> Iterator[tuple[int, str]]:
    """(line number, text without its newline) of each line of ``f`` from where it is;
    the error for a line over ``max_line_bytes`` or one that is not UTF-8."""
    n = first_line
    while True:
        raw = f.readline(max_line_bytes + 1)
        if not raw:
            return
        if len(raw) > max_line_bytes:
            raise fail(p, f"line {n} is longer than {max_line_bytes} bytes (it starts "
                       f"{excerpt(raw)}): not {what}", error)
        yield n, decode(raw, p, what, error, line=n).rstrip("\r\n")
        n += 1


def _mb(n: int) -> str:
    return f"{n / 1e6:.1f} MB" if n >= 100_000 else f"{n} bytes"
