"""MuJoCo loopback: emulated servos drive the joints of the shared MJCF hand.

Each calibrated servo of the rig (``config/rig.toml``) drives one joint of the
hand from :mod:`sim.hand_model` through a MuJoCo ``position`` actuator made to
behave like an X-series servo. A robot rig (:mod:`handrig.pose.robot_rig`, e.g.
``config/rigs/leap.toml``) drives the joints of its own MJCF model instead
(``[robot].model``): each servo's joint is found by name, and the model's own
position actuator on that joint (or one added) is rewired the same way.

- target: Goal Position (motor ticks, undoing Homing Offset and Drive Mode) ->
  joint angle by the rig calibration (:func:`handrig.devices.servo.positions.ticks_to_deg`);
- speed: the target moves toward the goal at most at the servo's Profile
  Velocity (or Velocity Limit), divided by the gear ratio;
- torque: saturates at the stall torque times the gear ratio (in
  current-based position mode at min(Goal Current, Current Limit),
  :meth:`EmulatedServo.current_cap_ma`, via the datasheet's stall torque /
  stall current ratio), so a stalled joint shows Present Current at that cap;
- stiffness from Position P Gain. Model (an assumption, not a datasheet
  formula): PWM = P/128 x error in ticks, torque = stall torque x PWM / 885, so
  P = 400 gives 1.2 Nm/rad at the XL330 horn;
- damping: a critically damped base (servo's inner loops, assumed) plus Position
  D Gain under the same PWM model, PWM = D/16 x error rate in ticks per
  :data:`D_GAIN_TIME_S` (the time unit is an assumption);
- a robot model's joints are not clipped to their range on the goal side: a goal
  beyond a joint's range drives it into the model's limit and the servo stalls
  there at its torque cap, as on a real hand whose goal lies past a mechanical
  stop;
- torque off: no drive, only back-drive damping.

Present Position / Velocity / Current come from the simulation (joint angle,
joint velocity, actuator force) mapped back through the calibration; the
servo's current is the actuator torque over the motor's torque constant.

Simulated time follows wall time: a thread steps the model in batches (1 ms
steps, every ~2 ms of wall time), holding the bus lock only to exchange goals
and present state. If the simulation falls more than ``max_lag_s`` behind, it
skips ahead, counts the event in :attr:`Puppet.behind_count` and calls
``on_behind``.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from firmware_protocol.dynamixel import MODELS, TICKS_PER_TURN, HardwareError, Reg
from handrig.config.rig import RigConfig, ServoCalibration
from handrig.devices.servo.models import servo_model
from handrig.devices.servo.positions import ticks_to_deg
from handrig.errors import ConfigError, HandrigError
from handrig.hand import DOF_NAMES, Hand
from handrig.pose.robot_rig import RobotRigConfig
from sim.dxl_line import PHYSICS_PRIORITY, try_realtime
from sim.dxl_servo import EmulatedServo
from sim.hand_model import (
    REFERENCE_HAND_LENGTH_M,
    ActuatorParams,
    PassiveParams,
    hand_model_xml,
)

PWM_LIMIT = 885  # X-series PWM Limit default (= 100 % duty)
# Reflected rotor inertia at the servo horn (assumed; sim.hand_model's default),
# scaled by gear_ratio^2 at the joint.
ARMATURE_KGM2 = 1e-4
# Back-drive damping of an unpowered servo at the horn, N m s/rad (assumed).
BACKDRIVE_DAMPING_NMS = 0.01
TICKS_PER_RAD = TICKS_PER_TURN / (2.0 * math.pi)
HEAT_EVERY_S = 0.05
# Time unit of the D term under this module's PWM model (assumed: the X series does
# not document its position loop period).
D_GAIN_TIME_S = 0.001


def kp_from_p_gain(p_gain: int, stall_torque_nm: float) -> float:
    """Horn stiffness (N m/rad) for a Position P Gain, under this module's PWM model."""
    return stall_torque_nm * (p_gain / 128.0) / PWM_LIMIT * TICKS_PER_RAD


def kv_from_d_gain(d_gain: int, stall_torque_nm: float) -> float:
    """Horn damping (N m s/rad) that Position D Gain adds, under this module's PWM model."""
    return stall_torque_nm * (d_gain / 16.0) / PWM_LIMIT * TICKS_PER_RAD * D_GAIN_TIME_S


