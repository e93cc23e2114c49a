import pytest

from handrig.config.loading import build
from handrig.config.rig import RigConfig, ServoCalibration, load_rig_config
from handrig.devices.servo.models import check_rig
from handrig.devices.servo.positions import deg_to_ticks, ticks_to_deg
from handrig.errors import ConfigError


def test_shipped_rig_has_twenty_servos():
    rig = load_rig_config()
    assert len(rig.servos) == 20
    assert rig.servo(7).joint == "riIndexMCPy"


@pytest.mark.parametrize("direction", [1, -1])
@pytest.mark.parametrize("gear", [1.0, 2.5])
def test_degrees_to_ticks_and_back_with_signs(direction, gear):
    s = ServoCalibration(id=1, joint="riIndexPIPy", zero_ticks=2000, direction=direction,
                         gear_ratio=gear, min_deg=0.0, max_deg=60.0)
    s.check()
    assert deg_to_ticks(s, 0.0) == 2000
    t = deg_to_ticks(s, 45.0)
    assert t == 2000 + direction * round(45.0 * gear * 4096 / 360)
    assert ticks_to_deg(s, t) == pytest.approx(45.0, abs=360 / 4096 / gear)
    # Outside the limits: clamped before conversion, whatever the caller asks
    assert deg_to_ticks(s, 500.0) == deg_to_ticks(s, 60.0)
    assert deg_to_ticks(s, -30.0) == deg_to_ticks(s, 0.0)


def test_bad_servo_entries_are_named():
    with pytest.raises(ConfigError, match=r"servos\[1\].id.*used twice"):
        build(RigConfig, {"servos": [{"id": 1, "joint": "riIndexPIPy", "min_deg": 0},
                                     {"id": 1, "joint": "riRingPIPy", "min_deg": 0}]})
    with pytest.raises(ConfigError, match=r"servos\[0\].min_deg.*inverted"):
        build(RigConfig, {"servos": [{"id": 1, "joint": "riIndexPIPy",
                                      "min_deg": 50, "max_deg": 10}]})
    with pytest.raises(ConfigError, match=r"servos\[0\].joint.*unknown joint"):
        build(RigConfig, {"servos": [{"id": 1, "joint": "riIndexPIP"}]})
    one = [{"id": 1, "joint": "riIndexPIPy", "min_deg": 0}]
    with pytest.raises(ConfigError, match=r"bus.baud.*allowed"):  # which bauds: the driver's
        check_rig(build(RigConfig, {"servos": one, "bus": {"baud": 4_500_000}}))
    with pytest.raises(ConfigError, match=r"bus.baud.*positive"):
        build(RigConfig, {"bus": {"baud": 0}})
    # what a tick is, and which IDs a bus takes, is the driver's to check
    far = build(RigConfig, {"servos": [{"id": 1, "joint": "riIndexPIPy", "min_deg": 0,
                                        "gear_ratio": 10.0}]})
    with pytest.raises(ConfigError, match=r"servos\[0\]\.max_deg.*outside the servo's range"):
        check_rig(far, "rig.toml")
    for key, value, msg in (("zero_ticks", 4096, "zero outside the position range"),
                            ("id", 253, "servo ID out of range")):
        bad = build(RigConfig, {"servos": [{**one[0], key: value}]})
        with pytest.raises(ConfigError, match=rf"rig.toml.*servos\[0\]\.{key}.*{msg}"):
            check_rig(bad, "rig.toml")
    with pytest.raises(ConfigError, match=r"servos\[0\]\.id.*out of range"):
        build(RigConfig, {"servos": [{**one[0], "id": -1}]})


def test_silence_tiers_are_read_and_checked():
    servos = [{"id": 1, "joint": "riIndexPIPy", "min_deg": 0.0, "max_deg": 90.0}]
    rig = build(RigConfig, {"servos": servos, "silence": {"action": "relax", "action_s": 2.0}})
    assert rig.silence.action == "relax" and rig.silence.action_s == 2.0
    assert load_rig_config().silence.action == "continue"
    with pytest.raises(ConfigError, match="tiers out of order"):
        build(RigConfig, {"servos": servos, "silence": {"warn_s": 2.0}})
    with pytest.raises(ConfigError, match=r"silence\.action"):
        build(RigConfig, {"servos": servos, "silence": {"action": "panic"}})
    with pytest.raises(ConfigError, match="out of range"):
        build(RigConfig, {"servos": servos, "silence": {"warn_s": 0.0}})


