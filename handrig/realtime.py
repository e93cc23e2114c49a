"""Realtime scheduling for the loop thread, best effort.

With ``SCHED_FIFO`` the loop is not preempted by ordinary processes (an emulator,
a compiler, a browser on the show laptop); ``docs/measurements.md`` has what that
did to the loop's latency on a loaded machine. It needs root or
``CAP_SYS_NICE`` (or an rtprio limit); without it the loop runs at normal
priority and says so. Only the calling thread is raised, and only inside the
``with`` block; threads started before keep their priority.

CPU split: with two or more CPUs the loop thread keeps the last one to itself
(:func:`pinned_loop`) and the processes handrig starts beside it (the simulated
servo bus and its MuJoCo puppet, the glove emulator) are told to stay off it
through ``HANDRIG_CPUS`` (:func:`apply_cpus_from_env`, called first by the CLI).
Real servos and a real glove cost the host nothing; their emulators must not steal
the loop's CPU either: a pty write wakes the emulator's reader, and woken onto the
loop's CPU it runs inside the loop's ``os.write`` (figures in
``docs/measurements.md``).
"""

from __future__ import annotations

import contextlib
import functools
import os
import struct
from collections.abc import Callable, Iterator

CPUS_ENV = "HANDRIG_CPUS"


def cpu_split() -> tuple[int | None, frozenset[int]]:
    """(the loop's CPU, the CPUs for everything else); (None, all) with one CPU."""
    if not hasattr(os, "sched_getaffinity"):
        return None, frozenset()
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < 2:
        return None, frozenset(cpus)
    return cpus[-1], frozenset(cpus[:-1])


def helper_env(env: dict[str, str] | None = None) -> dict[str, str]:
    """``env`` (default: this process's) plus ``HANDRIG_CPUS`` naming the CPUs a
    helper process (an emulator) may use: all but the loop's."""
    out = dict(os.environ if env is None else env)
    loop_cpu, others = cpu_split()
    if loop_cpu is not None:
        out[CPUS_ENV] = ",".join(str(c) for c in sorted(others))
    return out


def apply_cpus_from_env() -> None:
    """Keep this process on the CPUs ``HANDRIG_CPUS`` lists (set by :func:`helper_env`);
    ignored when unset, malformed or not possible here."""
    spec = os.environ.get(CPUS_ENV, "").strip()
    if not spec or not hasattr(os, "sched_setaffinity"):
        return
    try:
        cpus = {int(c) for c in spec.split(",") if c.strip()}
        os.sched_setaffinity(0, cpus & os.sched_getaffinity(0) or os.sched_getaffinity(0))
    except (ValueError, OSError):
        pass


_PR_SET_TIMERSLACK = 29
_PR_GET_TIMERSLACK = 30
LOOP_TIMER_SLACK_NS = 1000


def timer_slack_ns(new_ns: int | None = None) -> int | None:
    """The calling thread's timer slack (Linux prctl), set to ``new_ns`` if given;
    returns the value before, or None where there is no such thing.

    Linux lets a normal thread's timed sleeps (``select`` with a timeout, ``sleep``)
    end up to 50 us late by default, to batch wake-ups; SCHED_FIFO threads get none.
    """
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        before = int(libc.prctl(_PR_GET_TIMERSLACK, 0, 0, 0, 0))
        if before < 0:
            return None
        if new_ns is not None:
            libc.prctl(_PR_SET_TIMERSLACK, int(new_ns), 0, 0, 0)
        return before
    except (OSError, AttributeError):
        return None


# sched_setattr / sched_getattr by machine (Linux): a normal thread's slice is set there
_SCHED_ATTR_SYSCALLS = {"x86_64": (314, 315), "aarch64": (274, 275)}
_FAIR_POLICIES = (0, 3, 5)  # SCHED_OTHER, SCHED_BATCH, SCHED_IDLE
_SCHED_FLAG_RESET_ON_FORK = 1
SHORT_SLICE_NS = 100_000
"""The slice a normal (not SCHED_FIFO) timing thread asks for: the shortest Linux grants
(0.1 ms; the default is 0.7-3 ms). Since Linux 6.12 the fair scheduler (EEVDF) gives a
woken thread with a short slice an early deadline, so it runs at once rather than after
a busy thread's slice on its CPU: without root, a loop or an emulator beside a process
that keeps a core busy woke up to 3.7 ms late, with the short slice 0.37 ms at most
(``docs/measurements.md``). Older kernels take the request and ignore it."""


