"""Switchable faults of the emulated bus (:class:`FaultSpec`) and how a reply suffers them.

Dropped, CRC-corrupted, wrong-ID, truncated and delayed replies with given
probabilities (explicit seed), missing servos, a servo muted for a while (it hears
and obeys but does not answer), and an overload hardware error on chosen servos;
the bus counts every fault in ``SimBus.fault_counts``.
"""

from __future__ import annotations

import random
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from handrig.errors import ConfigError


@dataclass(frozen=True)
class FaultSpec:
    """Switchable faults. Probabilities are per reply; ``seed`` makes them repeatable.

    ``missing``: servo IDs that never answer (as if unplugged). ``overload``: servo
    IDs that report an overload hardware error ``overload_after_s`` after the bus
    starts (torque off, Alert bit set, only a reboot clears it). ``mute``: servo IDs
    that send no status from ``mute_from_s`` to ``mute_until_s`` after the bus starts
    (they still hear and obey every instruction, as with a broken reply line or a
    Status Return Level of 0; a Fast Sync Read's reply stops short at them). ``delay_s``
    is the extra latency of a delayed reply. ``hot``: servo IDs that start at
    ``hot_c`` (a servo warm from an earlier run; it cools or warms from there).
    """

    drop: float = 0.0
    corrupt: float = 0.0
    wrong_id: float = 0.0
    truncate: float = 0.0
    delay: float = 0.0
    delay_s: float = 0.005
    missing: frozenset[int] = field(default_factory=frozenset)
    overload: frozenset[int] = field(default_factory=frozenset)
    overload_after_s: float = 0.0
    mute: frozenset[int] = field(default_factory=frozenset)
    mute_from_s: float = 0.0
    mute_until_s: float = float("inf")
    hot: frozenset[int] = field(default_factory=frozenset)
    hot_c: float = 60.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("drop", "corrupt", "wrong_id", "truncate", "delay"):
            p = getattr(self, name)
            if not 0.0 <= p <= 1.0:
                raise ConfigError("fault probability out of range", key=name, value=p,
                                  allowed="0..1")
        if self.delay_s < 0 or self.overload_after_s < 0:
            raise ConfigError("times must be >= 0", key="delay_s/overload_after_s",
                              value=(self.delay_s, self.overload_after_s))
        if not 0.0 <= self.hot_c <= 120.0:
            raise ConfigError("start temperature out of range", key="hot", value=self.hot_c,
                              allowed="hot=ID+ID[@C], 0..120 C")
        if not 0.0 <= self.mute_from_s < self.mute_until_s:
            raise ConfigError("mute window must start at >= 0 s and end after it starts",
                              key="mute", value=(self.mute_from_s, self.mute_until_s),
                              allowed="mute=ID+ID[@FROM[-UNTIL]], seconds after the bus starts")

    @property
    def any_reply_fault(self) -> bool:
        return any((self.drop, self.corrupt, self.wrong_id, self.truncate, self.delay))

    @classmethod
    def parse(cls, spec: str) -> FaultSpec:
        """Parse ``"drop=0.02,corrupt=0.01,wrong_id=0.01,truncate=0.01,delay=0.01:0.005,
        missing=7+9,overload=3@1.5,mute=7@120-240,seed=42"`` (any subset, comma separated).

        ``delay=P[:SECONDS]``; ``missing``, ``overload`` and ``mute`` take IDs joined by
        ``+``; ``overload=IDS[@SECONDS]``; ``mute=IDS[@FROM[-UNTIL]]`` (seconds);
        ``hot=IDS[@C]``.
        """
        allowed = "drop, corrupt, wrong_id, truncate, delay=P[:S], missing=ID+ID, " \
                  "overload=ID+ID[@S], mute=ID+ID[@FROM[-UNTIL]], hot=ID+ID[@C], seed=N"
        kw: dict[str, object] = {}
        for part in filter(None, (p.strip() for p in spec.split(","))):
            key, eq, value = part.partition("=")
            key = key.strip().replace("-", "_")
            if not eq:
                raise ConfigError("expected key=value", file="--faults", key=part, allowed=allowed)
            try:
                if key in ("drop", "corrupt", "wrong_id", "truncate"):
                    kw[key] = float(value)
                elif key == "delay":
                    p, _, s = value.partition(":")
                    kw["delay"] = float(p)
                    if s:
                        kw["delay_s"] = float(s.removesuffix("s"))
                elif key == "missing":
                    kw["missing"] = frozenset(int(v) for v in value.split("+") if v)
                elif key == "overload":
                    ids, _, after = value.partition("@")
                    kw["overload"] = frozenset(int(v) for v in ids.split("+") if v)
                    if after:
                        kw["overload_after_s"] = float(after.removesuffix("s"))
                elif key == "mute":
                    ids, _, window = value.partition("@")
                    kw["mute"] = frozenset(int(v) for v in ids.split("+") if v)
                    start, dash, until = window.partition("-")
                    if start:
                        kw["mute_from_s"] = float(start.removesuffix("s"))
                    if dash:
                        kw["mute_until_s"] = float(until.removesuffix("s"))
                elif key == "hot":
                    ids, _, temp = value.partition("@")
                    kw["hot"] = frozenset(int(v) for v in ids.split("+") if v)
                    if temp:
                        kw["hot_c"] = float(temp.removesuffix("C"))
                elif key == "seed":
                    kw["seed"] = int(value)
                else:
                    raise ConfigError("unknown fault", file="--faults", key=key, allowed=allowed)
            except ValueError as exc:
                raise ConfigError(f"bad number ({exc})", file="--faults", key=key, value=value,
                                  allowed=allowed) from None
        try:
            return cls(**kw)  # type: ignore[arg-type]
        except ConfigError as exc:
            raise exc.located("--faults") from None



def apply_faults(
    spec: FaultSpec, rng: random.Random, counts: Counter[str], packet: bytes, servo_id: int,
    rebuild: Callable[[int], bytes],
) -> tuple[bytes, float]:
    """Drop, misaddress (``rebuild(other_id)``), corrupt, truncate or delay a reply:
    the packet as sent (empty when dropped) and the extra delay, s."""
    f = spec
    if f.drop and rng.random() < f.drop:
        counts["dropped"] += 1
        return b"", 0.0
    if f.wrong_id and rng.random() < f.wrong_id:
        counts["wrong_id"] += 1
        other = rng.choice([i for i in range(253) if i != servo_id])
        packet = rebuild(other)
    if f.corrupt and rng.random() < f.corrupt:
        counts["corrupted"] += 1
        packet = packet[:-1] + bytes((packet[-1] ^ 0x5A,))
    if f.truncate and rng.random() < f.truncate:
        counts["truncated"] += 1
        packet = packet[: rng.randrange(1, len(packet))]
    extra = 0.0
    if f.delay and rng.random() < f.delay:
        counts["delayed"] += 1
        extra = f.delay_s
    return packet, extra
