"""A small BVH (Biovision Hierarchy) reader: joints, channels and the MOTION block as numpy.

Why our own parser: no BVH package is available from the project's package index
(``bvh``, ``bvhio``, ``pybvh`` all missing), adding a dependency is the lead's call,
and what handrig needs is small: joint names, channel names, frame time and the
motion matrix in degrees. The MOTION block is parsed in one ``np.array(split)``
call (about 190 000 numbers in a few tens of milliseconds); rotations are not
composed, because the finger-dimensionality paper works on the channel angles.

Errors are :class:`~handrig.errors.DataError` naming the file and the line or frame.
"""

from __future__ import annotations

import io
import itertools
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np
from numpy.typing import NDArray

from handrig.config import bounded
from handrig.config.bounded import excerpt
from handrig.errors import DataError

CHANNEL_NAMES = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")


@dataclass(frozen=True)
class BvhJoint:
    """One joint of the hierarchy; ``channel_start`` is its first column in the motion matrix."""

    name: str
    parent: int  # index into Bvh.joints, -1 for the root
    offset: tuple[float, float, float]
    channels: tuple[str, ...]
    channel_start: int
    end_site: tuple[float, float, float] = (0.0, 1.0, 0.0)  # written for a joint with no child


@dataclass(frozen=True)
class Bvh:
    """A parsed BVH file: the hierarchy and ``motion`` (frames x channels), angles in degrees."""

    joints: tuple[BvhJoint, ...]
    frame_time_s: float
    motion: NDArray[np.float64]
    source: str = "<string>"

    @property
    def n_frames(self) -> int:
        return int(self.motion.shape[0])

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time_s

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    def joint(self, name: str) -> BvhJoint:
        """The joint called ``name``; DataError listing near names otherwise."""
        for j in self.joints:
            if j.name == name:
                return j
        raise DataError(f"{self.source}: no joint {name!r} in the hierarchy")

    def column(self, joint: str, channel: str) -> int:
        """Column of ``channel`` (e.g. ``"Zrotation"``) of ``joint`` in :attr:`motion`."""
        j = self.joint(joint)
        if channel not in j.channels:
            raise DataError(
                f"{self.source}: joint {joint!r} has no {channel} channel"
                f" (it has {', '.join(j.channels) or 'none'})"
            )
        return j.channel_start + j.channels.index(channel)


class _Tokens:
    """Whitespace tokens of the HIERARCHY block with their line numbers."""

    def __init__(self, lines: list[str], source: str) -> None:
        self.items: list[tuple[str, int]] = [
            (tok, n + 1) for n, line in enumerate(lines) for tok in line.split()
        ]
        self.pos = 0
        self.source = source

    def fail(self, msg: str) -> DataError:
        line = self.items[min(self.pos, len(self.items) - 1)][1] if self.items else 1
        return DataError(f"{self.source}: line {line}: {msg}")

    def next(self, what: str) -> str:
        if self.pos >= len(self.items):
            raise self.fail(f"file ends early: expected {what}")
        tok = self.items[self.pos][0]
        self.pos += 1
        return tok

    def expect(self, word: str) -> None:
        tok = self.next(repr(word))
        if tok != word:
            self.pos -= 1
            raise self.fail(f"expected {word!r}, found {excerpt(tok)}")

    def number(self, what: str) -> float:
        tok = self.next(what)
        try:
            return float(tok)
        except ValueError:
            self.pos -= 1
            raise self.fail(f"expected a number for {what}, found {excerpt(tok)}") from None

    def peek(self) -> str | None:
        return self.items[self.pos][0] if self.pos < len(self.items) else None


