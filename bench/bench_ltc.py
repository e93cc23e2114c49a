"""Timecode: the LTC decoder's CPU per second of audio, the reader's lock error against
the true timecode, a take frame's stamp cost on the loop, and a chase on the rig.

The decoder: 20 s of 25 fps LTC at 44.1, 48 and 96 kHz fed in 10 ms blocks, CPU time
(process time) per second of audio, min and median of 5 runs. The lock: 25 fps from
01:00:00:00 0.1 % fast, a jump, a stop, its return, read from a WAV on a fake clock;
the reader's position at every 10 ms block against the true timecode (frames): median,
p99, max away from the jump, and how long after the jump and the stop the position
followed. The stamp: ``TimecodeStamp.__call__`` per frame, the only work ``--ltc`` adds
to the loop. The chase (``HANDRIG_BENCH_LTC_CHASE=0`` to skip): ``play --chase-ltc``'s
glove on the byte-level bus emulator, each cycle's take frame against the true
timecode.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

from handrig.clock import FakeClock, MonotonicClock
from handrig.devices.timecode.audio import WavAudio
from handrig.devices.timecode.ltc import RATES, LtcDecoder, Timecode
from handrig.devices.timecode.ltc_encode import Rendered, Segment, render, write_wav
from handrig.devices.timecode.reader import LtcReader
from handrig.outputs.timecode_stamp import TimecodeStamp

FPS = RATES["25"]


def decoder_cpu() -> None:
    print("LTC decoder, CPU ms per second of audio (20 s of 25 fps, 10 ms blocks; min / median"
          " of 5):")
    for sr in (44100, 48000, 96000):
        r = render([Segment(Timecode(1, 0, 0, 0), 500, FPS, 1.0)], sr)
        block = sr // 100
        runs = []
        for _ in range(5):
            d = LtcDecoder(sr)
            t0 = time.process_time()
            n = 0
            for i in range(0, r.samples.size, block):
                n += len(d.feed(r.samples[i:i + block]))
            runs.append((time.process_time() - t0) / (r.samples.size / sr) * 1e3)
            assert n == 500, n
        print(f"  {sr / 1000:>5.1f} kHz  {min(runs):6.2f} / {float(np.median(runs)):6.2f} ms/s")


def lock_signal() -> Rendered:
    return render([Segment(Timecode(1, 0, 0, 0), 100, FPS, 1.001),
                   Segment(Timecode(1, 0, 10, 0), 100, FPS, 1.001),
                   Segment(None, silence_s=0.5),
                   Segment(Timecode(1, 0, 20, 0), 50, FPS, 1.001)], 48000)


def lock_error(folder: Path) -> None:
    r = lock_signal()
    wav = folder / "lock.wav"
    write_wav(wav, r.samples, r.sample_rate_hz)
    clock = FakeClock(0.0)
    audio = WavAudio(wav, clock)
    reader = LtcReader(audio, clock)
    t, pos = [], []
    while (got := audio.read()) is not None:
        reader.feed(*got)
        t.append(clock.now())
        p = reader.position(clock.now())
        pos.append(np.nan if p is None else p)
    ts, ps = np.array(t), np.array(pos)
    true = r.frame_at(ts)
    jump_s, stop_s = r.stretches[1][0], r.stretches[1][1]
    hearing = (ts >= jump_s) & (ts < jump_s + 0.07)
    locked = np.isfinite(ps) & np.isfinite(true) & ~hearing
    err = np.abs(ps[locked] - true[locked])
    after_jump = ts[(ts >= jump_s) & np.isfinite(ps) & (np.abs(ps - true) < 1.0)]
    after_stop = ts[(ts >= stop_s) & np.isnan(ps)]
    print("LTC reader, position against the true timecode (25 fps, 0.1 % fast, a jump, a stop;"
          " 10 ms blocks, frames):")
    print(f"  median {np.median(err):.3f}  p99 {np.percentile(err, 99):.3f}  max {err.max():.3f}"
          f"  ({locked.sum()} blocks)")
    print(f"  jump followed after {(after_jump[0] - jump_s) * 1e3:.0f} ms (the first frame after"
          f" it is 40 ms long); stop: position held at once, lost after"
          f" {(after_stop[0] - stop_s) * 1e3:.0f} ms")
    st = reader.stats()
    print(f"  {st.frames} frames, {st.jumps} jump, {st.losses} loss, {st.bad_frames} bad")


def stamp_cost(folder: Path) -> None:
    r = render([Segment(Timecode(1, 0, 0, 0), 25, FPS, 1.0)], 48000)
    clock = FakeClock(0.0)
    wav = folder / "stamp.wav"
    write_wav(wav, r.samples, 48000)
    audio = WavAudio(wav, clock)
    reader = LtcReader(audio, clock)
    for _ in range(50):
        got = audio.read()
        assert got is not None
        reader.feed(*got)
    stamp = TimecodeStamp(reader, clock, folder / "take.timecode.csv", take="take.csv")
    pose = np.zeros(54)
    dt = np.empty(20000)
    for i in range(dt.size):
        t0 = time.perf_counter()
        stamp(0.5 + i * 1e-6, pose)
        dt[i] = time.perf_counter() - t0
    stamp.close()
    print(f"--ltc on the loop: a frame's stamp {np.median(dt) * 1e6:.1f} us median,"
          f" {np.percentile(dt, 99) * 1e6:.1f} us p99 (after the Sync Write; 20000 calls)")


def chase(folder: Path) -> None:
    import argparse

    from handrig import hand
    from handrig.app.parts import build_parts
    from handrig.app.session import LiveOptions, run_live
    from handrig.app.takes import load_play_take, play_parts
    from handrig.app.timecode import chase_setup
    from handrig.config.rig import load_rig_config
    from handrig.config.rig_files import SHIPPED_RIG
    from handrig.outputs.recorder import Recorder
    from handrig.pose.pipeline import POSE_SIZE
    from sim.dxl_bus import SimBus

    take = folder / "take.csv"
    with Recorder(take, rate_hz=100.0, with_wrist=True, sync=False) as rec:
        for ti in np.arange(300) / 100.0:
            pose = np.zeros(POSE_SIZE)
            pose[hand.curve_index("riIndexMCPy")] = 80.0 * ti / 3.0
            rec.add(float(ti), pose[:50], pose[50:])
    r = render([Segment(Timecode(0, 59, 58, 15), 50, FPS, 1.001),
                Segment(Timecode(1, 0, 2, 0), 15, FPS, 1.001),
                Segment(None, silence_s=0.4)], 48000)
    wav = folder / "chase.wav"
    write_wav(wav, r.samples, 48000)
    parts = build_parts(None, None)
    played = load_play_take(take, parts.glove_config)
    parts = play_parts(parts, played)
    setup = chase_setup(argparse.Namespace(speed=1.0, loop=False, chase_ltc=str(wav),
                                           ltc_fps=None, chase_at="01:00:00:10"), played)
    with SimBus.from_rig(load_rig_config(SHIPPED_RIG)) as sim:
        result = run_live(parts, LiveOptions(
            glove=f"replay:{take}", take=setup.glove, timecode=setup.reader,
            bus=sim.port_path, duration_s=setup.duration_s, panel=False,
            log=lambda text: None))
    assert setup.chase is not None and result.error is None, result.error
    served = np.array(setup.chase.log)
    wav_s = served[:, 0] - setup.reader.audio_start_s
    start = Timecode(1, 0, 0, 10).frame_number(25)
    err = np.abs(served[:, 2] * 25.0 - (r.frame_at(wav_s) - start))
    jump_s = r.stretches[1][0]
    hearing = (wav_s >= jump_s) & (wav_s < jump_s + 0.065)
    e = err[~hearing]
    print(f"play --chase-ltc on the emulated bus: served take frame against the true timecode,"
          f" {len(e)} cycles: median {np.median(e):.2f}, p99 {np.percentile(e, 99):.2f},"
          f" max {e.max():.2f} frames; {hearing.sum()} cycles while the jump was heard"
          f" (max {err[hearing].max() if hearing.any() else 0:.1f} frames);"
          f" starts/jumps/stops {setup.chase.starts}/{setup.chase.jumps}/{setup.chase.stops}")


def main() -> None:
    print(f"(load: {os.getloadavg()[0]:.1f} 1-min average on {os.cpu_count()} cores)")
    decoder_cpu()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        lock_error(folder)
        stamp_cost(folder)
        if os.environ.get("HANDRIG_BENCH_LTC_CHASE", "1") != "0":
            chase(folder)
    MonotonicClock()  # the live chase ran on the real clock


if __name__ == "__main__":
    main()
