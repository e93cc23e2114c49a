"""The line a run prints beside its view URL on a machine without a GPU."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from handrig.app.view.address import browser_advice, has_gpu
from handrig.realtime import cpu_split


def test_a_render_node_is_a_gpu(tmp_path: Path) -> None:
    assert not has_gpu(tmp_path)  # an empty /dev/dri
    assert not has_gpu(tmp_path / "absent")  # none at all
    (tmp_path / "card0").touch()
    assert not has_gpu(tmp_path)  # a display card without a render node
    (tmp_path / "renderD128").touch()
    assert has_gpu(tmp_path)


def test_without_a_gpu_the_advice_names_the_cpus_off_the_loops_and_the_url() -> None:
    url = "http://127.0.0.1:8765/"
    assert browser_advice(url, gpu=True) is None
    loop_cpu, others = cpu_split()
    advice = browser_advice(url, gpu=False)
    if loop_cpu is None:
        assert advice is None  # one CPU: nothing to keep apart
        return
    assert advice is not None
    assert f"taskset -c {','.join(map(str, sorted(others)))} chrt --idle 0 chromium '{url}'" \
        in advice
    assert f"CPU {loop_cpu}" in advice


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="one CPU: no advice to give")
def test_the_advised_command_runs_here(tmp_path: Path) -> None:
    """The taskset/chrt part of the advice is a command this machine takes, as any user
    may (it only lowers a process's priority and narrows its CPUs)."""
    import shlex
    import shutil
    import subprocess

    if not (shutil.which("taskset") and shutil.which("chrt")):
        pytest.skip("taskset or chrt is not installed (util-linux)")
    advice = browser_advice("http://127.0.0.1:1/", gpu=False)
    assert advice is not None
    words = shlex.split(advice.split(": ")[-1])
    assert words[:5] == ["taskset", "-c", words[2], "chrt", "--idle"]
    done = subprocess.run([*words[:6], "true"], capture_output=True, text=True, timeout=10)
    assert done.returncode == 0, done.stderr
