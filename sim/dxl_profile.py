"""The servo's profile generator (e-manual, Profile Velocity(112), Profile
Acceleration(108), Moving Status(123)), velocity-based, as pure functions.

Positions in Present Position units (pulses), velocities in pulses per second.
No profile while Profile Velocity is 0 (the trajectory is the goal); a rectangular
profile at Profile Velocity when Profile Acceleration is 0; otherwise trapezoidal,
or triangular when the move is too short to reach Profile Velocity. Velocity Limit
caps Profile Velocity. (The time-based profile of Drive Mode bit 2 is not modelled.)
"""

from __future__ import annotations

from firmware_protocol.dynamixel import TICKS_PER_TURN, VELOCITY_UNIT_RPM

# Moving Status (123) bits.
IN_POSITION = 0x01
PROFILE_ONGOING = 0x02
FOLLOWING_ERROR = 0x08
PROFILE_NONE, PROFILE_RECTANGULAR, PROFILE_TRIANGULAR, PROFILE_TRAPEZOIDAL = 0x00, 0x10, 0x20, 0x30
# Profile Acceleration unit, rev/min^2.
PROFILE_ACCELERATION_UNIT_RPM2 = 214.577
VELOCITY_UNIT_TICKS_S = VELOCITY_UNIT_RPM * TICKS_PER_TURN / 60.0
ACCELERATION_UNIT_TICKS_S2 = PROFILE_ACCELERATION_UNIT_RPM2 * TICKS_PER_TURN / 3600.0


def profile_limits(profile_velocity: int, velocity_limit: int,
                   profile_acceleration: int) -> tuple[float, float]:
    """(top speed, acceleration) of a profile in pulses/s and pulses/s^2."""
    v_max = min(profile_velocity, velocity_limit or profile_velocity) * VELOCITY_UNIT_TICKS_S
    return v_max, profile_acceleration * ACCELERATION_UNIT_TICKS_S2


def profile_type(distance: float, v_max: float, accel: float) -> int:
    """The profile a move of ``distance`` pulses gets (Moving Status bits 4-5)."""
    if not accel:
        return PROFILE_RECTANGULAR
    if abs(distance) < v_max * v_max / accel:  # accelerating to v_max and back needs more
        return PROFILE_TRIANGULAR
    return PROFILE_TRAPEZOIDAL


def profile_step(position: float, velocity: float, goal: int, v_max: float, accel: float,
                 dt_s: float) -> tuple[float, float]:
    """The trajectory ``dt_s`` later: (position, velocity); it lands on ``goal`` exactly."""
    error = goal - position
    if error == 0:
        return float(goal), 0.0
    sign = 1.0 if error > 0 else -1.0
    v = velocity
    if not accel:
        v = sign * v_max
    elif v * sign < 0 or abs(error) > v * v / (2.0 * accel):
        v = max(-v_max, min(v_max, v + sign * accel * dt_s))  # speed up toward the goal
    else:
        v -= sign * accel * dt_s  # brake
        if v * sign <= 0:
            v = sign * min(v_max, accel * dt_s)
    moved = v * dt_s
    if abs(moved) >= abs(error):
        return float(goal), 0.0
    return position + moved, v
