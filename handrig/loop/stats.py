"""What a run measured, in fixed-size state: however long the show, memory stays flat.

:class:`LogHistogram` counts values in logarithmic buckets (each ``ratio`` wider
than the one below), so a percentile read from it is within ``ratio - 1`` of the
true value (relative) whatever the distribution; the exact minimum, maximum, mean
and standard deviation are kept beside the buckets. :class:`Ring` keeps the newest
``size`` items (recent events for a live display), :class:`SampleRing` the newest
``size`` numbers in one float array (recent latencies, whose percentiles a live
display reads 30 times a second). :class:`RunStats` holds the loop's histograms
and counters.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Generic, TypeVar, overload

import numpy as np

T = TypeVar("T")


class LogHistogram:
    """Counts of non-negative values in log-spaced buckets from ``low`` to ``high``.

    Bucket 0 holds everything at or below ``low`` (zero included), the last bucket
    everything above ``high``. ``add`` is O(1) and allocates nothing that lives on.
    """

    def __init__(self, low: float = 1e-7, high: float = 100.0, ratio: float = 1.02) -> None:
        if not 0.0 < low < high or ratio <= 1.0:
            raise ValueError(f"need 0 < low < high and ratio > 1, got {low}, {high}, {ratio}")
        self.low = float(low)
        self.ratio = float(ratio)
        self._inv_log_ratio = 1.0 / math.log(ratio)
        self._n_buckets = math.ceil(math.log(high / low) * self._inv_log_ratio) + 2
        self._counts = array("q", bytes(8 * self._n_buckets))
        self._log_low = math.log(self.low)
        self._last = self._n_buckets - 1
        self.count = 0
        self.min = math.inf
        self.max = -math.inf
        self._shift = 0.0
        self._sum = 0.0
        self._sum_sq = 0.0

    def add(self, x: float) -> None:
        """Count one value (a NaN is ignored)."""
        if x > self.low:
            i = int((math.log(x) - self._log_low) * self._inv_log_ratio) + 1
            if i > self._last:
                i = self._last
        elif x != x:
            return
        else:
            i = 0
        self._counts[i] += 1
        self.count += 1
        if x < self.min:
            self.min = x
        if x > self.max:
            self.max = x
        if self.count == 1:
            self._shift = x  # sums of deviations from the first value: no cancellation
        d = x - self._shift
        self._sum += d
        self._sum_sq += d * d

    @property
    def n_buckets(self) -> int:
        """How many buckets (fixed at construction)."""
        return self._n_buckets

    @property
    def mean(self) -> float:
        return self._shift + self._sum / self.count if self.count else math.nan

    @property
    def std(self) -> float:
        """Population standard deviation (``numpy.std``'s default); NaN below 2 values."""
        if self.count < 2:
            return math.nan
        m = self._sum / self.count
        return math.sqrt(max(0.0, self._sum_sq / self.count - m * m))

    def percentile(self, q: float) -> float:
        """The ``q``-th percentile (0..100): the geometric middle of the bucket holding it,
        kept within the exact minimum and maximum (so 0 and 100 are exact)."""
        if not self.count:
            return math.nan
        if q <= 0.0:
            return self.min
        if q >= 100.0:
            return self.max
        rank = q / 100.0 * self.count
        seen = 0
        bucket = 0
        for bucket, c in enumerate(self._counts):  # noqa: B007 - the bucket is the answer
            seen += c
            if seen >= rank and c:
                break
        value = self.low if bucket == 0 else self.low * self.ratio ** (bucket - 0.5)
        return min(max(value, self.min), self.max)


class Ring(Generic[T]):
    """The newest ``size`` items appended; indexing and slicing as on a list of them."""

    def __init__(self, size: int) -> None:
        self.size = int(size)
        self._items: list[T | None] = [None] * self.size
        self._n = 0  # items ever appended

    def append(self, item: T) -> None:
        self._items[self._n % self.size] = item
        self._n += 1

    @property
    def total(self) -> int:
        """How many items were ever appended (older ones are gone)."""
        return self._n

    def _list(self) -> list[T]:
        n = min(self._n, self.size)
        start = self._n - n
        return [self._items[(start + k) % self.size] for k in range(n)]  # type: ignore[misc]

    def __len__(self) -> int:
        return min(self._n, self.size)

    def __iter__(self) -> Iterator[T]:
        return iter(self._list())

    @overload
    def __getitem__(self, index: int) -> T: ...

    @overload
    def __getitem__(self, index: slice) -> list[T]: ...

    def __getitem__(self, index: int | slice) -> T | list[T]:
        n = min(self._n, self.size)
        if isinstance(index, int):  # one item, without building the list
            if not -n <= index < n:
                raise IndexError("ring index out of range")
            k = index + n if index < 0 else index
            return self._items[(self._n - n + k) % self.size]  # type: ignore[return-value]
        if index.step is None and index.stop is None and index.start is not None \
                and -n <= index.start < 0:  # the newest few (a display's last events)
            k = -index.start
            return [self._items[(self._n - k + i) % self.size]
                    for i in range(k)]
        return self._list()[index]


class SampleRing:
    """The newest ``size`` numbers appended, in one float64 array: appending costs a
    store, and the percentiles of the newest ``k`` read the array where it lies (no
    list is built: a percentile does not care about order)."""

    def __init__(self, size: int) -> None:
        self.size = int(size)
        self._values = np.zeros(self.size)
        self._n = 0  # values ever appended

    def append(self, value: float) -> None:
        self._values[self._n % self.size] = value
        self._n += 1

    @property
    def total(self) -> int:
        """How many values were ever appended (older ones are gone)."""
        return self._n

    def __len__(self) -> int:
        return min(self._n, self.size)

    def newest(self, k: int) -> np.ndarray:
        """The newest ``min(k, len(self))`` values, oldest first (a copy)."""
        k = min(int(k), len(self))
        end = self._n % self.size
        if k <= end:
            return self._values[end - k:end].copy()
        return np.concatenate((self._values[self.size - (k - end):], self._values[:end]))

    def percentiles(self, qs: tuple[float, ...], k: int | None = None) -> tuple[float, ...]:
        """The ``qs``-th percentiles (0..100, ``numpy.percentile``'s linear method) of the
        newest ``k`` values (default all kept); NaNs before any value."""
        n = len(self) if k is None else min(int(k), len(self))
        if not n:
            return (math.nan,) * len(qs)
        part = self.newest(n)
        ranks = [q / 100.0 * (n - 1) for q in qs]
        kth = sorted({min(int(r), n - 1) for r in ranks} | {min(int(r) + 1, n - 1) for r in ranks})
        part.partition(kth)
        out = []
        for r in ranks:
            lo = min(int(r), n - 1)
            hi = min(lo + 1, n - 1)
            a, b = float(part[lo]), float(part[hi])
            out.append(a + (b - a) * (r - lo))
        return tuple(out)


RECENT_LATENCIES = 2048  # what a live display shows: about 10 s at 200 Hz
KEPT_EVENTS = 200


@dataclass
class RunStats:
    """What a run measured. Times in seconds unless the name says otherwise.

    ``latency`` (end to end: a glove frame's arrival at the host, its last byte, to
    the Sync Write carrying it handed to the OS), ``compute`` (the part of it from the
    cycle's start to the same point) and ``period`` (between cycle starts) are
    histograms; ``latencies_s`` the newest latencies and ``events`` the newest
    events, both of fixed size (``events.total`` counts all). ``writes_delayed``:
    reads after which the next write had to wait (a frame arrived during the read,
    or the read ran past the next tick). ``cycles_without_frame``: writes with no new
    glove frame (floor-rate ticks, fixed ticks between frames). ``cpu_s``: CPU time
    of the loop's thread during the run.
    """

    frames: int = 0
    duration_s: float = 0.0
    glove_samples: int = 0
    latency: LogHistogram = field(default_factory=LogHistogram)
    compute: LogHistogram = field(default_factory=LogHistogram)
    period: LogHistogram = field(default_factory=LogHistogram)
    latencies_s: SampleRing = field(default_factory=lambda: SampleRing(RECENT_LATENCIES))
    overruns: int = 0
    overrun_max_s: float = 0.0
    missed_cycles: int = 0
    clamps: int = 0  # full-pose values clamped to joint limits (both hands)
    servo_clamps: int = 0  # servo targets clamped to joint or servo limits
    nonfinite: int = 0  # NaN/inf servo targets replaced by the last good target
    slewed: int = 0
    bus_clamps: int = 0
    reads: int = 0
    stale_reads: int = 0
    writes_delayed: int = 0
    read_splits: int = 0  # times reads were split in more parts to fit between frames
    frames_skipped: int = 0  # glove frames superseded while the loop was busy
    frames_in_bursts: int = 0  # glove frames superseded on arrival (sent back to back)
    frames_in_host_stalls: int = 0  # frames left waiting while the host read nothing
    frames_caught_up: int = 0  # frames written just before a newer one that came with them
    cycles_without_frame: int = 0
    ceiling_waits: int = 0
    cpu_s: float = 0.0
    loop_mode: str = ""  # "fixed" or "glove": what triggered the cycles
    tracking_sq_sum: float = 0.0
    tracking_n: int = 0
    tracking_max_deg: float = 0.0
    relax_events: int = 0  # times the glove was lost and the puppet eased to relaxed
    resumes: int = 0  # times the puppet eased back to the glove (after a loss or a relax key)
    relax_keys: int = 0  # times the relax key relaxed the puppet (no glove loss)
    servo_silences: int = 0  # servos past the [silence] warning
    servos_held: int = 0  # servos whose goal was held for silence
    heat_warnings: int = 0  # servos past [heat] warn_c
    heat_reliefs: int = 0  # effort caps put on servos past [heat] act_c
    heat_actions: int = 0  # servos past [heat] action_c
    max_temperature_c: tuple[float, ...] = ()  # the hottest reading per servo (NaN: never read)
    hottest: str = ""  # "servo 19 (riWristFlexion) 41 C": the run's hottest reading
    servo_recoveries: int = 0  # silent servos that answered again
    servo_recovery_reads_max: int = 0  # the longest silence that ended, in reads
    servos_admitted: int = 0  # servos left out at connect, admitted when they answered
    silence_counts: dict[str, object] = field(default_factory=dict)
    """What happened to whom (:meth:`handrig.loop.silence.SilenceWatch.counts`)."""
    estop: bool = False
    stop_reason: str = ""
    events: Ring[str] = field(default_factory=lambda: Ring(KEPT_EVENTS))

    @property
    def rate_hz(self) -> float:
        return self.frames / self.duration_s if self.duration_s > 0 else 0.0

    def latency_us(self, q: float) -> float:
        """The ``q``-th latency percentile in microseconds (NaN before any)."""
        return self.latency.percentile(q) * 1e6

    def compute_us(self, q: float) -> float:
        """The ``q``-th percentile of the compute part of the latency, microseconds."""
        return self.compute.percentile(q) * 1e6

    @property
    def cpu_per_cycle_us(self) -> float:
        """CPU time of the loop's thread per cycle (NaN before any)."""
        return self.cpu_s / self.frames * 1e6 if self.frames else math.nan

    @property
    def jitter_us(self) -> float:
        """Standard deviation of the cycle period."""
        return self.period.std * 1e6

    @property
    def tracking_rms_deg(self) -> float:
        return math.sqrt(self.tracking_sq_sum / self.tracking_n) if self.tracking_n else math.nan

    def add_overrun(self, late_s: float, skipped: int) -> None:
        self.overruns += 1
        self.overrun_max_s = max(self.overrun_max_s, late_s)
        self.missed_cycles += skipped
