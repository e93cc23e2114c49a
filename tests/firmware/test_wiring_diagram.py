"""firmware/wiring.svg is what firmware/tools/wiring_diagram.py draws, and its pins are
the firmware's (firmware/glove/glove_config.h)."""

from __future__ import annotations

import importlib.util
import re
import xml.dom.minidom
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def load_tool():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location(
        "wiring_diagram", ROOT / "firmware" / "tools" / "wiring_diagram.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_committed_diagram_is_the_drawn_one_with_the_firmware_pins():
    tool = load_tool()
    svg = tool.draw()
    assert (ROOT / "firmware" / "wiring.svg").read_text(encoding="utf-8") == svg, (
        "firmware/wiring.svg is stale: run python firmware/tools/wiring_diagram.py")
    xml.dom.minidom.parseString(svg)
    config = (ROOT / "firmware" / "glove" / "glove_config.h").read_text()
    inputs = re.search(r"#define GLOVE_ADC_INPUTS \{([^}]*)\}", config)
    assert inputs is not None
    assert [f"A{int(v)}" for v in inputs.group(1).split(",")] == [p for _, _, p, _ in tool.SENSORS]
    assert "#define GLOVE_BUTTON_PIN 2" in config and "#define GLOVE_LED_PIN 13" in config
    assert "#define GLOVE_TEST_POINT_PIN 8" in config and "#define GLOVE_IMU_ADDR 0x28" in config
