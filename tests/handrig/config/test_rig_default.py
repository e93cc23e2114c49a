"""The shipped rig is named in one place (``rig_files.SHIPPED_RIG``): the run's default
when you have no ``rig.toml``, and what ``load_rig_config()`` with no path loads, your
``rig.toml`` or not (benches and tests load a fixed rig)."""

from __future__ import annotations

from handrig.config.loading import load
from handrig.config.paths import user_config
from handrig.config.rig import RigConfig, load_rig_config
from handrig.config.rig_files import SHIPPED_RIG, resolve_rig_file


def test_the_shipped_rig_is_the_default_without_yours_and_what_the_loader_loads() -> None:
    mine = user_config("rig.toml")
    before = mine.read_bytes() if mine.is_file() else None  # another test's, kept
    mine.parent.mkdir(parents=True, exist_ok=True)
    try:
        mine.unlink(missing_ok=True)
        assert resolve_rig_file(None).path == SHIPPED_RIG and SHIPPED_RIG.is_file()
        mine.write_text(SHIPPED_RIG.read_text().replace("[[servos]]\nid = 1\n",
                                                        "[[servos]]\nid = 200\n", 1))
        assert resolve_rig_file(None).path == mine  # a run takes yours
        assert load(mine, RigConfig).servos[0].id == 200
        assert load_rig_config().servos[0].id == 1  # the loader: the shipped one
    finally:
        if before is None:
            mine.unlink(missing_ok=True)
        else:
            mine.write_bytes(before)
