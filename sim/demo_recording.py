"""The demo's glove recording, derived from the reference mocap.

The right hand's five control curves of the reference capture
(``data/mocap/pn_gestures_reference.bvh``, 24 fps) are resampled to the glove
rate and turned into raw sensor counts through the inverse of the default glove
calibration (``config/glove.toml``), so the real pipeline's calibration brings
them back to the performer's angles. A forearm orientation path is added that
sweeps the passive sag: inclination swings between -55 and +55 degrees
(period 11 s) while the rotation about the forearm swings between palm down
(0) and palm up (180) through palm vertical (period 7 s); the heading wanders
too, and must not matter. IMU quaternions are scalar last, ENU world frame, as
``firmware_protocol/SPEC.md`` sends them.

``python -m sim.demo_recording`` writes it to the user's data directory
(``$XDG_DATA_HOME/handrig/recordings/demo_glove.csv``, ``~/.local/share/handrig``
when unset); the shipped copy is regenerated only when named:
``python -m sim.demo_recording --out config/recordings/demo_glove.csv``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from handrig.config.loading import CONFIG_DIR
from handrig.config.paths import DATA_HOME_HELP, user_data
from handrig.devices.glove_calibration import (
    GloveCalibration,
    load_glove_config,
    recording_from_degrees,
)
from handrig.devices.glove_recording import GloveRecording, write_glove_recording
from handrig.hand import curve_index
from handrig.offline.mocap import load_reference
from handrig.pose.orientation import ForearmOrientation

DEMO_RECORDING = CONFIG_DIR / "recordings" / "demo_glove.csv"
ADC_MAX = 4095


def forearm_path(t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(inclination, rotation, heading) in degrees along the demo's forearm path."""
    inclination = 55.0 * np.sin(2 * np.pi * t_s / 11.0)
    rotation = 90.0 - 90.0 * np.cos(2 * np.pi * t_s / 7.0)
    heading = 30.0 * np.sin(2 * np.pi * t_s / 13.0)
    return inclination, rotation, heading


def make_demo_recording(rate_hz: float = 200.0) -> GloveRecording:
    """The recording: mocap controls as raw counts plus the forearm sweep."""
    cfg = load_glove_config(CONFIG_DIR / "glove.toml")
    cal = GloveCalibration.from_config(cfg)
    mocap = load_reference()
    cols = [curve_index(c) for c in cal.curves]
    controls = mocap.curves[:, cols]
    t_mocap = np.arange(len(controls)) / mocap.fps
    t = np.arange(0.0, t_mocap[-1], 1.0 / rate_hz)
    deg = np.stack([np.interp(t, t_mocap, controls[:, j]) for j in range(len(cols))], axis=1)
    incl, rot, heading = forearm_path(t)
    imu = ForearmOrientation()  # scalar last, ENU, identity mount: as SPEC.md sends
    quat = np.array([imu.quaternion_for(a, b, h)
                     for a, b, h in zip(incl, rot, heading, strict=True)])
    return recording_from_degrees(
        cal, t, deg, quat_xyzw=quat, full_scale=ADC_MAX,
        meta={"rate_hz": f"{rate_hz:g}",
              "source": "data/mocap/pn_gestures_reference.bvh (LGPL-2.1), right-hand "
                        "controls; forearm path of sim/demo_recording.py"},
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rate", type=float, default=200.0)
    ap.add_argument("--out", type=Path, default=None,
                    help=f"output CSV (default recordings/demo_glove.csv in {DATA_HOME_HELP}; "
                         f"the shipped {DEMO_RECORDING.relative_to(CONFIG_DIR.parent)} only "
                         "when named here)")
    args = ap.parse_args()
    if args.out is None:
        args.out = user_data("recordings/demo_glove.csv")
    rec = make_demo_recording(args.rate)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_glove_recording(args.out, rec)
    print(f"wrote {args.out}: {len(rec)} samples, {rec.duration_s:.1f} s at {args.rate:g} Hz")


if __name__ == "__main__":
    main()
