"""The one factory: the concrete devices and outputs a run opens on its parts.

The parts (configs loaded and checked, the pipeline built) come from
:mod:`handrig.app.parts`, the run summary is :mod:`handrig.app.summary`'s. Everything
else takes its dependencies as arguments; only this module (and the commands that
call it) decide which glove, bus and outputs a run uses: :func:`servo_bus` (with
:func:`zeroing_bus`, the same bus as servo calibration talks to it, and
:func:`servo_bringup`, the servos as ``handrig servos`` and ``handrig setup`` bring
them up) is the one place a servo vendor is chosen.
The simulated rig's emulators run as subprocesses (``handrig sim-bus``,
``handrig sim-glove``) started through :mod:`handrig.app.port_processes`, each in
its own session so that a Ctrl-C in the terminal reaches the rig alone: the rig
eases, turns torque off, and only then stops them. In-process simulator parts
come through :mod:`handrig.app.simulator`.
"""

from __future__ import annotations

import contextlib
import subprocess
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from handrig.app.parts import RigParts, control_channels, glove_spec
from handrig.app.port_processes import SIM_BUS, StartedEmulators, port_process, sim_bus_argv
from handrig.clock import Clock
from handrig.config.rig import SIM_PORT, RigConfig, require_port
from handrig.devices.glove import GloveSource, ReplayGlove, SerialGlove
from handrig.devices.glove_calibration import (
    GloveConfig,
)
from handrig.devices.glove_recording import check_channels, read_glove_recording
from handrig.devices.servo import DynamixelBus
from handrig.devices.servo.bringup import BusBringup
from handrig.devices.servo.bus import ServoBus
from handrig.devices.servo.dynamixel import ReadFields, cycle_bytes, wire_time_s
from handrig.devices.servo.dynamixel_bringup import DynamixelBringup
from handrig.devices.servo.dynamixel_zeroing import DynamixelZeroing
from handrig.devices.servo.models import check_rig
from handrig.devices.servo.zeroing import ZeroingBus
from handrig.loop.rig import Rig

FloatArray = NDArray[np.float64]


def open_glove(spec: str | None, cfg: GloveConfig, clock: Clock,
               glove_file: Path | None = None) -> GloveSource:
    """``PORT``, ``opengloves:PORT`` or ``replay:FILE`` (None: the port in glove.toml),
    checked first (:func:`glove_spec`)."""
    spec = glove_spec(spec, cfg, glove_file)
    needed = max(ch.raw_index() for ch in cfg.channels) + 1
    if spec.startswith("replay:"):
        path = spec.removeprefix("replay:")
        rec = read_glove_recording(path)
        check_channels(rec, needed, path, glove_file)  # a take of another glove
        return ReplayGlove(rec, clock)
    if spec.startswith("opengloves:"):
        return SerialGlove(spec.removeprefix("opengloves:"), "opengloves", clock=clock,
                           baud=cfg.glove.baud, analog_max=cfg.glove.analog_max,
                           estop_letter=cfg.glove.estop_letter, reader="poll")
    # reader="poll": the loop itself reads the port without blocking, so a frame is
    # handled in the cycle that reads it (no reader thread competing for the GIL).
    # a frame with fewer raw channels than the calibration reads is never settled on
    names = [""] * needed
    for ch in cfg.channels:
        names[ch.raw_index()] = names[ch.raw_index()] or ch.curve
    return SerialGlove(spec, "frames", clock=clock, baud=cfg.glove.baud, reader="poll",
                       min_channels=needed, channel_names=names)


def cycle_rate_hz(rig: RigConfig, glove_rate_hz: float) -> float:
    """Cycles a second the loop runs at: the glove's nominal frame rate in mode "glove"
    (held to the ceiling), ``[loop] rate_hz`` in mode "fixed"."""
    if rig.loop.mode == "fixed":
        return rig.loop.rate_hz
    return min(glove_rate_hz, rig.loop.ceiling_hz)