def _fallback_passive() -> PassiveParams:
    """Weak springs for joints no servo drives, used when the tuned relaxed-hand
    parameters (config/passive_hand.toml) are not available."""
    names = DOF_NAMES["ri"]
    return PassiveParams({n: 0.0 for n in names}, {n: 0.05 for n in names},
                         {n: 0.005 for n in names})


# Motor state per channel: ticks, rpm, mA, actuator force (N m).
_State = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


@dataclass
class _Channel:
    servo_id: int
    cal: ServoCalibration
    actuator: int
    qpos: int
    stall_nm: float
    kt_nm_per_a: float
    powered: bool = False
    servo: EmulatedServo | None = None
    p_gain: int = -1
    d_gain: int = 0
    saturated_s: float = 0.0
    limits_key: tuple[bytes, bytes, bytes, bytes, bytes, int] | None = None
    pulled: bytes = b""  # control table 10..115 at the last pull that powered the channel
    pulled_goal: bytes = b""  # and its Goal Position bytes
    force_limit_nm: float = 0.0


class _HandSim:
    def __init__(
        self, hand: Hand, cals: Sequence[ServoCalibration], timestep_s: float,
        hand_length_m: float,
    ) -> None:
        import mujoco

        self.mujoco = mujoco
        self.hand = hand
        try:
            from sim.hand_model import default_passive

            passive = default_passive()
        except (HandrigError, OSError, KeyError):
            passive = _fallback_passive()
        actuated = {}
        for c in cals:
            info = MODELS[servo_model(c)]
            kp = kp_from_p_gain(info.position_p_gain, info.stall_torque_nm) * c.gear_ratio**2
            armature = ARMATURE_KGM2 * c.gear_ratio**2
            actuated[c.joint] = ActuatorParams(
                kp_nm_per_rad=kp,
                kv_nms_per_rad=2.0 * math.sqrt(kp * armature),
                force_limit_nm=info.stall_torque_nm * c.gear_ratio,
                max_speed_rad_s=math.radians(info.no_load_speed_rpm * 6.0) / c.gear_ratio,
                armature_kgm2=armature,
            )
        xml = hand_model_xml(hand, hand_length_m, passive=passive, actuated=actuated,
                             timestep_s=timestep_s)
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.joint_names: tuple[str, ...] = DOF_NAMES[hand]
        acts = {c.joint: mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_ACTUATOR, c.joint)
                for c in cals}
        self._setup(cals, acts)

    def _setup(self, cals: Sequence[ServoCalibration], actuator_of: dict[str, int]) -> None:
        """Channels and calibration arrays for ``cals`` on ``self.model``."""
        mujoco = self.mujoco
        self.data = mujoco.MjData(self.model)
        self.channels: list[_Channel] = []
        for c in cals:
            jnt = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_JOINT, c.joint)
            info = MODELS[servo_model(c)]
            self.channels.append(_Channel(
                c.id, c, actuator_of[c.joint], int(self.model.jnt_qposadr[jnt]),
                info.stall_torque_nm, info.stall_torque_nm / info.stall_current_a))
        n = len(self.channels)
        self.act_idx = np.array([ch.actuator for ch in self.channels], dtype=np.intp)
        self.q_idx = np.array([ch.qpos for ch in self.channels], dtype=np.intp)
        self.goal_rad = np.zeros(n)
        self.speed_rad_s = np.zeros(n)
        self.heat_pending_s = 0.0
        # calibration as arrays: ticks = zero + direction * gear * deg * ticks/deg
        cal_list = [ch.cal for ch in self.channels]
        self.zero_ticks = np.array([c.zero_ticks for c in cal_list], dtype=float)
        self.ticks_per_deg = np.array(
            [c.direction * c.gear_ratio * TICKS_PER_TURN / 360.0 for c in cal_list])
        self.rpm_per_rad_s = np.array(
            [c.direction * c.gear_ratio * 60.0 / (2.0 * math.pi) for c in cal_list])
        self.ma_per_nm = np.array(
            [c.direction * 1000.0 / (c.gear_ratio * ch.kt_nm_per_a)
             for c, ch in zip(cal_list, self.channels, strict=True)])
        for ch in self.channels:
            self._set_power(ch, False)
        self.mujoco.mj_forward(self.model, self.data)

    def _set_power(self, ch: _Channel, on: bool) -> None:
        m = self.model
        a = ch.actuator
        g = ch.cal.gear_ratio
        if on:
            s = ch.servo
            ch.d_gain = s.get(Reg.POSITION_D_GAIN) if s else 0
            self._set_gain(ch, s.get(Reg.POSITION_P_GAIN) if s else 400)
            self.data.ctrl[a] = self.data.qpos[ch.qpos]
        else:
            m.actuator_gainprm[a, 0] = 0.0
            m.actuator_biasprm[a, 1] = 0.0
            m.actuator_biasprm[a, 2] = -BACKDRIVE_DAMPING_NMS * g * g
            ch.p_gain = -1
            ch.limits_key = None
        ch.powered = on
        ch.saturated_s = 0.0

    def _set_gain(self, ch: _Channel, p_gain: int) -> None:
        m = self.model
        a = ch.actuator
        g = ch.cal.gear_ratio
        kp = kp_from_p_gain(p_gain, ch.stall_nm) * g * g
        kv = 2.0 * math.sqrt(kp * ARMATURE_KGM2 * g * g)
        kv += kv_from_d_gain(ch.d_gain, ch.stall_nm) * g * g
        m.actuator_gainprm[a, 0] = kp
        m.actuator_biasprm[a, 1] = -kp
        m.actuator_biasprm[a, 2] = -kv
        ch.p_gain = p_gain

    def pull(self) -> None:
        """Read goals, torque and limits from the servos (bus lock held)."""
        for k, ch in enumerate(self.channels):
            s = ch.servo
            if s is None:
                continue
            mem = s.mem
            # everything read below lies in 10..119; unchanged since the last pull: the
            # same result (goals change most often: 116..119, then only the goal)
            settings = bytes(mem[10:116])
            if settings == ch.pulled and ch.powered:
                if mem[116:120] != ch.pulled_goal:
                    ch.pulled_goal = bytes(mem[116:120])
                    self.goal_rad[k] = math.radians(ticks_to_deg(ch.cal, s.goal_motor_ticks()))
                continue
            ch.pulled, ch.pulled_goal = settings, bytes(mem[116:120])
            on = mem[64] == 1
            if on != ch.powered:
                self._set_power(ch, on)
            if not on:
                continue
            g = ch.cal.gear_ratio
            self.goal_rad[k] = math.radians(ticks_to_deg(ch.cal, s.goal_motor_ticks()))
            self.speed_rad_s[k] = s.speed_limit_ticks_per_s() / TICKS_PER_RAD / g
            # P/D gain, Goal Current, Current Limit, PWM Limit and Goal PWM, Operating
            # Mode: act
            # only on a change
            key = (bytes(mem[80:82]), bytes(mem[84:86]), bytes(mem[102:104]),
                   bytes(mem[38:40]), bytes(mem[36:38]) + bytes(mem[100:102]), mem[11])
            if key != ch.limits_key:
                self._apply_limits(ch, s)
                ch.limits_key = key

    def _apply_limits(self, ch: _Channel, s: EmulatedServo) -> None:
        p_gain = s.get(Reg.POSITION_P_GAIN)
        d_gain = s.get(Reg.POSITION_D_GAIN)
        if p_gain != ch.p_gain or d_gain != ch.d_gain:
            ch.d_gain = d_gain
            self._set_gain(ch, p_gain)
        g = ch.cal.gear_ratio
        limit = ch.stall_nm
        cap_ma = s.current_cap_ma()
        if cap_ma is not None:  # current-based position: the current cap bounds torque
            limit = min(limit, cap_ma / 1000.0 * ch.kt_nm_per_a)
        limit *= g * min(1.0, s.effort_fraction())
        self.model.actuator_forcerange[ch.actuator] = (-limit, limit)
        ch.force_limit_nm = limit

    def step(self, n: int) -> None:
        """``n`` physics steps with the target ramped at the speed limit."""
        lo = self.model.actuator_ctrlrange[self.act_idx, 0]
        hi = self.model.actuator_ctrlrange[self.act_idx, 1]
        goal = np.clip(self.goal_rad, lo, hi)
        powered = np.array([ch.powered for ch in self.channels])
        max_step = self.speed_rad_s * self.model.opt.timestep
        ctrl = self.data.ctrl
        for _ in range(n):
            cur = ctrl[self.act_idx]
            new = cur + np.clip(goal - cur, -max_step, max_step)
            ctrl[self.act_idx] = np.where(powered, new, cur)
            self.mujoco.mj_step(self.model, self.data)

    def sample(self) -> _State:
        """The motors' state now (physics lock held): ticks, rpm, mA and actuator force
        per channel, as new arrays the servos may be given later (:meth:`apply`)."""
        d = self.data
        q_deg = np.degrees(d.qpos[self.q_idx])
        ticks = self.zero_ticks + self.ticks_per_deg * q_deg
        rpm = self.rpm_per_rad_s * d.qvel[self.q_idx]
        force = d.actuator_force[self.act_idx]
        return ticks, rpm, self.ma_per_nm * force, force

    def push(self, dt_s: float = 0.0, overload_s: float | None = None) -> None:
        """Write present state to the servos (bus lock held). With ``overload_s``, a
        servo held at its torque limit that long reports an overload error."""
        self.apply(self.sample(), dt_s, overload_s)

    def apply(self, state: _State, dt_s: float, overload_s: float | None) -> None:
        """Give the servos a :meth:`sample` of the motors' state ``dt_s`` after the last
        one (bus lock held); ``overload_s`` as :meth:`push`."""
        ticks, rpm, current_ma, force = state
        # temperature changes over minutes: update it every HEAT_EVERY_S
        self.heat_pending_s += dt_s
        heat_dt_s = 0.0
        if self.heat_pending_s >= HEAT_EVERY_S:
            heat_dt_s, self.heat_pending_s = self.heat_pending_s, 0.0
        for k, ch in enumerate(self.channels):
            s = ch.servo
            if s is None:
                continue
            s.set_motion(float(ticks[k]), float(rpm[k]), float(current_ma[k]))
            s.tick(dt_s)  # the servo's clock, profile generator and Moving Status
            if heat_dt_s:
                s.heat(heat_dt_s)
            if overload_s is not None and ch.powered:
                saturated = abs(float(force[k])) >= 0.98 * ch.force_limit_nm
                ch.saturated_s = ch.saturated_s + dt_s if saturated else 0.0
                if ch.saturated_s > overload_s:
                    s.inject_hardware_error(HardwareError.OVERLOAD)
                    ch.saturated_s = 0.0


