"""``python -m bench.compare``: two sides' bench outputs merged line by line."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from bench.compare import merge, skeleton

ROOT = Path(__file__).resolve().parents[2]


def test_numbers_are_cut_out_of_a_line_as_printed() -> None:
    shape, numbers = skeleton("expand one frame, 10 controls: median 3.28 us, p99 1e-05")
    assert numbers == ["10", "3.28", "99", "1e-05"]
    assert shape == "expand one frame, \0 controls: median \0 us, p\0 \0"


def test_numbers_that_differ_become_base_to_new_medians() -> None:
    base = ["median 3.00 us (20 servos)\n", "median 5.00 us (20 servos)\n",
            "median 4.00 us (20 servos)\n"]
    new = ["median 1.20 us (20 servos)\n", "median 1.40 us (20 servos)\n",
           "median 1.30 us (20 servos)\n"]
    assert merge(base, new) == ["median 4.00->1.30 us (20 servos)"]


def test_a_number_that_agrees_everywhere_is_printed_once() -> None:
    assert merge(["a 1 b 2.5"], ["a 1 b 2.7"]) == ["a 1 b 2.5->2.7"]


def test_lines_whose_words_differ_are_printed_for_each_side() -> None:
    assert merge(["cycle 0.81 of the wire limit\ndone"],
                 ["cycle 0.83 of the wire limit, 3 retries\ndone"]) == [
        "base: cycle 0.81 of the wire limit",
        "new:  cycle 0.83 of the wire limit, 3 retries", "done"]


def test_a_line_only_one_side_printed_is_marked_with_its_side() -> None:
    assert merge(["x 1\nextra 2"], ["x 1"]) == ["x 1", "base: extra 2"]


def test_a_base_that_is_not_a_commit_is_refused() -> None:
    out = subprocess.run([sys.executable, "-m", "bench.compare", "--base", "no-such-rev",
                          "--benches", "expand"], cwd=ROOT, capture_output=True, text=True)
    assert out.returncode != 0
    assert "is not a commit here" in out.stderr


def test_a_table_row_whose_column_padding_differs_is_still_merged() -> None:
    assert merge(["handrig cycle    618     0.49       9"],
                 ["handrig cycle    451     0.36      54"]) == [
        "handrig cycle    618->451     0.49->0.36       9->54"]


def test_each_rounds_values_on_request() -> None:
    assert merge(["t 1.0", "t 3.0"], ["t 2.0", "t 2.0"], each=True) == ["t 1.0,3.0->2.0"]
