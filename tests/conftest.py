"""Shared fixtures, and the test session's own home.

The user's home is never read: before any test module is imported or any fixture
of any scope runs, ``pytest_configure`` points ``HOME`` and the XDG directories at
a temporary folder for the whole session (so a module- or session-scoped fixture
that loads a default file gets the installed one, not a calibrated glove.toml or a
baked grid of the developer's); every test then gets empty ones of its own.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from hypothesis import settings

from tests.helpers.emulator import SimBusProcess, start_sim_bus

# No per-example deadline: a property test checks what the code computes, not how
# fast; on a loaded 2-core CI machine one example took 0.9 s against the default
# 0.2 s deadline and failed the run. Speed is measured by the benchmarks.
settings.register_profile("handrig", deadline=None)
settings.load_profile("handrig")

SESSION_HOME_VARS = ("HOME", "XDG_CONFIG_HOME", "XDG_DATA_HOME", "XDG_CACHE_HOME",
                     "XDG_STATE_HOME")
_saved_env: dict[str, str | None] = {}
_session_home: list[str] = []


def pytest_configure(config: pytest.Config) -> None:
    home = tempfile.mkdtemp(prefix="handrig-test-home-")
    _session_home.append(home)
    for var in SESSION_HOME_VARS:
        _saved_env[var] = os.environ.get(var)
    os.environ["HOME"] = home
    os.environ["XDG_CONFIG_HOME"] = os.path.join(home, ".config")
    os.environ["XDG_DATA_HOME"] = os.path.join(home, ".local", "share")
    os.environ["XDG_CACHE_HOME"] = os.path.join(home, ".cache")
    os.environ["XDG_STATE_HOME"] = os.path.join(home, ".local", "state")
    # no host-wide CPU latency request from the tests' runs (CI runs as root): the
    # request's writes are tested on a pipe (tests/handrig/loop/test_keep_cpus_awake.py)
    os.environ["HANDRIG_CPU_LATENCY_DEVICE"] = ""


def pytest_unconfigure(config: pytest.Config) -> None:
    for var, value in _saved_env.items():
        if value is None:
            os.environ.pop(var, None)
        else:
            os.environ[var] = value
    for home in _session_home:
        shutil.rmtree(home, ignore_errors=True)

SPEC = Path(__file__).resolve().parents[1] / "firmware_protocol" / "SPEC.md"

# `make test` runs the suite as three pytest processes side by side (see the Makefile):
# - `-m compute_only`: the tests below only compute (maps, sag, baking, rendering,
#   parsing, compiling) or start a command that keeps no time; they run at the lowest
#   CPU priority (nice 19), on what the other two leave;
# - `-m patient`, two at a time at nice 10: end-to-end tests against the emulators whose checks
#   hold on a busy machine: they check what was found, written, commissioned or recorded
#   and wait for conditions, not for a time (PATIENT below);
# - the rest (`-m "not compute_only and not patient"`): realtime loops whose checks are
#   about time (rates, latency, frames skipped or lost, the emulated glove chip keeping
#   its clock), one at a time.
# A plain `pytest` runs all of them one after the other. (Two realtime tests at once,
# pytest-xdist's `-n 2`, was tried: the emulated AVR glove fell to 163 Hz of its 200.)
COMPUTE_ONLY = (
    "handrig/pose/", "handrig/offline/", "handrig/config/", "firmware_protocol/",
    "firmware/", "sim/test_bake.py", "sim/test_bake_plot_state.py", "sim/test_passive.py",
    "sim/test_hand_model.py", "sim/test_render.py", "sim/test_calibration_motion.py",
    "sim/test_dxl_servo.py", "sim/test_dxl_fast_paths.py", "sim/test_dxl_compiled.py",
    "test_user_home.py", "test_layers.py",
    "handrig/app/test_demo_render.py", "handrig/cli/test_sag_commands.py",
    "handrig/cli/test_cli_startup.py", "handrig/app/view/test_view_advice.py",
    "handrig/devices/test_glove_channel_indices.py", "handrig/test_bounded_inputs.py",
    "sim/test_retarget_fit.py", "handrig/cli/test_retarget_fit_command.py",
    "sim/test_leap_pinch.py",
    "handrig/loop/test_rig_settings.py", "handrig/loop/test_layer_mixer.py",
    "test_boundaries.py", "handrig/app/test_second_vendor_session.py",
    "handrig/cli/test_first_hour_messages.py", "sim/test_openxr_model_agrees.py",
    "handrig/outputs/test_openxr_output.py",
    "sim/test_robot_gravity_emulated.py",
    "handrig/app/lerobot/test_frame_grid.py", "handrig/app/lerobot/test_plugin_layers.py",
    "handrig/app/lerobot/test_plugin_extra.py",
    "handrig/app/lerobot/test_frame_grid_early.py::test_calls_faster_than_the_grid_",
    "handrig/app/cues/test_cue_parsing.py", "handrig/app/cues/test_cue_show.py",
    "handrig/app/test_layers_shown.py", "handrig/app/test_output_contract.py",
    "handrig/devices/test_ltc",
    # these compute too and ran in the realtime process: codecs, stats, tables, modes
    "handrig/devices/servo/test_servo_codec.py", "handrig/devices/servo/test_servo_registers.py",
    "handrig/loop/test_stats.py", "handrig/loop/test_rings.py", "handrig/loop/test_modes.py",
    "handrig/loop/test_easing.py", "handrig/loop/test_warm_up.py",
    "handrig/loop/test_warm_up_wake.py", "handrig/loop/test_keep_cpus_awake.py",
    "handrig/loop/test_silence_stopped.py", "handrig/devices/servo/test_host_timeouts.py",
    "handrig/test_hand.py", "handrig/devices/test_glove_status.py",
    "handrig/outputs/test_glove_take.py", "handrig/app/test_robotrig.py", "sim/test_wrist_load.py",
    "handrig/outputs/test_take_frames_beyond_header.py", "handrig/test_error_values_shown.py",
    "bench/test_bench_skips.py", "handrig/app/test_panel_recording.py",
    "handrig/cli/test_servos_scan_default.py",
    "handrig/cli/test_calibrate_servos_any_vendor.py",
    "handrig/devices/servo/test_fault_vocabulary.py",
    "handrig/app/test_setup_any_vendor.py", "handrig/test_short_slice.py",
    "handrig/devices/servo/test_host_pressure.py", "handrig/devices/servo/test_held_replies.py",
    "handrig/app/test_panel_host_timeouts.py",
    "handrig/devices/servo/test_reboot_return_delay.py",
)
# Tests that start handrig's commands (imports, argument and file checks, help texts, a
# take's repair) but no loop, no emulator and no glove: nothing in them keeps time, so
# they run beside the realtime tests with the compute-only ones, one core between them.
NO_LOOP = (
    "handrig/app/test_run_messages.py", "bench/test_bench_help.py",
    "handrig/test_corrupt_files.py", "handrig/outputs/test_take_damage.py",
    "handrig/cli/test_retarget_command.py", "handrig/cli/test_cli.py",
    # the ORCA preset's file and model checks and `retarget check` (its demos are realtime)
    "sim/test_orca_preset.py::test_the_", "sim/test_orca_preset.py::test_retarget_check_",
)
# End-to-end tests whose checks hold on a busy machine (nothing in them measures time).
PATIENT = (
    # LeRobot's record and replay stamp frames on LeRobot's own grid and compare values;
    # most of their time is LeRobot's and torch's imports
    "handrig/app/lerobot/test_lerobot_record.py", "handrig/app/lerobot/test_lerobot_readme.py",
    # bring-up and commissioning commands against the emulator: they check what was
    # found, written and commissioned, and wait for conditions, not for a time
    "handrig/cli/test_servos_command.py", "handrig/cli/test_setup_command.py",
    "handrig/cli/test_calibrate_servos.py", "handrig/cli/test_calibrate_servos_pty.py",
    "handrig/cli/test_calibrate_glove_session.py", "handrig/cli/test_files_in_use.py",
    "handrig/cli/test_calibrate_glove_imu.py",
    "handrig/cli/test_simulated_says_so.py", "handrig/test_servo_missing_at_start.py",
    "handrig/test_servo_readmitted.py", "handrig/test_heat_live.py",
    "handrig/test_glove_faults_live.py", "handrig/test_readme_takes.py",
    "handrig/test_spec_glove_drives_rig.py", "bench/test_bench_startup.py",
    "sim/test_orca_core_client.py",
    # the robot API's blocks (torque, signals, moves) and the presets' demos, whose
    # tracking bound holds at load 11 (tests/sim/test_orca_preset.py)
    "handrig/app/test_robot_api.py", "handrig/app/test_robot_api_moves.py",
    "handrig/app/test_robot_api_signals.py",
    "sim/test_orca_preset.py",
    "handrig/app/lerobot/test_lerobot_teleoperate.py",
    "handrig/app/test_robot_gravity_live.py",
    # silences, restarts, unplugged gloves and ports in use, named and recovered from:
    # the checks are the events and the summary's counts, each waited for
    "handrig/test_one_silent_servo.py", "handrig/test_reboot_events.py",
    "handrig/devices/test_glove_comes_back.py", "handrig/test_bus_port_busy.py",
    # the panel's keys, layers, the view's server, OpenXR and two hands' summaries
    "handrig/app/test_show_keys.py", "handrig/app/test_layering_live.py",
    "handrig/app/view/test_view_server.py", "handrig/app/test_openxr_live.py",
    "handrig/app/test_hands_summary.py",
    # live runs inside folders that compute (the longest entry wins: lane_of): a show
    # and the demo on the emulated bus, their checks what was run, counted and written
    "handrig/config/test_show.py::test_run_show_starts_",
    "handrig/app/test_demo_render.py::test_demo_render_",
)
TESTS = Path(__file__).resolve().parent


@pytest.hookimpl(tryfirst=True)  # before `-m` selects by the markers
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        rel = item.path.resolve().relative_to(TESTS).as_posix()
        lane = lane_of(f"{rel}::{item.name}")
        if lane == "compute_only":
            item.add_marker(pytest.mark.compute_only)
        elif lane == "patient":
            item.add_marker(pytest.mark.patient)


def lane_of(name: str) -> str:
    """The lane of a test (``path::name`` under tests/): the list with the longest entry
    it starts with, so a file or test named in one list wins over its directory in
    another (``handrig/config/`` computes, its ``test_show.py::test_run_show_`` runs a
    show on the emulated bus); "realtime" when no list names it."""
    lanes = (("compute_only", COMPUTE_ONLY + NO_LOOP), ("patient", PATIENT))
    best, lane = -1, "realtime"
    for candidate, entries in lanes:
        for entry in entries:
            if name.startswith(entry) and len(entry) > best:
                best, lane = len(entry), candidate
    return lane



@pytest.fixture
def sim_bus(request: pytest.FixtureRequest) -> Iterator[SimBusProcess]:
    """The bus emulator in a process of its own (:mod:`tests.helpers.emulator`), with the
    flags of the test's ``@pytest.mark.sim_bus(...)`` (none: the MuJoCo puppet, the
    realtime priority it asks for, no wire timing); ``stderr=subprocess.PIPE`` in the
    marker's keywords keeps what it says for the test to read."""
    marker = request.node.get_closest_marker("sim_bus")
    flags = tuple(marker.args) if marker else ()
    stderr = marker.kwargs.get("stderr", subprocess.DEVNULL) if marker else subprocess.DEVNULL
    with start_sim_bus(*flags, stderr=stderr) as bus:
        yield bus