def _parse_joint(
    toks: _Tokens, name: str, parent: int, joints: list[BvhJoint], n_channels: int
) -> int:
    toks.expect("{")
    toks.expect("OFFSET")
    offset = (toks.number("OFFSET x"), toks.number("OFFSET y"), toks.number("OFFSET z"))
    channels: tuple[str, ...] = ()
    if toks.peek() == "CHANNELS":
        toks.next("CHANNELS")
        count_tok = toks.next("channel count")
        if not (count_tok.isascii() and count_tok.isdigit()):
            toks.pos -= 1
            raise toks.fail(f"expected a channel count, found {excerpt(count_tok)}")
        chans = []
        for _ in range(int(count_tok)):
            ch = toks.next("a channel name")
            if ch not in CHANNEL_NAMES:
                toks.pos -= 1
                raise toks.fail(
                    f"unknown channel {excerpt(ch)} of joint {excerpt(name)} (known: "
                    f"{', '.join(CHANNEL_NAMES)})"
                )
            chans.append(ch)
        channels = tuple(chans)
    index = len(joints)
    joints.append(BvhJoint(name, parent, offset, channels, n_channels))
    n_channels += len(channels)
    while True:
        tok = toks.next("'}', JOINT or End Site")
        if tok == "}":
            return n_channels
        if tok == "JOINT":
            n_channels = _parse_joint(toks, toks.next("a joint name"), index, joints, n_channels)
        elif tok == "End":
            toks.expect("Site")
            toks.expect("{")
            toks.expect("OFFSET")
            for axis in "xyz":
                toks.number(f"End Site OFFSET {axis}")
            toks.expect("}")
        else:
            toks.pos -= 1
            raise toks.fail(f"expected '}}', JOINT or End Site in joint {excerpt(name)}, found "
                            f"{excerpt(tok)}")


def parse_bvh(text: str, source: str = "<string>") -> Bvh:
    """Parse BVH ``text``; ``source`` names the file in error messages."""
    return _parse_lines(enumerate(text.splitlines(), start=1), source)


MAX_HIERARCHY_BYTES = 1 << 20
"""A HIERARCHY block is a few kilobytes (60 joints: about 10 kB)."""
_BLOCK_FRAMES = 2048


def _parse_lines(lines: Iterator[tuple[int, str]], source: str) -> Bvh:
    """Parse numbered lines (a file's, read one at a time: the hierarchy and one block
    of frames at a time are held as text)."""
    head: list[str] = []
    size = 0
    for _, ln in lines:
        if ln.strip() == "MOTION":
            break
        head.append(ln)
        size += len(ln) + 1
        if size > MAX_HIERARCHY_BYTES:
            raise DataError(f"{source}: no MOTION block in the first {MAX_HIERARCHY_BYTES}"
                            " bytes: not a BVH file")
    else:
        raise DataError(f"{source}: no MOTION block: not a BVH file, or the file is cut short")
    joints, n_channels = parse_hierarchy(head, source)
    header: list[tuple[int, str]] = []
    for n, ln in lines:
        if ln.strip():
            header.append((n, ln.strip()))
            if len(header) == 2:
                break
    n_frames, frame_time_s, _ = _motion_header(header, source)
    motion = _motion_matrix(lines, n_frames, n_channels, source)
    return Bvh(tuple(joints), frame_time_s, motion, source)


def parse_hierarchy(lines: list[str], source: str = "<string>") -> tuple[list[BvhJoint], int]:
    """The joints of a ``HIERARCHY`` block (``lines`` up to ``MOTION``) and the channel count."""
    toks = _Tokens(lines, source)
    toks.expect("HIERARCHY")
    joints: list[BvhJoint] = []
    n_channels = 0
    while toks.peek() is not None:
        toks.expect("ROOT")
        n_channels = _parse_joint(toks, toks.next("the root name"), -1, joints, n_channels)
    if not joints:
        raise DataError(f"{source}: the HIERARCHY block has no ROOT joint")
    return joints, n_channels


UNFINISHED_HINT = ("if the recording was cut short (a crash, a power cut), `handrig record"
                   " repair FILE` keeps every whole frame and sets 'Frames:'")