# Goals of a robot model's servos are not clipped to the joint range (see the module
# docstring): MuJoCo's ctrlrange is set this wide instead.
UNCLIPPED_CTRL_RAD = 1000.0


class _RobotSim(_HandSim):
    """A robot's own MJCF model (``[robot].model`` of a robot rig) driven by servos.

    Each servo's joint must exist and carry an actuator (a ``<position>`` actuator,
    as Menagerie models have); that actuator is rewired as a servo (gains, bias,
    force limit, armature at the servo's values). Actuators no servo drives go slack.
    """

    def __init__(self, model_path: str, cals: Sequence[ServoCalibration],
                 timestep_s: float) -> None:
        import mujoco

        self.mujoco = mujoco
        self.hand = "ri"
        try:
            self.model = mujoco.MjModel.from_xml_path(model_path)
        except ValueError as exc:
            raise ConfigError(f"MuJoCo cannot load the robot model: {exc}",
                              file=model_path) from None
        m = self.model
        m.opt.timestep = timestep_s
        names = (mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(m.njnt))
        self.joint_names = tuple(n for n in names if n)
        actuator_of: dict[str, int] = {}
        for i, c in enumerate(cals):
            jnt = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, c.joint)
            if jnt < 0:
                raise ConfigError("no such joint in the robot model", file=model_path,
                                  key=f"servos[{i}].joint", value=c.joint,
                                  allowed=", ".join(self.joint_names))
            acts = [a for a in range(m.nu)
                    if m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT
                    and m.actuator_trnid[a, 0] == jnt]
            if not acts:
                raise ConfigError(f"the robot model has no actuator on joint {c.joint}",
                                  file=model_path, key=f"servos[{i}].joint", value=c.joint,
                                  allowed="a joint with a <position> actuator")
            a = acts[0]
            m.actuator_gaintype[a] = mujoco.mjtGain.mjGAIN_FIXED
            m.actuator_biastype[a] = mujoco.mjtBias.mjBIAS_AFFINE
            m.actuator_forcelimited[a] = 1
            m.actuator_ctrllimited[a] = 0
            m.actuator_ctrlrange[a] = (-UNCLIPPED_CTRL_RAD, UNCLIPPED_CTRL_RAD)
            m.dof_armature[m.jnt_dofadr[jnt]] = ARMATURE_KGM2 * c.gear_ratio**2
            actuator_of[c.joint] = a
        for a in set(range(m.nu)) - set(actuator_of.values()):
            m.actuator_gainprm[a, 0] = 0.0
            m.actuator_biasprm[a, 1:3] = 0.0
        self._setup(cals, actuator_of)


