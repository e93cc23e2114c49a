"""A long value in an error message is cut to a line but keeps its end: a long path still
shows its file name (a show file under a deep temporary folder lost it)."""

from __future__ import annotations

from handrig.errors import ConfigError


def test_a_long_path_keeps_its_file_name_in_the_message() -> None:
    path = "/tmp/" + "deep-folder/" * 12 + "none.toml"
    err = str(ConfigError("no such file", key="--show", value=path))
    assert "none.toml" in err and "/tmp/" in err
    assert f"({len(repr(path))} characters)" in err
    assert len(err) < 120
    short = str(ConfigError("no such file", key="--show", value="/tmp/none.toml"))
    assert short == "--show '/tmp/none.toml': no such file"