def _motion_header(header: list[tuple[int, str]], source: str) -> tuple[int, float, int]:
    body = [(n, s) for n, s in header if s][:2]
    if len(body) < 2 or not body[0][1].startswith("Frames:") or not body[1][1].startswith(
        "Frame Time:"
    ):
        raise DataError(f"{source}: MOTION must be followed by 'Frames: N' and 'Frame Time: T'")
    try:
        n_frames = int(body[0][1].split(":", 1)[1])
        frame_time_s = float(body[1][1].split(":", 1)[1])
    except ValueError:
        raise DataError(
            f"{source}: line {body[0][0]}: cannot read 'Frames:'/'Frame Time:' values"
        ) from None
    if n_frames == 0:
        raise DataError(f"{source}: 'Frames: 0': an empty recording, or one that was never"
                        f" finished; {UNFINISHED_HINT}")
    if n_frames < 1 or not 0.0 < frame_time_s < float("inf"):
        raise DataError(
            f"{source}: Frames = {n_frames} and Frame Time = {frame_time_s}: need at least one"
            " frame and a positive frame time"
        )
    return n_frames, frame_time_s, body[1][0]  # 1-based line number == 0-based next line


def _motion_matrix(
    lines: Iterator[tuple[int, str]], n_frames: int, n_channels: int, source: str
) -> NDArray[np.float64]:
    blocks: list[NDArray[np.float64]] = []
    done = 0  # frames parsed
    chunk: list[str] = []
    for item in itertools.chain(lines, [(0, "")]):
        if item[0]:
            if item[1].strip():
                chunk.append(item[1])
            if len(chunk) < _BLOCK_FRAMES:
                continue
        if not chunk:
            continue
        ends = item[0] == 0
        flat = _numbers(chunk, done, source, ends)
        if flat.size != len(chunk) * n_channels or done + len(chunk) > n_frames:
            counts = [len(ln.split()) for ln in chunk]
            bad = next((k for k, c in enumerate(counts) if c != n_channels), len(counts))
            if done + bad >= n_frames:
                raise DataError(
                    f"{source}: MOTION frame {n_frames} (0-based) is more than the header"
                    f" declares ({n_frames} frames of {n_channels} channels): fix 'Frames:',"
                    f" or {UNFINISHED_HINT}")
            if not ends or bad < len(counts) - 1:
                raise DataError(
                    f"{source}: MOTION frame {done + bad} (0-based) has {counts[bad]} values,"
                    f" expected {n_channels}")
            raise DataError(
                f"{source}: MOTION is truncated at frame {done + bad} (0-based): the header"
                f" declares {n_frames} frames of {n_channels} channels; frame {done + bad} has"
                f" {counts[bad]} values and {done + len(chunk)} frame lines are present."
                f" Re-export the file, or {UNFINISHED_HINT}")
        blocks.append(flat.reshape(len(chunk), n_channels))
        done += len(chunk)
        chunk = []
    if done < n_frames:
        raise DataError(
            f"{source}: MOTION is truncated at frame {done} (0-based): the header declares"
            f" {n_frames} frames of {n_channels} channels; frame {done} has 0 values"
            f" and {done} frame lines are present. Re-export the file, or {UNFINISHED_HINT}")
    if not blocks:
        return np.zeros((0, n_channels))
    return np.concatenate(blocks) if len(blocks) > 1 else blocks[0]


def _numbers(chunk: list[str], first: int, source: str, ends: bool) -> NDArray[np.float64]:
    """The numbers of frame lines ``chunk`` (frame ``first`` onwards)."""
    try:
        return np.array(" ".join(chunk).split(), dtype=np.float64)
    except ValueError:
        for k, ln in enumerate(chunk):
            for tok in ln.split():
                try:
                    float(tok)
                except ValueError:
                    last = (f" (the last frame: the file is cut; {UNFINISHED_HINT})"
                            if ends and k == len(chunk) - 1 else "")
                    raise DataError(
                        f"{source}: MOTION frame {first + k}: {excerpt(tok, 24)} is not a"
                        f" number{last}") from None
        raise