class Puppet:
    """A MuJoCo hand driven by emulated servos, stepped in wall-clock time.

    ``rig``: which servo drives which joint (joints of one or both hands).
    ``timestep_s``: physics step; ``period_s``: how often the thread exchanges state
    with the servos; ``max_lag_s``: how far simulated time may trail wall time before
    the puppet skips ahead and reports it. ``overload_s``: if set, a servo held at its
    torque limit for that long reports an overload hardware error (torque off until
    a reboot), as an X-series servo does under a persistent load.
    """

    def __init__(
        self,
        rig: RigConfig,
        *,
        timestep_s: float = 0.001,
        period_s: float = 0.002,
        max_lag_s: float = 0.05,
        hand_length_m: float = REFERENCE_HAND_LENGTH_M,
        overload_s: float | None = None,
        on_behind: Callable[[float], None] | None = None,
    ) -> None:
        if not 0 < timestep_s <= period_s:
            raise ConfigError("need 0 < timestep_s <= period_s", key="timestep_s",
                              value=(timestep_s, period_s))
        self.hands: dict[Hand, _HandSim]
        robot = rig.robot if isinstance(rig, RobotRigConfig) else None
        if robot is not None:  # a robot rig: its own model, every servo on it
            self.hands = {"ri": _RobotSim(robot.model, rig.servos, timestep_s)}
            # the hand mounted as its rig file says: gravity along [robot].gravity_direction
            self.hands["ri"].model.opt.gravity[:] = robot.gravity_mps2
        else:
            by_hand: dict[Hand, list[ServoCalibration]] = {}
            for cal in rig.servos:
                hand: Hand = "ri" if cal.joint in DOF_NAMES["ri"] else "le"
                if cal.joint not in DOF_NAMES[hand]:
                    continue  # a curve with no joint in the 23-DOF model
                by_hand.setdefault(hand, []).append(cal)
            self.hands = {
                h: _HandSim(h, cals, timestep_s, hand_length_m) for h, cals in by_hand.items()
            }
        self.timestep_s = timestep_s
        self.period_s = period_s
        self.max_lag_s = max_lag_s
        self.on_behind = on_behind
        self.overload_s = overload_s
        self.sim_time_s = 0.0
        self.lag_s = 0.0
        self.behind_count = 0
        self.behind_total_s = 0.0
        self.steps = 0
        self._lock: threading.RLock = threading.RLock()
        # Held while MuJoCo steps; hold it to read model/data consistently (viewers).
        self.physics_lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.error: BaseException | None = None
        self._exchanged = False
        self._realtime = False
        # per hand: a state sample and the simulated seconds it covers, not yet given
        # to the servos (exchanged mode)
        self._pending: dict[Hand, tuple[_State, float]] = {}

    @property
    def driven_ids(self) -> list[int]:
        """Servo IDs whose motion comes from the simulation."""
        return [ch.servo_id for h in self.hands.values() for ch in h.channels]

    def attach(self, servos: Sequence[EmulatedServo], lock: threading.RLock) -> None:
        """Bind the emulated servos (by ID) and the bus lock."""
        by_id = {s.id: s for s in servos}
        for h in self.hands.values():
            for ch in h.channels:
                ch.servo = by_id.get(ch.servo_id)
        self._lock = lock
        with lock:
            for h in self.hands.values():
                h.push()

    def set_gravity(self, gravity_mps2: Sequence[float], hand: Hand | None = None) -> None:
        """Gravity in the forearm frame (``sim.hand_model.gravity_in_forearm``), m/s^2,
        for one hand or all; the default model has the palm down, forearm level."""
        if len(gravity_mps2) != 3:
            raise ValueError(f"gravity must have 3 components, got {len(gravity_mps2)}")
        with self._lock:
            for h, sim in self.hands.items():
                if hand is None or h == hand:
                    sim.model.opt.gravity[:] = gravity_mps2

    def joint_deg(self, name: str) -> float:
        """A joint's simulated angle in degrees (vocabulary convention)."""
        import mujoco

        for h in self.hands.values():
            jid = mujoco.mj_name2id(h.model, mujoco.mjtObj.mjOBJ_JOINT, name)
            if jid >= 0:
                with self.physics_lock:
                    return math.degrees(float(h.data.qpos[h.model.jnt_qposadr[jid]]))
        raise KeyError(f"no simulated joint {name!r}")

    def step(self, n: int = 1) -> None:
        """Advance the simulation by ``n`` steps now (tests; the thread does this live)."""
        with self._lock:
            for h in self.hands.values():
                h.pull()
        with self.physics_lock:
            for h in self.hands.values():
                h.step(n)
        with self._lock:
            for h in self.hands.values():
                h.push(n * self.timestep_s, self.overload_s)
        self.steps += n
        self.sim_time_s += n * self.timestep_s

    def start(self, *, exchanged: bool = False, realtime: bool = False) -> None:
        """Step the physics in wall time in a thread of its own. ``exchanged``: that
        thread only steps MuJoCo (which lets go of the interpreter while it runs); the
        servos' goals and present state change hands when the bus calls
        :meth:`exchange` from its own thread, in time it waits anyway, so the physics
        never holds the bus lock or the interpreter while a packet waits. ``realtime``:
        SCHED_FIFO below the bus thread (:data:`sim.dxl_line.PHYSICS_PRIORITY`) where
        allowed, so ordinary work cannot preempt it while it holds the interpreter."""
        if self._thread is not None or not self.hands:
            return
        self._exchanged = exchanged
        self._realtime = realtime
        self._pending = {}
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="puppet-physics", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None

    def _run(self) -> None:
        if self._realtime:
            try_realtime(PHYSICS_PRIORITY)
        try:
            t0 = time.perf_counter() - self.sim_time_s
            dt = self.timestep_s
            max_batch = max(1, int(self.max_lag_s / dt))
            while not self._stop.is_set():
                wall = time.perf_counter() - t0
                n = int((wall - self.sim_time_s) / dt)
                self.lag_s = wall - self.sim_time_s
                if n <= 0:
                    self._stop.wait(self.period_s)
                    continue
                if n > max_batch:
                    skipped = (n - max_batch) * dt
                    self.behind_count += 1
                    self.behind_total_s += skipped
                    self.sim_time_s += skipped
                    if self.on_behind is not None:
                        self.on_behind(skipped)
                    n = max_batch
                if self._exchanged:
                    self._step_physics(n)
                else:
                    self.step(n)
        except BaseException as exc:  # reported through .error
            self.error = exc
            raise

    def _step_physics(self, n: int) -> None:
        """``n`` steps on the goals the last :meth:`exchange` pulled; the state they
        end in waits for the next one."""
        with self.physics_lock:
            for h, sim in self.hands.items():
                sim.step(n)
                sample = sim.sample()
                _, waiting_s = self._pending.get(h, ((), 0.0))
                self._pending[h] = (sample, waiting_s + n * self.timestep_s)
        self.steps += n
        self.sim_time_s += n * self.timestep_s

    def exchange(self) -> bool:
        """From the bus's thread, bus lock held: give the servos the state the physics
        reached since the last call and the physics the servos' goals. False (nothing
        done) while the physics is stepping; the bus tries again later."""
        if not self.physics_lock.acquire(blocking=False):
            return False
        try:
            pending, self._pending = self._pending, {}
            for h, sim in self.hands.items():
                if h in pending:
                    state, dt_s = pending[h]
                    sim.apply(state, dt_s, self.overload_s)
                sim.pull()
        finally:
            self.physics_lock.release()
        return True

    def joint_angles_deg(self) -> dict[str, float]:
        """All simulated joint angles, degrees."""
        out: dict[str, float] = {}
        with self.physics_lock:
            for h in self.hands.values():
                for name in h.joint_names:
                    jid = h.mujoco.mj_name2id(h.model, h.mujoco.mjtObj.mjOBJ_JOINT, name)
                    out[name] = math.degrees(float(h.data.qpos[h.model.jnt_qposadr[jid]]))
        return out