def test_heat_tiers_are_read_and_bounded_with_messages():
    servos = [{"id": 1, "joint": "riIndexPIPy", "min_deg": 0.0, "max_deg": 90.0}]
    shipped = load_rig_config().heat
    assert (shipped.warn_c, shipped.act_c, shipped.action_c) == (55.0, 60.0, 65.0)
    assert shipped.action == "relax" and shipped.relief_pwm_pct == 50.0
    rig = build(RigConfig, {"servos": servos, "heat": {"action": "stop", "warn_c": 45.0}})
    assert rig.heat.action == "stop" and rig.heat.warn_c == 45.0
    with pytest.raises(ConfigError, match=r"heat\.act_c.*tiers out of order"):
        build(RigConfig, {"servos": servos, "heat": {"warn_c": 62.0}})
    with pytest.raises(ConfigError, match=r"heat\.warn_c.*out of range.*35\.\.95"):
        build(RigConfig, {"servos": servos, "heat": {"warn_c": 20.0}})
    with pytest.raises(ConfigError, match=r"heat\.relief_pwm_pct.*10\.\.100"):
        build(RigConfig, {"servos": servos, "heat": {"relief_pwm_pct": 5.0}})
    with pytest.raises(ConfigError, match=r"heat\.action.*'continue', 'relax', 'stop'"):
        build(RigConfig, {"servos": servos, "heat": {"action": "panic"}})
    # the action comes before the servo's own Temperature Limit (the driver checks the
    # rig against its models): 70 C on an XL330 (the default model) ...
    with pytest.raises(ConfigError, match=r"servo 1's \(XL330-M288\) Temperature Limit of 70"):
        check_rig(build(RigConfig, {"servos": servos, "heat": {"action_c": 72.0}}))
    # ... 80 C on an XM430
    xm = [{**servos[0], "model": "XM430-W350"}]
    rig = build(RigConfig, {"servos": xm, "heat": {"action_c": 75.0}})
    check_rig(rig)
    assert rig.heat.action_c == 75.0
    with pytest.raises(ConfigError, match=r"servos\[0\]\.model.*XL330-M288"):
        check_rig(build(RigConfig, {"servos": [{**servos[0], "model": "AX-12A"}]}))


def test_loop_mode_and_its_rates_are_checked():
    servo = [{"id": 1, "joint": "riIndexPIPy", "min_deg": 0}]
    assert load_rig_config().loop.mode == "glove"
    cfg = build(RigConfig, {"servos": servo, "loop": {"mode": "fixed", "floor_hz": 50.0,
                                                       "ceiling_hz": 800.0}})
    assert (cfg.loop.mode, cfg.loop.floor_hz, cfg.loop.ceiling_hz) == ("fixed", 50.0, 800.0)
    with pytest.raises(ConfigError, match=r"loop.mode"):
        build(RigConfig, {"servos": servo, "loop": {"mode": "fast"}})
    with pytest.raises(ConfigError, match=r"loop.floor_hz.*out of range"):
        build(RigConfig, {"servos": servo, "loop": {"floor_hz": 1.0}})
    with pytest.raises(ConfigError, match=r"loop.ceiling_hz.*out of range"):
        build(RigConfig, {"servos": servo, "loop": {"floor_hz": 200.0, "ceiling_hz": 100.0}})


def test_read_parts_shipped_and_checked() -> None:
    servo = [{"id": 1, "joint": "riIndexPIPy", "min_deg": 0}]
    assert load_rig_config().bus.read_parts == 2  # the shipped rig: half the servos a read
    assert build(RigConfig, {"servos": servo, "bus": {"read_parts": 2}}).bus.read_parts == 2
    with pytest.raises(ConfigError, match=r"bus.read_parts.*out of range"):
        build(RigConfig, {"servos": servo, "bus": {"read_parts": 9}})