def read_bvh(path: str | Path) -> Bvh:
    """Read and parse the BVH file at ``path``, one line at a time (a line over
    :data:`~handrig.config.bounded.MAX_LINE_BYTES`, or bytes that are not text, are
    refused where they are)."""
    p = Path(path)
    try:
        with p.open("rb") as f:
            return _parse_lines(bounded.lines(f, p, "a BVH file"), str(p))
    except FileNotFoundError:
        raise DataError(f"{p}: file not found") from None
    except OSError as exc:
        raise DataError(f"{p}: cannot read: {exc.strerror}") from None


def format_bvh(bvh: Bvh, decimals: int = 5) -> str:
    """BVH text for ``bvh`` (joints as a tree, one frame per line); :func:`parse_bvh` reads it."""
    buf = io.StringIO()
    write_bvh(buf, bvh, decimals)
    return buf.getvalue()


def format_hierarchy(joints: tuple[BvhJoint, ...] | list[BvhJoint]) -> str:
    """The ``HIERARCHY`` block for ``joints`` (joints as a tree), ending in a newline."""
    children: dict[int, list[int]] = {}
    for i, j in enumerate(joints):
        children.setdefault(j.parent, []).append(i)
    out = ["HIERARCHY"]

    def emit(i: int, depth: int) -> None:
        j = joints[i]
        pad = "\t" * depth
        out.append(f"{pad}{'ROOT' if j.parent < 0 else 'JOINT'} {j.name}")
        out.append(f"{pad}{{")
        out.append(f"{pad}\tOFFSET {j.offset[0]:.6f} {j.offset[1]:.6f} {j.offset[2]:.6f}")
        if j.channels:
            out.append(f"{pad}\tCHANNELS {len(j.channels)} {' '.join(j.channels)}")
        kids = children.get(i, [])
        for k in kids:
            emit(k, depth + 1)
        if not kids:
            e = j.end_site
            out.extend([f"{pad}\tEnd Site", f"{pad}\t{{",
                        f"{pad}\t\tOFFSET {e[0]:.6f} {e[1]:.6f} {e[2]:.6f}", f"{pad}\t}}"])
        out.append(f"{pad}}}")

    for root in children.get(-1, []):
        emit(root, 0)
    return "\n".join(out) + "\n"


def write_bvh(f: TextIO, bvh: Bvh, decimals: int = 5) -> None:
    """Write ``bvh`` to the text stream ``f`` (the motion block with numpy, for long takes)."""
    f.write(format_hierarchy(bvh.joints))
    f.write(f"MOTION\nFrames: {bvh.n_frames}\nFrame Time: {bvh.frame_time_s:.10g}\n")
    if bvh.n_frames:
        np.savetxt(f, bvh.motion, fmt=f"%.{decimals}f", delimiter=" ")


def make_bvh(
    joint_names: list[str] | tuple[str, ...],
    motion: NDArray[np.float64],
    frame_time_s: float = 1.0 / 30.0,
    channels: tuple[str, ...] = ("Zrotation", "Xrotation", "Yrotation"),
) -> Bvh:
    """A flat BVH: the first joint is the root, every other joint its child, same channels.

    ``motion`` is frames x (len(joint_names) * len(channels)). For tests and for writing
    derived recordings; real skeletons come from :func:`read_bvh`.
    """
    joints = tuple(
        BvhJoint(name, -1 if i == 0 else 0, (0.0, 0.0, 0.0), channels, i * len(channels))
        for i, name in enumerate(joint_names)
    )
    m = np.asarray(motion, dtype=np.float64)
    if m.ndim != 2 or m.shape[1] != len(joints) * len(channels):
        raise DataError(
            f"motion must be frames x {len(joints) * len(channels)} channels, got {m.shape}"
        )
    return Bvh(joints, frame_time_s, m)
