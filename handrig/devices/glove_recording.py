"""Glove recordings: a CSV file of raw glove samples over time.

Format (UTF-8 text)::

    # handrig glove recording 1
    # rate_hz: 100
    t_s,thumb_cmc_x,thumb_cmc_y,thumb_cmc_z,index_mcp,pinky_mcp,qx,qy,qz,qw,buttons
    0.000000,2048,1900,1500,800,700,0.0,0.0,0.0,1.0,0
    0.010000,2050,1902,1510,820,705,0.0,0.0,0.0,1.0,0

* The first line names the format and version; further ``# key: value`` lines
  are metadata (``rate_hz`` is the glove's nominal rate; others are kept).
* The header: ``t_s`` first (seconds from the start, strictly increasing), then
  one column per raw channel (any names, in the glove's channel order), then
  optionally ``qx,qy,qz,qw`` (the forearm IMU quaternion, scalar last, ENU world
  frame, as in ``firmware_protocol/SPEC.md``; empty cells = no IMU reading), then
  ``buttons`` (integer bitfield, bit 0 = relax / e-stop).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from handrig.config import bounded
from handrig.config.bounded import excerpt
from handrig.errors import DataError

MAGIC = "# handrig glove recording 1"
QUAT_COLUMNS = ("qx", "qy", "qz", "qw")

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(frozen=True, eq=False)
class GloveRecording:
    """Raw glove samples over time.

    ``t_s`` (n,) seconds, strictly increasing; ``raw`` (n, k) raw channel counts;
    ``quat_xyzw`` (n, 4) or ``None`` when the recording has no IMU (a row of NaN
    is a sample without a valid reading); ``buttons`` (n,) bitfields.
    """

    t_s: FloatArray
    raw: FloatArray
    buttons: IntArray
    channel_names: tuple[str, ...]
    quat_xyzw: FloatArray | None = None
    rate_hz: float = 0.0
    meta: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.t_s)
        if self.raw.ndim != 2 or self.raw.shape[0] != n:
            raise DataError(f"raw has shape {self.raw.shape}, expected ({n}, k)")
        if self.raw.shape[1] != len(self.channel_names):
            raise DataError(f"{self.raw.shape[1]} raw columns but "
                            f"{len(self.channel_names)} channel names")
        if self.buttons.shape != (n,):
            raise DataError(f"buttons has shape {self.buttons.shape}, expected ({n},)")
        if self.quat_xyzw is not None and self.quat_xyzw.shape != (n, 4):
            raise DataError(f"quat_xyzw has shape {self.quat_xyzw.shape}, expected ({n}, 4)")
        if n and (not np.all(np.isfinite(self.t_s)) or np.any(np.diff(self.t_s) <= 0)):
            raise DataError("t_s must be finite and strictly increasing")
        if not np.all(np.isfinite(self.raw)):
            raise DataError("raw channels must be finite numbers")

    def __len__(self) -> int:
        return len(self.t_s)

    @property
    def n_channels(self) -> int:
        """Raw channels per sample (k)."""
        return self.raw.shape[1]

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample."""
        return float(self.t_s[-1] - self.t_s[0]) if len(self) else 0.0

    @property
    def nominal_rate_hz(self) -> float:
        """``rate_hz`` from the file, else the median sample rate."""
        if self.rate_hz > 0:
            return self.rate_hz
        if len(self) < 2:
            return 0.0
        return float(1.0 / np.median(np.diff(self.t_s)))


def check_channels(rec: GloveRecording, need: int, path: str | Path,
                   glove_file: str | Path | None = None) -> None:
    """DataError naming ``path`` when the recording has no frames, or fewer raw channels
    than ``need`` (what the glove file ``glove_file`` reads: a take of another glove)."""
    if len(rec) == 0:
        raise DataError(f"{path}: a glove take without frames: nothing to play")
    if rec.n_channels < need:
        where = f" ({glove_file})" if glove_file is not None else ""
        raise DataError(
            f"{path}: {rec.n_channels} raw channels, but the glove file{where} reads"
            f" {need}: a take of another glove; play it with that glove's file"
            " (--glove-config FILE)")


def write_glove_recording(path: str | Path, rec: GloveRecording) -> None:
    """Write ``rec`` to ``path`` in the format of this module."""
    p = Path(path)
    header = ["t_s", *rec.channel_names]
    if rec.quat_xyzw is not None:
        header += QUAT_COLUMNS
    header.append("buttons")
    with p.open("w", newline="", encoding="utf-8") as f:
        f.write(MAGIC + "\n")
        rate = rec.nominal_rate_hz
        if rate > 0:
            f.write(f"# rate_hz: {rate:g}\n")
        for k, v in rec.meta.items():
            if k != "rate_hz":
                f.write(f"# {k}: {v}\n")
        w = csv.writer(f, lineterminator="\n")
        w.writerow(header)
        for i in range(len(rec)):
            row = [f"{rec.t_s[i]:.6f}", *(f"{v:.10g}" for v in rec.raw[i])]
            if rec.quat_xyzw is not None:
                q = rec.quat_xyzw[i]
                row += ["" if math.isnan(v) else f"{v:.6f}" for v in q]
            row.append(str(int(rec.buttons[i])))
            w.writerow(row)


MAX_META_LINES = 1000
"""``# key: value`` lines a recording may carry (a handful are written)."""


