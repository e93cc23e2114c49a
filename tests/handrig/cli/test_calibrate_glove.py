"""`handrig calibrate glove --yes` against the pty glove emulator."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pytest

from handrig.cli import calibrate_glove
from handrig.cli.calibrate_glove import derive
from handrig.devices.glove_calibration import CALIBRATION_STEPS, load_glove_config
from handrig.devices.glove_recording import GloveRecording
from handrig.errors import DataError, HandrigError
from sim.glove_emulator import GloveEmulator


def main(argv: list[str]) -> int:
    """The CLI's contract for this one command: HandrigError -> one line, status 2."""
    parser = argparse.ArgumentParser(prog="handrig")
    calibrate_glove.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except HandrigError as exc:
        print(f"handrig: error: {exc}", file=sys.stderr)
        return 2


SETTLE_S, HOLD_S = 0.3, 0.5  # generous: the emulator thread and the command share this process
POSES = {  # raw counts per step; channel 1 (thumb CMC abduction) reads lower when closed
    "open": [1000, 3000, 1000, 1000, 1000],
    "fist": [2500, 1200, 2600, 3100, 3000],
    "thumb-oppose": [3000, 1500, 2900, 1500, 1500],
    "thumb-spread": [1500, 3500, 1500, 1100, 1100],
}


def posed_recording(poses: dict[str, list[int]], rate_hz: float = 200.0) -> GloveRecording:
    step_s = SETTLE_S + HOLD_S
    n_step = round(step_s * rate_hz)
    rows = [poses[name] for name, _ in CALIBRATION_STEPS for _ in range(n_step)]
    rows += [poses[CALIBRATION_STEPS[-1][0]]] * n_step  # hold the last pose a little longer
    n = len(rows)
    return GloveRecording(np.arange(n) / rate_hz, np.array(rows, dtype=float),
                          np.zeros(n, dtype=np.int64), tuple(f"ch{i}" for i in range(5)),
                          None, rate_hz)


def run_calibration(tmp_path: Path, poses: dict[str, list[int]]) -> tuple[int, Path]:
    out = tmp_path / "glove.toml"
    with GloveEmulator(posed_recording(poses), "frames") as emu:
        status = main(["calibrate", "glove", "--glove", emu.port_path, "--yes",
                       "--settle", str(SETTLE_S), "--hold", str(HOLD_S), "--out", str(out)])
    return status, out


def test_guided_calibration_writes_the_measured_ranges(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    status, out = run_calibration(tmp_path, POSES)
    text = capsys.readouterr().out
    assert status == 0, text
    assert "Open hand" in text and f"wrote {out}" in text
    cfg = load_glove_config(out)
    got = {c.curve: (c.raw_open, c.raw_closed) for c in cfg.channels}
    assert got == {
        "riThumbCMCx": (1000, 3000),  # largest in its closing direction: thumb opposition
        "riThumbCMCy": (3000, 1200),  # reversed sensor stays reversed: fist, not the spread
        "riThumbCMCz": (1000, 2900),
        "riIndexMCPy": (1000, 3100),
        "riPinkyMCPy": (1000, 3000),
    }
    default = load_glove_config()
    assert [c.open_deg for c in cfg.channels] == [c.open_deg for c in default.channels]
    assert cfg.glove.port == default.glove.port  # a pty (/dev/pts/N) is never saved
    assert "not saved: a pseudo-terminal" in text
    assert cfg.filter == default.filter


def test_a_calibrated_glove_file_keeps_the_shipped_comments_and_layout(
        tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    from handrig.config.paths import installed_config

    status, out = run_calibration(tmp_path, POSES)
    assert status == 0, capsys.readouterr().err
    shipped = installed_config("glove.toml").read_text().splitlines()
    written = out.read_text().splitlines()
    assert len(written) == len(shipped)
    changed = [(a, b) for a, b in zip(shipped, written, strict=True) if a != b]
    # only raw_open / raw_closed lines differ; every comment line and layout line stays
    assert changed and all(b.split("=")[0].strip() in ("raw_open", "raw_closed")
                           for _, b in changed), changed
    for a, b in changed:
        if "#" in a:
            assert a[a.index("#"):] == b[b.index("#"):]


def test_calibration_writes_keep_a_backup_and_undo_restores_the_last(
        tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "glove.toml"
    out.write_text("# mine\n" + load_text())
    before = out.read_bytes()
    status, _ = run_calibration(tmp_path, POSES)
    assert status == 0 and out.read_bytes() != before
    assert (tmp_path / "backups").is_dir()
    from handrig.config.toml_edit import undo

    assert "restored" in undo(out)
    assert out.read_bytes() == before


def load_text() -> str:
    from handrig.config.paths import installed_config

    return installed_config("glove.toml").read_text()


def test_a_sensor_that_does_not_move_is_refused(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    dead = {k: [v[0], v[1], v[2], 1000, v[4]] for k, v in POSES.items()}
    status, out = run_calibration(tmp_path, dead)
    assert status == 2 and not out.exists()
    assert "riIndexMCPy, raw channel 3) barely moved" in capsys.readouterr().err


def test_derive_is_pure() -> None:
    cfg = load_glove_config()
    medians = {k: np.array(v, dtype=float) for k, v in POSES.items()}
    new, report = derive(cfg, medians, 4095.0)
    assert len(report) == 5 and new.channels[3].raw_closed == 3100
    with pytest.raises(DataError, match="sends 3"):
        derive(cfg, {k: v[:3] for k, v in medians.items()}, 4095.0)


def test_no_port_is_a_clear_error(capsys) -> None:  # type: ignore[no-untyped-def]
    assert main(["calibrate", "glove", "--yes"]) == 2
    assert "no glove port: pass --glove PORT" in capsys.readouterr().err