@functools.cache
def _sched_attr() -> type:
    import ctypes

    class SchedAttr(ctypes.Structure):  # struct sched_attr, version 1 (56 bytes)
        _fields_ = [("size", ctypes.c_uint32), ("sched_policy", ctypes.c_uint32),
                    ("sched_flags", ctypes.c_uint64), ("sched_nice", ctypes.c_int32),
                    ("sched_priority", ctypes.c_uint32), ("sched_runtime", ctypes.c_uint64),
                    ("sched_deadline", ctypes.c_uint64), ("sched_period", ctypes.c_uint64),
                    ("sched_util_min", ctypes.c_uint32), ("sched_util_max", ctypes.c_uint32)]
    return SchedAttr


def fair_slice_ns(new_ns: int | None = None) -> int | None:
    """The calling thread's slice under the fair scheduler (``sched_runtime`` of
    ``sched_getattr``, ns), set to ``new_ns`` if given (its nice and policy kept);
    returns the value before, or None where there is no such thing (not Linux, an
    unknown machine, refused, or a thread that is not under the fair scheduler: its
    settings are left alone). Threads it starts afterwards inherit the slice."""
    import platform

    calls = _SCHED_ATTR_SYSCALLS.get(platform.machine())
    if calls is None:
        return None
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        attr = _sched_attr()()
        if libc.syscall(calls[1], 0, ctypes.byref(attr), ctypes.sizeof(attr), 0) != 0:
            return None
        before = int(attr.sched_runtime)
        if attr.sched_policy not in _FAIR_POLICIES:  # SCHED_FIFO, RR, DEADLINE: not ours
            return None
        if new_ns is not None and new_ns != before:
            attr.size = ctypes.sizeof(attr)
            attr.sched_flags &= _SCHED_FLAG_RESET_ON_FORK  # kept; no clamp or keep flags
            attr.sched_runtime = int(new_ns)
            if libc.syscall(calls[0], 0, ctypes.byref(attr), 0) != 0:
                return None
        return before
    except (OSError, AttributeError):
        return None


PSI_CPU = "/proc/pressure/cpu"


class CpuPressure:
    """The host's CPU pressure (Linux PSI): :meth:`total_us` is how long, in all, some
    task has waited for a CPU (the ``some`` line's ``total``, microseconds). Read with
    one ``pread`` on a kept descriptor (about 1 us). Where there is no PSI (not Linux,
    ``psi=0``) every reading is None."""

    def __init__(self, path: str = PSI_CPU) -> None:
        try:
            self._fd: int | None = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
        except OSError:
            self._fd = None

    def total_us(self) -> int | None:
        if self._fd is None:
            return None
        try:
            text = os.pread(self._fd, 256, 0)
            at = text.index(b"total=") + 6
            return int(text[at:text.index(b"\n", at)])
        except (OSError, ValueError):
            return None

    def close(self) -> None:
        if self._fd is not None:
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = None


@functools.cache
def host_cpu_pressure() -> CpuPressure:
    """This process's one :class:`CpuPressure` (a descriptor kept open for the process's
    life; ``pread`` on it is safe from any thread)."""
    return CpuPressure()


@contextlib.contextmanager
def short_slice() -> Iterator[bool]:
    """Run the block with the calling thread's fair-scheduler slice at
    :data:`SHORT_SLICE_NS` (restored after); yields whether the kernel took it."""
    before = fair_slice_ns(SHORT_SLICE_NS)
    try:
        yield before is not None and fair_slice_ns() == SHORT_SLICE_NS
    finally:
        if before is not None:
            fair_slice_ns(before)


@contextlib.contextmanager
def pinned_loop(
    enabled: bool = True, log: Callable[[str], None] | None = None
) -> Iterator[int | None]:
    """Run the block with the calling thread on the loop's CPU (:func:`cpu_split`);
    yields that CPU, or None when there is one CPU or pinning is off or refused.

    The thread's timer slack is cut to 1 us in the block either way: the servo
    driver polls for a reply from shortly before its wire instant (DynamixelBus
    ``spin_s``), and a wake-up 50 us late defeats that (``handrig bench bus`` shows
    the difference; figures in ``docs/measurements.md``)."""
    slack_before = timer_slack_ns(LOOP_TIMER_SLACK_NS)
    try:
        with _pinned(enabled, log) as cpu:
            yield cpu
    finally:
        if slack_before is not None:
            timer_slack_ns(slack_before)


@contextlib.contextmanager
def _pinned(enabled: bool, log: Callable[[str], None] | None) -> Iterator[int | None]:
    loop_cpu, _ = cpu_split()
    if not enabled or loop_cpu is None:
        yield None
        return
    before = os.sched_getaffinity(0)
    try:
        os.sched_setaffinity(0, {loop_cpu})
    except OSError as exc:
        if log is not None:
            log(f"cannot pin the loop to CPU {loop_cpu} ({exc.strerror or exc})")
        yield None
        return
    try:
        yield loop_cpu
    finally:
        with contextlib.suppress(OSError):
            os.sched_setaffinity(0, before)