def read_fields_for(rig: RigConfig, glove_rate_hz: float) -> ReadFields:
    """What the loop reads back: position, velocity and current when a goal write plus that
    read fit in 70 % of a cycle on the wire, else position only (e.g. 20 servos at 1 Mbps
    and 200 Hz: 4.4 ms of wire for the full read, 3.2 ms for positions, in a 5 ms cycle).
    The cycle is the loop's (:func:`cycle_rate_hz`), not ``[loop] rate_hz`` in mode glove."""
    n, period = len(rig.servos), 1.0 / cycle_rate_hz(rig, glove_rate_hz)
    full = wire_time_s(cycle_bytes(n, data_len=10), rig.bus.baud)
    return "motion" if full <= 0.7 * period else "position"


@dataclass
class OpenedBus:
    """A servo bus the factory opened (not yet connected): the driver, its port, and the
    emulator process behind it when the bus is simulated."""

    bus: ServoBus
    port: str
    emulator: subprocess.Popen[str] | None = None

    def emulator_output(self) -> str:
        """What the emulator printed after its port line (read once it has stopped)."""
        if self.emulator is None or self.emulator.stdout is None:
            return ""
        try:
            return self.emulator.stdout.read() or ""
        except (OSError, ValueError):
            return ""


@contextlib.contextmanager
def servo_bus(spec: str | None, parts: RigParts, clock: Clock, *, wire_timing: bool = True,
              viewer: bool = False, faults: str = "",
              log: Callable[[str], None] = print,
              started: StartedEmulators | None = None) -> Iterator[OpenedBus]:
    """The servo bus on ``spec`` (a port, ``"sim"``, None: rig.toml's port); closed on exit
    (torque off if still on). ``"sim"`` starts ``handrig sim-bus`` (the MuJoCo puppet,
    ``wire_timing``, ``viewer``, ``faults``) first, or takes the one ``started`` holds
    for these arguments (:func:`~handrig.app.port_processes.sim_bus_argv`), and stops it
    after the bus is closed."""
    rig_cfg = parts.rig_config
    check_rig(rig_cfg, str(parts.rig_file))  # the servos it names, at bauds they take
    bus_spec = require_port(spec or rig_cfg.bus.port, parts.rig_file,
                            flag="--bus-left" if parts.hand == "le" else "--port")
    with contextlib.ExitStack() as stack:
        proc: subprocess.Popen[str] | None = None
        if bus_spec == SIM_PORT:
            argv = sim_bus_argv(parts.rig_file, parts.hand, wire_timing=wire_timing,
                                viewer=viewer, faults=faults)
            emulator = started.take(argv) if started is not None else None
            if emulator is None:
                proc, port = stack.enter_context(port_process(argv, SIM_BUS))
            else:
                stack.enter_context(emulator)
                proc, port = emulator.proc, emulator.port()
            log(f"SIMULATED servo bus ({SIM_PORT!r}: the emulated servos and MuJoCo puppet "
                f"on {port}); no hardware is driven")
        else:
            port = bus_spec
        # No reply poll (spin_s 0): the loop reads the servos once every few cycles, where
        # the tens of microseconds a poll saves do not matter, and a SCHED_FIFO thread
        # that polls holds back the kernel worker delivering the reply (and the glove's
        # bytes) whenever that worker is queued on the loop's CPU.
        fields = read_fields_for(rig_cfg, parts.glove_config.glove.rate_hz)
        bus = DynamixelBus(port, rig_cfg, clock=clock, read_fields=fields,
                           spin_s=0.0, emulated=proc is not None,
                           missing_ok=rig_cfg.silence.action == "continue")
        stack.callback(bus.close)
        yield OpenedBus(bus, port, proc)


