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
