"""The command line builds only the parser of the command it was given.

``handrig.cli.COMMANDS`` stands in for the modules of the commands not given (their
name and help line); these tests hold it to what the modules register, check that the
lazily built parser reads exactly as the full one (help and errors), and that
``handrig --help`` imports none of the heavy packages a run needs.
"""

from __future__ import annotations

import argparse
import importlib
import subprocess
import sys

import pytest

from handrig import cli

HEAVY = ("mujoco", "numba", "scipy", "dynamixel_sdk")


def _subparsers(parser: argparse.ArgumentParser) -> argparse._SubParsersAction:
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))


def test_the_table_is_what_the_modules_register() -> None:
    registered_by: dict[str, list[str]] = {}
    for module in cli.command_modules():  # each alone: the commands it adds to
        parser = argparse.ArgumentParser(prog="handrig")
        sub = parser.add_subparsers(dest="command")
        importlib.import_module(f"handrig.cli.{module}").register(sub)
        for name in sub.choices:
            registered_by.setdefault(name, []).append(module)
    helps = {a.dest: a.help for a in _subparsers(cli.build_parser())._choices_actions}
    assert list(helps) == list(cli.COMMANDS)
    assert {n: h for n, (h, _) in cli.COMMANDS.items()} == helps
    assert {n: list(m) for n, (_, m) in cli.COMMANDS.items()} == registered_by
    assert registered_by["calibrate"] == ["calibrate_glove", "calibrate_servos"]


@pytest.mark.parametrize("command", [None, "nope", *cli.COMMANDS])
def test_lazy_parser_reads_as_the_full_one(command: str | None) -> None:
    full = cli.build_parser()
    lazy = cli.build_parser(command, full=False)
    assert lazy.format_help() == full.format_help()
    if command in cli.COMMANDS:
        assert (_subparsers(lazy).choices[command].format_help()
                == _subparsers(full).choices[command].format_help())


@pytest.mark.parametrize("argv", [
    ["demo", "--bogus"], ["--bogus", "demo"], ["nope"], ["-5", "demo"],
    ["--", "demo", "--frames", "x"], ["calibrate", "servos", "--bogus"],
    ["servos", "scan", "--baud", "x"], ["run", "--seconds", "nan"]])
def test_errors_read_as_with_the_full_parser(argv: list[str], capsys) -> None:
    lazy = cli.build_parser(cli.command_in(argv), full=False)
    with pytest.raises(SystemExit) as lazy_exit:
        lazy.parse_args(argv)
    lazy_err = capsys.readouterr().err
    with pytest.raises(SystemExit) as full_exit:
        cli.build_parser().parse_args(argv)
    assert lazy_exit.value.code == full_exit.value.code == 2
    assert lazy_err == capsys.readouterr().err
    assert "error:" in lazy_err


def test_command_in() -> None:
    assert cli.command_in(["--version"]) is None
    assert cli.command_in(["-h", "demo", "--frames", "1"]) == "demo"
    assert cli.command_in(["--", "sim-bus"]) == "sim-bus"
    assert cli.command_in(["nope", "demo"]) is None


# the emulators a simulated rig starts: what they import before their run (MuJoCo for
# sim-bus's puppet) is their own, the parser imports none of it
@pytest.mark.parametrize("argv", [["--help"], ["joints", "--json"], [],
                                  ["sim-bus", "--help"], ["sim-glove", "--help"]])
def test_light_commands_import_no_heavy_package(argv: list[str]) -> None:
    code = ("import sys, contextlib, io\n"
            "from handrig.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            f"    status = main({argv!r})\n"
            f"print(status, sorted(m for m in {HEAVY!r} if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split(None, 1) == ["0", "[]\n"], out.stdout + out.stderr


def test_a_heavy_command_still_gets_its_modules() -> None:
    """The guard above can fail: ``demo --help`` does import numba (through the driver)."""
    code = ("import sys, contextlib, io\n"
            "from handrig.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    status = main(['demo', '--help'])\n"
            "print(status, 'numba' in sys.modules, 'handrig.cli.demo' in sys.modules,"
            " 'handrig.cli.calibrate_glove' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60)
    assert out.stdout.split() == ["0", "True", "True", "False"], out.stdout + out.stderr
