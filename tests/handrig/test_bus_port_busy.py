"""A servo port in use is reported as busy: a second real ``handrig run`` on the port
a first one drives is refused before it sends a byte, and the first goes on."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sim.demo_recording import DEMO_RECORDING
from tests.helpers.emulator import SimBusProcess

CLI = [sys.executable, "-m", "handrig.cli"]


@pytest.mark.sim_bus("--no-realtime")
def test_a_second_run_on_a_busy_bus_port_is_refused_as_busy(sim_bus: SimBusProcess,
                                                            tmp_path: Path) -> None:
    port = sim_bus.port
    first: subprocess.Popen[str] | None = None
    try:
        err = tmp_path / "first.txt"
        with open(err, "w") as f:
            first = subprocess.Popen(
                [*CLI, "run", "--glove", f"replay:{DEMO_RECORDING}", "--bus", port,
                 "--seconds", "120", "--json"], stdout=subprocess.PIPE, stderr=f, text=True,
                start_new_session=True)
        deadline = time.monotonic() + 120
        while "commissioned" not in err.read_text():
            assert first.poll() is None, err.read_text()
            assert time.monotonic() < deadline
            time.sleep(0.05)
        second = subprocess.run(
            [*CLI, "run", "--glove", f"replay:{DEMO_RECORDING}", "--bus", port,
             "--seconds", "1", "--json"], capture_output=True, text=True, timeout=120)
        assert second.returncode == 2, second.stderr
        error = json.loads(second.stdout.strip().splitlines()[-1])["error"]
        assert f"servo port {port} is busy" in error, error
        assert "unplugged" not in error
        assert first.poll() is None  # the first run goes on
        first.send_signal(signal.SIGTERM)
        out, _ = first.communicate(timeout=60)
        summary = json.loads(out.strip().splitlines()[-1])
        assert first.returncode == 0 and summary["torque_off"] is True, summary.get("error")
    finally:
        if first is not None and first.poll() is None:
            first.kill()
            first.wait()