@contextlib.contextmanager
def zeroing_bus(spec: str, rig_cfg: RigConfig, rig_file: Path) -> Iterator[ZeroingBus]:
    """The bus ``handrig calibrate servos`` finds the zeros on (not yet connected): on
    the port ``spec``, or on ``handrig sim-bus`` started for ``rig_file`` when ``spec``
    is ``"sim"`` (stopped after the bus is closed, torque off)."""
    with contextlib.ExitStack() as stack:
        port = spec
        if spec == SIM_PORT:
            _, port = stack.enter_context(
                port_process(["sim-bus", "--rig", str(rig_file)], "the simulated servo bus"))
        bus = DynamixelZeroing(port, rig_cfg)
        stack.callback(bus.close)
        yield bus


def servo_bringup() -> type[BusBringup]:
    """The bring-up of the servos' vendor (``handrig servos``, ``handrig setup``): a
    class, as its bauds are known before a port is (the command line checks ``--baud``
    against them); ``servo_bringup()(port)`` works on one port."""
    return DynamixelBringup


def outputs(stack: contextlib.ExitStack, rig_cfg: RigConfig, clock: Clock, *,
            vmc: str | None = None, record: str | None = None,
            log: Callable[[str], None] = print, glove_rate_hz: float | None = None,
            record_rate_hz: float | None = None, openxr: str | None = None
            ) -> list[Callable[[float, FloatArray], None]]:
    """The outputs a run feeds the full pose to: a VMC sender (``HOST:PORT``), the
    OpenXR hand joints (``openxr``, ``HOST:PORT``: :mod:`handrig.outputs.openxr`), a
    recorder (``.csv`` or ``.bvh``). Each is closed when ``stack`` unwinds. A BVH take
    is written at ``record_rate_hz`` if given (``--record-rate``), else at the glove's
    nominal rate (``glove_rate_hz``, ``[glove] rate_hz``) when the loop follows the
    glove, at ``[loop] rate_hz`` in mode "fixed"."""
    out: list[Callable[[float, FloatArray], None]] = []
    if vmc:
        from handrig.outputs.vmc import VmcSender, parse_host_port

        host, port = parse_host_port(vmc)
        sender = VmcSender(host, port, clock=clock)
        stack.callback(sender.close)
        out.append(sender)
    if openxr:
        from handrig.outputs.openxr import OpenXrSender, parse_target

        xr = OpenXrSender(*parse_target(openxr), clock=clock)
        stack.callback(xr.close)
        out.append(xr)
    if record:
        from handrig.outputs.recorder import Recorder

        rate_hz = take_rate_hz(rig_cfg, glove_rate_hz, record_rate_hz)
        recorder = Recorder(record, rate_hz=rate_hz, log=log)
        stack.callback(lambda: log(f"recorded performance: {recorder.close()}"))
        out.append(recorder)
    return out


def take_rate_hz(rig_cfg: RigConfig, glove_rate_hz: float | None,
                 record_rate_hz: float | None) -> float:
    """A BVH take's frame rate: ``--record-rate``, else the glove's nominal rate when the
    loop follows the glove, else ``[loop] rate_hz``."""
    if record_rate_hz:
        return record_rate_hz
    if rig_cfg.loop.mode == "glove" and glove_rate_hz:
        return glove_rate_hz
    return rig_cfg.loop.rate_hz


def build_rig(parts: RigParts, glove: Any, bus: Any, clock: Clock, *,
              outputs: Sequence[Callable[[float, FloatArray], None]] = (),
              log: Callable[[str], None] = print, profile: bool = False,
              ease_in: bool = False) -> Rig:
    """The loop on these devices, with the rig file's rates and safety timings
    (:meth:`Rig.from_config`); ``ease_in``: the first frame eases in (a take played)."""
    return Rig.from_config(parts.rig_config, glove, bus, parts.pipeline, clock,
                           controls_from_raw=parts.controls, orientation=parts.orientation,
                           outputs=outputs, log=log, profile=profile, ease_in=ease_in,
                           raw_channels=control_channels(parts.glove_config,
                                                         parts.pipeline.expander.controls),
                           gravity=parts.gravity)