def read_glove_recording(path: str | Path) -> GloveRecording:
    """Read a glove recording one line at a time (a line over
    :data:`~handrig.config.bounded.MAX_LINE_BYTES` or bytes that are not text are refused
    where they are); any problem is a DataError naming the file and line."""
    p = Path(path)
    try:
        with p.open("rb") as f:
            return _read(p, bounded.lines(f, p, "a glove recording"))
    except FileNotFoundError:
        raise DataError(f"{p}: glove recording not found") from None
    except OSError as exc:
        raise DataError(f"{p}: cannot read glove recording: {exc.strerror}") from None


def _read(p: Path, lines: Iterator[tuple[int, str]]) -> GloveRecording:
    first = next(lines, (1, ""))[1]
    if first.strip() != MAGIC:
        hint = ""
        if first.startswith("t_s,"):
            hint = ("; it is a performance take (`handrig run --record`): play it onto the"
                    f" servos with `handrig play {p} --bus PORT` (or sim)")
        raise DataError(f"{p}:1: not a glove recording (the first line must be {MAGIC!r})"
                        f"{hint}; `handrig record glove TAKE.csv` or `handrig run"
                        " --record-glove TAKE.csv` make one")
    meta: dict[str, str] = {}
    lineno, line = 0, None
    for lineno, line in lines:
        if not line.startswith("#"):
            break
        if len(meta) >= MAX_META_LINES:
            raise DataError(f"{p}:{lineno}: more than {MAX_META_LINES} '# key: value' lines:"
                            " not a glove recording")
        key, sep, value = line[1:].partition(":")
        if sep:
            meta[key.strip()] = value.strip()
    else:
        line = None
    if line is None:
        raise DataError(f"{p}: no header line (t_s,...,buttons)")
    header = [h.strip() for h in next(csv.reader([line]))]
    if len(header) < 2 or header[0] != "t_s" or header[-1] != "buttons":
        raise DataError(f"{p}:{lineno}: header must start with t_s and end with buttons,"
                        f" got {excerpt(','.join(header))}")
    has_quat = tuple(header[-5:-1]) == QUAT_COLUMNS
    names = tuple(header[1:-5] if has_quat else header[1:-1])
    times: list[float] = []
    raws: list[list[float]] = []
    quats: list[list[float]] = []
    buttons_list: list[int] = []
    rows = ((n, row) for n, ln in lines if ln.strip() for row in csv.reader([ln]))
    row_at = next(rows, None)
    while row_at is not None:
        n, row = row_at
        try:
            row_at = next(rows, None)
            ends = row_at is None
        except DataError:
            row_at, ends = None, False
        where = f"{p}:{n}"
        if len(row) != len(header):
            cut = (" (the last line: the take is cut short; `handrig record repair` keeps"
                   " the frames before it)" if ends else "")
            raise DataError(f"{where}: {len(row)} columns, the header has {len(header)}{cut}")
        try:
            t = _number(row[0], "t_s")
            raws.append([_number(v, names[k]) for k, v in enumerate(row[1:1 + len(names)])])
            if has_quat:
                cells = row[-5:-1]
                if all(c.strip() for c in cells):
                    quats.append([_number(c, q) for c, q in zip(cells, QUAT_COLUMNS,
                                                                 strict=True)])
                elif any(c.strip() for c in cells):
                    raise ValueError("quaternion cells must be all filled or all empty")
                else:
                    quats.append([math.nan] * 4)
            try:
                buttons_list.append(int(row[-1]))
            except ValueError:
                raise ValueError(f"buttons {excerpt(row[-1])} is not an integer") from None
        except ValueError as exc:
            raise DataError(f"{where}: {exc}") from None
        if times and not t > times[-1]:
            raise DataError(f"{where}: t_s {t:g} does not come after {times[-1]:g}: the"
                            " times must increase")
        times.append(t)
    t_s = np.array(times, dtype=np.float64)
    raw = np.array(raws, dtype=np.float64).reshape(len(times), len(names))
    quat = np.array(quats, dtype=np.float64).reshape(len(times), 4) if has_quat else None
    buttons = np.array(buttons_list, dtype=np.int64)
    try:
        rate = float(meta.get("rate_hz", "0") or 0)
    except ValueError:
        raise DataError(f"{p}: rate_hz {excerpt(meta['rate_hz'])} is not a number") from None
    try:
        return GloveRecording(t_s, raw, buttons, names, quat, rate, meta)
    except DataError as exc:
        raise DataError(f"{p}: {exc}") from None


def sweep_recording(
    duration_s: float = 2.0,
    rate_hz: float = 100.0,
    n_channels: int = 5,
    *,
    low: float = 500.0,
    high: float = 3500.0,
    with_imu: bool = True,
) -> GloveRecording:
    """A synthetic recording for tests and benchmarks: each channel a slow sine
    between ``low`` and ``high`` counts (period 1 s + 0.25 s per channel index), the
    IMU tilting about the east axis by +-45 degrees over 2 s, no buttons."""
    n = max(1, round(duration_s * rate_hz))
    t = np.arange(n) / rate_hz
    periods = 1.0 + 0.25 * np.arange(n_channels)
    mid, amp = (low + high) / 2, (high - low) / 2
    raw = mid + amp * np.sin(2 * np.pi * t[:, None] / periods[None, :])
    quat = None
    if with_imu:
        half = np.radians(45.0) * np.sin(2 * np.pi * t / 2.0) / 2
        quat = np.stack([np.sin(half), np.zeros(n), np.zeros(n), np.cos(half)], axis=1)
    names = tuple(f"ch{i}" for i in range(n_channels))
    return GloveRecording(t, np.rint(raw), np.zeros(n, dtype=np.int64), names, quat, rate_hz,
                          {"source": "sweep_recording"})


def _number(text: str, column: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"column {excerpt(column, 24)}: {excerpt(text.strip(), 24)} is not"
                         " a number") from None
