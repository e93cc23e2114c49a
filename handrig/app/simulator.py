"""The one door from ``handrig`` into the simulator (``sim/``).

``sim/`` may import ``handrig``, never the reverse; a command that needs an
emulator, the puppet or the demo's recording gets it here, and this module
imports ``sim`` only when one of its functions is called (the user asked for the
simulated rig). Everything else reaches the emulators as subprocesses
(``handrig sim-bus``, ``handrig sim-glove``, started by :mod:`handrig.app.factory`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

import numpy as np

from handrig.config.rig import RigConfig

if TYPE_CHECKING:
    from handrig.devices.glove_recording import GloveRecording
    from sim.dxl_bus import SimBus
    from sim.glove_emulator import EmulatorFormat, GloveEmulator
    from sim.puppet import Puppet


def relaxed_hand() -> ModuleType:
    """``sim.passive``: the relaxed-hand model (Neff & Seidel) with its config loader."""
    from sim import passive

    return passive


def relaxed_hand_tuning() -> ModuleType:
    """``sim.passive_tuning``: the relaxed hand's check, tune and config-writing steps
    (``handrig passive``)."""
    from sim import passive_tuning

    return passive_tuning


def baker() -> ModuleType:
    """``sim.bake``: bakes the passive-sag grid from the relaxed-hand model
    (``handrig bake``)."""
    from sim import bake

    return bake


def retarget_fitter() -> ModuleType:
    """``sim.retarget_fit``: fits a robot's retarget table through its MJCF kinematics
    and grades one (fist closure, pinch gaps, fingertip error; ``handrig retarget``)."""
    from sim import retarget_fit

    return retarget_fit


def demo_recording() -> Path:
    """The glove recording ``handrig demo`` streams (``config/recordings/demo_glove.csv``)."""
    from sim.demo_recording import DEMO_RECORDING

    return Path(DEMO_RECORDING)


def render_strip(frames_deg: Sequence[np.ndarray], joint_names: Sequence[str],
                 out: str | Path, *, model: str | Path | None = None,
                 times_s: Sequence[float] | None = None,
                 view: tuple[float, float, float] | None = None,
                 labels: Sequence[str] | None = None) -> Path:
    """An image strip of the simulated hand at these servo positions, or of the robot
    ``model`` (an MJCF file) when given, each tile labelled with its frame's time from
    ``times_s`` or with ``labels`` (needs EGL or OSMesa); HandrigError when it cannot
    render. :func:`tiles_drawn` says how many tiles it holds."""
    from sim.render import render_strip as render

    return Path(render(frames_deg, joint_names, out, model=model, times_s=times_s, view=view,
                       labels=labels))


def tiles_drawn(n_frames: int) -> int:
    """How many tiles :func:`render_strip` draws for ``n_frames`` frames."""
    from sim.render import picked

    return len(picked(n_frames))


def servo_bus(
    rig: RigConfig,
    *,
    ids: Sequence[int] | None = None,
    model: str | None = None,
    puppet: bool = True,
    on_behind: Callable[[float], None] | None = None,
    wire_timing: bool = False,
    faults: str = "",
    realtime: bool = True,
    bauds: Mapping[int, int] | None = None,
) -> tuple[SimBus, Puppet | None]:
    """The emulated servos (sim/dxl_bus.py) on a pty (not started), and the MuJoCo puppet they
    drive (None with ``puppet=False``: the servos move kinematically). ``model``:
    every servo of that model (the rig's servos too: :func:`with_model`); ``faults``:
    a fault spec as ``handrig sim-bus --faults`` takes it; ``bauds``: servo ID -> baud
    for servos not at the rig's (a servo answers only at its own)."""
    from sim.dxl_bus import FaultSpec, SimBus

    spec = FaultSpec.parse(faults) if faults else None
    hand: Puppet | None = None
    if puppet:
        from sim.puppet import Puppet

        kwargs: dict[str, Any] = {} if on_behind is None else {"on_behind": on_behind}
        hand = Puppet(rig, **kwargs)
    bus = SimBus.from_rig(rig, ids=ids, model=model, puppet=hand or False,
                          wire_timing=wire_timing, faults=spec, realtime=realtime,
                          bauds=bauds)
    return bus, hand


def with_model(rig: RigConfig, model: str) -> RigConfig:
    """The rig with every servo of model ``model`` (servos and puppet must agree)."""
    from sim.dxl_bus import with_model as replace_model

    return replace_model(rig, model)


def glove_emulator(recording: GloveRecording, fmt: EmulatorFormat = "frames", *,
                   rate_hz: float | None = None, loop: bool = False,
                   loop_from_s: float = 0.0, analog_max: int = 4095) -> GloveEmulator:
    """A glove emulator streaming ``recording`` on a pty (a context manager)."""
    from sim.glove_emulator import GloveEmulator

    return GloveEmulator(recording, fmt, rate_hz=rate_hz, loop=loop, loop_from_s=loop_from_s,
                         analog_max=analog_max)


def calibration_motion() -> ModuleType:
    """``sim.calibration_motion``: the scripted poses of ``handrig calibrate glove``
    (open hand, fist, each thumb motion) as emulated sensor readings."""
    import sim.calibration_motion

    return sim.calibration_motion


def view_models(rig: RigConfig) -> dict[str, Any]:
    """The rig's MuJoCo models as the puppet builds them, by hand (``"ri"``, ``"le"``;
    a robot rig: its MJCF model as ``"ri"``), for drawing (``handrig.app.view``)."""
    from sim.puppet import Puppet

    return {hand: sim.model for hand, sim in Puppet(rig).hands.items()}


def human_hand_models() -> dict[str, Any]:
    """Both hands of the 23-DOF human-hand model (``sim.hand_model``), by hand."""
    import mujoco

    from sim.hand_model import hand_model_xml

    return {h: mujoco.MjModel.from_xml_string(hand_model_xml(h)) for h in ("ri", "le")}


def recording_from(path: str | Path, offset_s: float, folder: str | Path) -> Path:
    """The glove recording at ``path`` started ``offset_s`` seconds in (what came before
    goes to the end, so it is as long), written into ``folder``: the demo's left glove,
    which should not move as the right one does."""
    import dataclasses

    from handrig.devices.glove_recording import read_glove_recording, write_glove_recording

    rec = read_glove_recording(path)
    n = len(rec.t_s)
    k = int(np.searchsorted(rec.t_s - rec.t_s[0], offset_s)) % max(n, 1)
    order = np.r_[k:n, 0:k]
    rolled = dataclasses.replace(
        rec, raw=rec.raw[order], buttons=rec.buttons[order],
        quat_xyzw=None if rec.quat_xyzw is None else rec.quat_xyzw[order])
    out = Path(folder) / f"{Path(path).stem}_from_{offset_s:g}s.csv"
    write_glove_recording(out, rolled)
    return out
