"""One rule for the default rig file (``rig_files.resolve_rig_file``): a run without
``--rig`` and ``load_rig_config()`` with no path read the same file, your ``rig.toml``
when there is one, else the shipped one (``rig_files.SHIPPED_RIG``, named once; what
benches name when they want the fixed rig)."""

from __future__ import annotations

from handrig.config.paths import user_config
from handrig.config.rig import load_rig_config
from handrig.config.rig_files import SHIPPED_RIG, resolve_rig_file


def test_the_loader_and_a_run_take_one_default_yours_else_the_shipped_one() -> None:
    mine = user_config("rig.toml")
    before = mine.read_bytes() if mine.is_file() else None  # another test's, kept
    mine.parent.mkdir(parents=True, exist_ok=True)
    try:
        mine.unlink(missing_ok=True)
        assert resolve_rig_file(None).path == SHIPPED_RIG and SHIPPED_RIG.is_file()
        assert load_rig_config().servos[0].id == 1  # without yours: the shipped one
        mine.write_text(SHIPPED_RIG.read_text().replace("[[servos]]\nid = 1\n",
                                                        "[[servos]]\nid = 200\n", 1))
        assert resolve_rig_file(None).path == mine  # a run takes yours
        assert load_rig_config().servos[0].id == 200  # and so does the loader
        assert load_rig_config(SHIPPED_RIG).servos[0].id == 1  # the fixed rig, by name
    finally:
        if before is None:
            mine.unlink(missing_ok=True)
        else:
            mine.write_bytes(before)
