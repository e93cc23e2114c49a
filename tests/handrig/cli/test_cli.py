import json

from handrig.cli import main


def test_joints_json(capsys):
    assert main(["joints", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert len(out["curves"]) == 50 and len(out["wrist_dofs"]) == 4


def test_config_error_is_one_line_not_a_traceback(tmp_path, capsys):
    p = tmp_path / "bad.toml"
    p.write_text("[limits]\nriIndexPIPy = [90, 10]\n")
    assert main(["joints", "--limits", str(p)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("handrig: error:") and "Traceback" not in err
    assert "inverted limit" in err


NUMERIC_FLAGS = [
    # (command and flag, bad value, what the message says)
    (["run", "--seconds"], "nan", "finite"),
    (["run", "--seconds"], "-5", "above 0"),
    (["run", "--seconds"], "inf", "finite"),
    (["run", "--seconds"], "0", "above 0"),
    (["run", "--frames"], "0", "1 or more"),
    (["run", "--frames"], "2.5", "whole number"),
    (["demo", "--frames"], "-1", "1 or more"),
    (["demo", "--glove-rate"], "nan", "finite"),
    (["play", "x.csv", "--speed"], "0", "above 0"),
    (["play", "x.csv", "--rate"], "-60", "above 0"),
    (["bench", "bus", "--seconds"], "nan", "finite"),
    (["bench", "bus", "--servos"], "0", "1 or more"),
    (["sag", "--rotation", "0", "--inclination"], "inf", "finite"),
    (["sag", "--inclination", "0", "--rotation"], "nan", "finite"),
    (["bake", "--step-deg"], "0", "above 0"),
    (["calibrate", "glove", "--hold"], "-1", "above 0"),
    (["sim-glove", "x.csv", "--rate"], "inf", "finite"),
    (["sim-bus", "--servos"], "3.5", "whole number"),
    (["fit-map", "x.bvh", "--alpha"], "-1", "0 or more"),
    (["analyze", "x.bvh", "--fps"], "nan", "finite"),
    (["analyze", "x.bvh", "--rmsd-strict"], "-0.1", "0 or more"),
    (["evaluate", "x.bvh", "--folds"], "zero", "whole number"),
]


def test_every_numeric_flag_is_checked_and_named(capsys):
    for args, value, says in NUMERIC_FLAGS:
        assert main([*args, value]) == 2, args
        err = capsys.readouterr().err
        assert f"argument {args[-1]}: " in err and says in err, (args, value, err)


def test_numeric_flags_accept_good_values():
    from handrig.cli import build_parser

    parser = build_parser()
    args = parser.parse_args(["run", "--seconds", "1.5", "--frames", "10"])
    assert args.seconds == 1.5 and args.frames == 10
    args = parser.parse_args(["sag", "--inclination", "-90", "--rotation", "-180"])
    assert args.inclination == -90.0 and args.rotation == -180.0


def test_no_flag_takes_a_bare_float_or_int():
    """Every numeric flag goes through a check in handrig.cli._numbers."""
    import argparse

    from handrig.cli import build_parser

    def walk(parser: argparse.ArgumentParser, path: str):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    yield from walk(sub, f"{path} {name}")
            elif action.type in (float, int) and action.choices is None:
                yield f"{path} {'/'.join(action.option_strings) or action.dest}"

    assert list(walk(build_parser(), "handrig")) == []


def test_help_and_a_parse_error_return_their_status(capsys):
    assert main(["run", "--help"]) == 0
    assert "--seconds" in capsys.readouterr().out
    assert main(["run", "--seconds", "nan"]) == 2
    assert "argument --seconds: must be a finite number, got 'nan'" in capsys.readouterr().err