@pytest.fixture(scope="session")
def build_spec_c(tmp_path_factory: pytest.TempPathFactory) -> Callable[..., Path]:
    """Compile the C code blocks of firmware_protocol/SPEC.md with a given ``main``,
    as a firmware author would (``posix=True`` for a host program that sleeps and
    writes to a file descriptor); skips the test where no C compiler is installed."""
    cc = shutil.which("cc") or shutil.which("gcc")

    def build(main: str, name: str, posix: bool = False) -> Path:
        if cc is None:
            pytest.skip("no C compiler on this machine")
        blocks = re.findall(r"```c\n(.*?)```", SPEC.read_text(), flags=re.S)
        assert len(blocks) == 3  # cobs_encode, crc16_ccitt_false, glove_frame_build
        prelude = "#define _POSIX_C_SOURCE 200809L\n" if posix else ""
        src = prelude + "#include <stdint.h>\n#include <stddef.h>\n" + "\n".join(blocks) + main
        d = tmp_path_factory.mktemp(name)
        (d / f"{name}.c").write_text(src)
        exe = d / name
        subprocess.run([cc, "-std=c99", "-Wall", "-Werror", "-O1", "-o", str(exe),
                        str(d / f"{name}.c")], check=True, capture_output=True)
        return exe

    return build


@pytest.fixture(autouse=True)
def _user_dirs(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every test (and the commands it starts) gets empty XDG config and data dirs: a
    calibrated glove.toml or baked grid in the developer's home is never read."""
    base = tmp_path_factory.mktemp("xdg")
    monkeypatch.setenv("XDG_CONFIG_HOME", str(base / "config"))
    monkeypatch.setenv("XDG_DATA_HOME", str(base / "data"))