@contextlib.contextmanager
def realtime_priority(
    priority: int = 20, log: Callable[[str], None] | None = None, *,
    short_slice_instead: bool = False,
) -> Iterator[bool]:
    """Run the block at SCHED_FIFO ``priority`` (1..99); yields whether it worked.
    ``short_slice_instead`` (the loops): where it is refused (no root, no
    CAP_SYS_NICE, no rtprio limit) the block runs with a short fair-scheduler slice
    (:func:`short_slice`) and the log line says so."""
    if not hasattr(os, "sched_setscheduler") or priority <= 0:
        yield False
        return
    try:
        old_policy = os.sched_getscheduler(0)
        old_param = os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (PermissionError, OSError) as exc:
        with short_slice() if short_slice_instead else contextlib.nullcontext(False) as short:
            if log is not None:
                log(f"realtime priority unavailable ({exc.strerror or exc}): the loop runs "
                    "at normal priority" + (f" with a {SHORT_SLICE_NS / 1e6:g} ms slice (woken, "
                                            "it runs ahead of busy threads)" if short else ""))
            yield False
        return
    try:
        yield True
    finally:
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, old_policy, old_param)


CPU_LATENCY_DEVICE = "/dev/cpu_dma_latency"
CPU_LATENCY_ENV = "HANDRIG_CPU_LATENCY_DEVICE"  # another device path; empty: never (tests)
_AWAKE = struct.pack("i", 0)  # no wake-up latency allowed: idle CPUs poll
_ASLEEP = struct.pack("i", 2_000_000_000)  # the kernel's default: idle CPUs may halt
_REFUSED: set[str] = set()  # devices this process was refused (said once)


class CpuWake:
    """A request that idle CPUs poll instead of halting, held only around each frame
    (:meth:`hold`, :meth:`release`); a no-op without the device (``fd`` None).

    A halted CPU (a virtual machine's idle vCPU goes back to the host; a laptop's core
    goes to a deep sleep state) takes tens to hundreds of microseconds to wake: the pty
    or USB write of the frame and of its Sync Write each wake one, and that time is
    felt. Linux's CPU latency request (PM QoS, :data:`CPU_LATENCY_DEVICE`) of 0 makes
    every idle CPU poll instead, and the kernel wakes the halted ones when it is made;
    held from the warm-up before each expected frame until its Sync Write is out
    (``[loop] keep_cpus_awake``), the CPUs poll for that share of the time only. The
    polling is the kernel's idle loop, not this process's CPU, and gives way to any
    work at once; it costs power (``python -m bench felt`` prints the share of time the
    CPUs spent polling). Writes that fail turn the request off (:attr:`error`)."""

    def __init__(self, fd: int | None = None) -> None:
        self.fd = fd
        self.held = False
        self.holds = 0  # times the request was made
        self.error = ""

    def hold(self) -> None:
        if self.fd is None or self.held:
            return
        self._write(_AWAKE)
        self.held = self.fd is not None
        self.holds += 1

    def release(self) -> None:
        if self.held:
            self.held = False
            self._write(_ASLEEP)

    def _write(self, value: bytes) -> None:
        try:
            os.write(self.fd, value)  # type: ignore[arg-type]
        except OSError as exc:
            self.error = exc.strerror or str(exc)
            self.close()

    def close(self) -> None:
        fd, self.fd, self.held = self.fd, None, False
        if fd is not None:
            with contextlib.suppress(OSError):
                os.close(fd)  # closing drops the request


@contextlib.contextmanager
def cpus_awake_around_frames(
    enabled: bool = True, log: Callable[[str], None] | None = None,
    device: str | None = None,
) -> Iterator[CpuWake]:
    """A :class:`CpuWake` on ``device`` (default: ``HANDRIG_CPU_LATENCY_DEVICE`` if set,
    else :data:`CPU_LATENCY_DEVICE`) for the block (closed after it); one that does
    nothing when off or the path is empty, or when the device is missing or not
    writable (said in ``log``)."""
    if device is None:
        device = os.environ.get(CPU_LATENCY_ENV, CPU_LATENCY_DEVICE)
    if not enabled or not device:
        yield CpuWake()
        return
    try:
        fd = os.open(device, os.O_WRONLY | os.O_CLOEXEC)
    except OSError as exc:
        if log is not None and os.path.exists(device) and device not in _REFUSED:
            _REFUSED.add(device)  # said once in a process (each hand asks)
            log(f"cannot keep the CPUs awake around frames ({device}: "
                f"{exc.strerror or exc}): each frame may wait for a CPU to wake "
                "(see docs/hardware.md, or set [loop] keep_cpus_awake = false)")
        yield CpuWake()
        return
    wake = CpuWake(fd)
    try:
        yield wake
    finally:
        wake.close()
