"""The abstract servo bus the realtime loop drives, and what it returns.

Units: joint angles in degrees (vocabulary convention: flexion positive, radial
positive), joint velocities in degrees per second, currents in milliamperes,
temperatures in degrees Celsius, times in seconds on the bus's :class:`Clock`.
Arrays are in rig order (``RigConfig.servos``), one entry per servo.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass, field, fields
from enum import IntFlag
from typing import Literal

import numpy as np


class ServoFault(IntFlag):
    """What a servo says is wrong with it, as :attr:`ServoState.hardware_errors` carries
    it: one bit each. A driver whose servos number these otherwise maps its own bits
    onto these in the driver; the panel and the summary read only these."""

    INPUT_VOLTAGE = 1 << 0
    OVERHEATING = 1 << 2
    ENCODER = 1 << 3
    ELECTRICAL_SHOCK = 1 << 4
    OVERLOAD = 1 << 5


FAULT_LETTERS: tuple[tuple[ServoFault, str], ...] = (
    (ServoFault.INPUT_VOLTAGE, "V"), (ServoFault.OVERHEATING, "H"), (ServoFault.ENCODER, "E"),
    (ServoFault.ELECTRICAL_SHOCK, "S"), (ServoFault.OVERLOAD, "L"),
)
"""Each :class:`ServoFault` as the one letter the panel shows (its legend names them)."""


def fault_letters(bits: int) -> str:
    """:class:`ServoFault` bits as letters (:data:`FAULT_LETTERS`), "" for none."""
    return "".join(letter for fault, letter in FAULT_LETTERS if bits & fault)


@dataclass
class ServoState:
    """One read of the servos' present state, in rig order.

    ``stale[i]`` is True when servo ``i`` did not give a valid reading in this
    read: its entries then hold the last good reading (NaN if there never was
    one) and ``age_s[i]`` says how old that is. Nothing stale is passed off as
    fresh.
    """

    positions_deg: np.ndarray  # (n,) float64, joint angle
    velocities_dps: np.ndarray  # (n,) float64, joint velocity
    currents_ma: np.ndarray  # (n,) float64, motor current (signed)
    temperatures_c: np.ndarray  # (n,) float64, last temperature read (NaN if never)
    status_errors: np.ndarray  # (n,) uint8, ERR byte of the servo's last status
    hardware_errors: np.ndarray  # (n,) uint8, ServoFault bits read in this read (0 = none)
    stale: np.ndarray  # (n,) bool
    age_s: np.ndarray  # (n,) float64, time since that servo's reading was taken (inf: never)
    timestamp_s: float  # clock time of this read
    stats: BusStats  # the bus's counters at the time of this read (a copy)
    asked: np.ndarray | None = None
    """(n,) bool: the servos this read asked for (a read of one part of the servos,
    ``read_state(part=...)``); the others keep their last reading, ``age_s`` says how
    old, and are not stale for it. None: every servo was asked."""
    sent: bool = True
    """Whether the read went on the wire. False: the bus declined it (its request and
    replies could not both be on the wire by the deadline, or the caller came after
    the deadline); every servo is then stale with its last reading."""
    stopped: np.ndarray | None = None
    """(n,) bool: the servos where a reply stopped while servos before them answered, not
    heard since (a Fast Sync Read's chain ends at a silent servo, and the servos after it
    go unanswered with it): their own silence, where the others' is not. None: the bus
    cannot tell (it has no chain, it fell back to Sync Read, or a whole read every servo
    answered took the short way)."""

    @property
    def all_fresh(self) -> bool:
        return not bool(self.stale.any())

    @property
    def answered(self) -> np.ndarray:
        """(n,) bool: the servos that gave a valid reading in this read."""
        fresh = ~np.asarray(self.stale, dtype=bool)
        return fresh if self.asked is None else fresh & self.asked


_ARRAY_COUNTERS = ("stale_readings", "hardware_errors", "reboots")


@dataclass
class BusStats:
    """Counters of a bus since it was connected (``per-servo`` arrays in rig order)."""

    n_servos: int
    writes: int = 0  # goal Sync Writes sent
    reads: int = 0  # present-state reads attempted
    retries: int = 0  # extra read attempts within a cycle
    timeouts: int = 0  # replies (or parts of replies) missing at the deadline
    host_timeouts: int = 0  # of those, the host's: woke HOST_STALL_S late, tasks waited as
    # long, or the reply came in whole later (held on its way: the host, an emulator, an adapter)
    crc_errors: int = 0  # replies or per-servo blocks failing their CRC
    malformed: int = 0  # replies with a wrong id, length or header
    status_errors: int = 0  # readings refused with an error number (range, access, ...)
    clamps: int = 0  # goal values clamped into a servo's limits (incl. NaN replaced)
    fallbacks: int = 0  # switches from Fast Sync Read to plain Sync Read
    watchdog_trips: int = 0  # servos found with a tripped Bus Watchdog (then re-armed)
    late_replies: int = 0  # intact replies to an earlier read, recognised and dropped
    watchdog_gaps: int = 0  # goal writes after a silence near the Bus Watchdog (re-armed)
    skipped_reads: int = 0  # reads not sent: the wire could not carry them by their deadline
    late_reads: int = 0  # reads not sent: the caller came after the read's deadline
    partial_replies: int = 0  # Fast Sync Read replies cut short (the servos before the cut taken)
    chain_ends: int = 0  # reads that asked servos which stopped answering last in the chain
    admissions: int = 0  # servos left out at connect, commissioned when they answered
    stale_readings: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    hardware_errors: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    reboots: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    def __post_init__(self) -> None:
        for name in ("stale_readings", "hardware_errors", "reboots"):
            if len(getattr(self, name)) != self.n_servos:
                setattr(self, name, np.zeros(self.n_servos, np.int64))

    @classmethod
    def total(cls, ledgers: Sequence[BusStats]) -> BusStats:
        """The bus's counters: the sum of its parts' own ledgers (each part counts what it
        did in a ledger of its own; nobody writes another's). A few microseconds: it
        runs once per read."""
        new = ledgers[0].copy()
        d = new.__dict__
        for other in ledgers[1:]:
            od = other.__dict__
            for name in _INT_COUNTERS:
                v = od[name]
                if v:
                    d[name] += v
            for name in _ARRAY_COUNTERS:
                a = od[name]
                if len(a):  # only the parts that count per servo have these
                    d[name] = d[name] + a
        return new

    def copy(self) -> BusStats:
        new = object.__new__(BusStats)  # every read takes one: no __init__ round trip
        new.__dict__.update(self.__dict__)
        new.stale_readings = self.stale_readings.copy()
        new.hardware_errors = self.hardware_errors.copy()
        new.reboots = self.reboots.copy()
        return new

    def summary(self) -> str:
        """One line for logs."""
        return (
            f"writes {self.writes}, reads {self.reads}, retries {self.retries}, "
            f"timeouts {self.timeouts} (the host's {self.host_timeouts}), crc errors "
            f"{self.crc_errors}, malformed "
            f"{self.malformed}, status errors {self.status_errors}, clamps {self.clamps}, "
            f"fallbacks {self.fallbacks}, watchdog trips {self.watchdog_trips}, late replies "
            f"{self.late_replies}, watchdog gaps {self.watchdog_gaps}, skipped reads "
            f"{self.skipped_reads}, late reads {self.late_reads}, partial replies "
            f"{self.partial_replies}, chain ends {self.chain_ends}, admissions "
            f"{self.admissions}, stale readings "
            f"{int(self.stale_readings.sum())}, hardware errors "
            f"{int(self.hardware_errors.sum())}, reboots {int(self.reboots.sum())}"
        )


_INT_COUNTERS = tuple(f.name for f in fields(BusStats)
                      if f.name != "n_servos" and f.name not in _ARRAY_COUNTERS)


@dataclass(frozen=True)
class FaultPolicy:
    """What the bus does about faults. Times in seconds.

    - ``read_retries``: extra attempts of a failed read, only while the read's
      deadline (``read_budget_s`` after the call, or the caller's) allows.
    - ``max_stale_reads``: this many reads in a row that the wire could not carry
      by their deadline (a configuration that does not fit) raise DeviceTimeoutError.
    - ``on_hardware_error``: ``"reboot"`` the servo (at most ``max_reboots`` times
      per servo, then stop) or ``"stop"`` at once (ServoFault naming servo and bit).
    - ``fast_failures_before_fallback``: whole Fast Sync Reads failing in a row
      before switching to plain Sync Read for good (ROBOTIS' ROS 2 driver uses 10).
    """

    read_retries: int = 1
    read_budget_s: float = 0.004
    max_stale_reads: int = 50
    on_hardware_error: Literal["reboot", "stop"] = "reboot"
    max_reboots: int = 3
    reboot_wait_s: float = 1.0
    fast_failures_before_fallback: int = 10

    def __post_init__(self) -> None:
        if self.read_retries < 0 or self.max_stale_reads < 1 or self.max_reboots < 0:
            raise ValueError(f"invalid fault policy {self}")
        if self.read_budget_s <= 0 or self.reboot_wait_s <= 0:
            raise ValueError(f"fault policy times must be positive: {self}")


class ServoBus(ABC):
    """A bus of position servos, one per joint, in rig order: everything the loop uses.

    The realtime loop calls ``write_goals_deg`` every cycle and ``read_state`` every
    few; torque is on only inside ``with bus.torque():``. The abstract methods are
    what every bus must do; the rest are hooks with defaults that a bus fills in when
    it can say more (its wire timing, housekeeping reads between state reads, events
    for the log). The loop decides what to do about silent servos
    (:mod:`handrig.loop.silence`) from what :meth:`read_state` reports.
    """

    port: str = ""
    """Where the bus is (a serial path), for a person."""
    baud: int = 0
    """The wire's baud rate (0: not a serial wire; the loop then assumes no wire time)."""
    emulated: bool = False
    """The servos are an emulator's (the factory knows: it started it); what the loop
    says about servos that all go quiet at once then points at the emulator."""

    @property
    @abstractmethod
    def joint_names(self) -> tuple[str, ...]:
        """The joint each servo drives, in rig order."""

    @property
    @abstractmethod
    def stats(self) -> BusStats:
        """Live counters (the object is updated in place)."""

    @abstractmethod
    def connect(self) -> None:
        """Open the port and commission every servo; DeviceError says what is wrong."""

    @abstractmethod
    def close(self) -> None:
        """Torque off if still on, close the port. Safe to call twice."""

    @abstractmethod
    def torque(self, *, handle_signals: bool = True) -> AbstractContextManager[ServoBus]:
        """Context manager: torque on inside, off on every way out. ``handle_signals``:
        the bus may catch the exit signals itself while torque is on (a session that
        handles them, :class:`handrig.app.session_exit.ExitSignals`, passes False)."""

    @abstractmethod
    def write_goals_deg(self, goals_deg: np.ndarray) -> int:
        """Send one goal per servo (degrees, rig order); return how many were clamped
        into the servos' limits (a bus never sends a goal outside them)."""

    @abstractmethod
    def read_state(self, deadline_s: float | None = None,
                   part: tuple[int, int] | None = None, *, patient: bool = False
                   ) -> ServoState:
        """Read present state by ``deadline_s`` (clock time; None: the bus's own
        budget). ``part=(i, m)``: ask only the servos at rig indices ``i, i + m, ...``
        (``ServoState.asked``). Servos without a valid reply are marked stale with
        their age; a read the bus declined says so (``ServoState.sent``).
        ``patient``: a caller that waits for the answer (not the realtime loop), so the
        bus may retry up to ``deadline_s`` rather than keep to the loop's budget."""

    # -- hooks: what a bus may say beyond the contract (defaults: nothing to say) ----------
    @property
    def ids(self) -> tuple[int, ...]:
        """Each servo's bus id, in rig order (default: 1..n)."""
        return tuple(range(1, self.n_servos + 1))

    @property
    def last_goals_deg(self) -> np.ndarray:
        """The goals last sent, after clamping (NaN before the first write or if the bus
        does not know): where the loop starts from."""
        return np.full(self.n_servos, np.nan)

    @property
    def left_out(self) -> tuple[int, ...]:
        """Rig indices of servos that did not answer at connect and that the bus left
        out (``[silence] action = "continue"``): never sent a goal or torque until
        admitted (:meth:`admit`), already named once; the loop's silence tiers skip
        them (default: none)."""
        return ()

    def admit(self, index: int) -> tuple[float | None, str]:
        """Bring servo ``index``, left out at connect and answering now, into the run:
        commissioned as at connect, given torque where it is (clamped into its limits)
        and from then on sent goals. Returns (the goal it is held at, joint degrees,
        or None when it stays left out; one line saying what was done or why not).
        The loop eases it from there to its goals (default: nobody is left out)."""
        return None, f"servo index {index}: this bus leaves no servo out"

    @property
    def last_write_s(self) -> float:
        """When the last write was handed to the OS, clock time (NaN: unknown); where the
        loop's latency figure ends (default: when the loop's write call returned)."""
        return float("nan")

    def rehearse_write(self, goals_deg: np.ndarray) -> None:  # noqa: B027 - optional hook
        """Build the goal write for ``goals_deg`` into scratch, sending nothing: its code
        and tables are then in the CPU's caches for the next :meth:`write_goals_deg` (the
        loop's warm-up before an expected glove frame). Changes nothing a caller can see:
        no write, no counter, no goal remembered; default: nothing to rehearse."""

    def read_wire_s(self, n: int) -> float:
        """Wire time of a present-state read of ``n`` servos, request and replies
        (0: no wire to wait for)."""
        return 0.0

    def write_wire_s(self) -> float:
        """Wire time of one goal write to every servo (0: no wire to wait for)."""
        return 0.0

    def quiet_wait_s(self) -> float:
        """How long a read asked now would wait, beyond the wire, for the line to go
        quiet (after a failed reply); the loop counts it when fitting reads into gaps."""
        return 0.0

    def housekeeping(self, deadline_s: float) -> bool:
        """Between state reads, where the wire has room by ``deadline_s``: the bus's own
        upkeep (watchdogs, temperatures). True if it ran (default: nothing to do)."""
        return False

    def drain_events(self) -> list[str]:
        """What the bus did since the last call, one line each for the run's log."""
        return []

    def limit_effort(self, index: int, fraction: float) -> bool:
        """Cap the effort of the servo at rig index ``index`` at ``fraction`` (0..1] of
        its full effort (1.0 lifts the cap): the loop's relief for a hot servo. True if
        the cap is in place; False if this bus cannot cap a servo (the default) or the
        servo did not take it (the bus says why in its events)."""
        return False

    @property
    def torque_enabled(self) -> bool:
        """Whether torque is on now, as the bus knows it (a fault may have turned it
        off). Default: a bus that cannot tell says False."""
        return False

    @property
    def connect_notes(self) -> tuple[str, ...]:
        """What :meth:`connect` found and did, one line each (settings checked or
        changed, servos left out), for the run's header (default: nothing to say)."""
        return ()

    def confirm_torque_off(self, budget_s: float) -> tuple[bool | None, list[str]]:
        """After the run, torque read back from every servo that was given it, within
        ``budget_s``: (True if every one is off, False if one is still on, None if one
        could not be read; the servos not confirmed off, each named with why). A servo
        left out at connect is asked too, its silence no failure. Default: this bus
        cannot read torque back, so nothing is confirmed."""
        left_out = set(self.left_out)
        return None, [f"{self.describe(i)}: not read back (this bus cannot read torque)"
                      for i in range(self.n_servos) if i not in left_out]

    def describe(self, index: int) -> str:
        """``"servo 7 (riRingPIPy)"`` for the servo at rig index ``index``."""
        return f"servo {self.ids[index]} ({self.joint_names[index]})"

    def where(self) -> str:
        """Where the bus is, for a message (``"on /dev/ttyUSB0"``)."""
        return f"on {self.port}" if self.port else ""

    @property
    def n_servos(self) -> int:
        return len(self.joint_names)

    def __enter__(self) -> ServoBus:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
