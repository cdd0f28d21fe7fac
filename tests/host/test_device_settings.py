"""Device settings by name → the commands of protocol/spec.md §5, checked against the spec's golden vectors
and its field ranges; what cannot be read back is filled from HELLO or the firmware's defaults, and said."""

import pytest

from sphere.link.device_settings import SETTINGS, SettingError, axes_text, plan_settings
from sphere.protocol.packets import Hello
from sphere.protocol.vectors import load_vectors

VECTORS = {v.name: v for v in load_vectors()}


def _hello(**kw):
    fields = dict(protocol_version=2, firmware_version=(0, 2, 0), sensors_found=7, adxl345_devid=0xE5,
                  itg3200_whoami=0x69, hmc5883l_id=(72, 52, 51), imu_rate_hz=200, mag_rate_hz=75, stream_mode=7,
                  raw_rate_hz=200, orientation_rate_hz=100, calibration_state=0)
    for f in Hello.FIELDS[len(fields):]:
        fields[f.name] = 0
    fields.update(kw)
    return Hello(**fields)



@pytest.mark.parametrize("vector, items", [
    ("cmd_set_tap", None),
    ("cmd_set_free_fall", None),
    ("cmd_set_filter", None),
])
def test_the_spec_vectors_from_physical_values(vector, items):
    """Each host-command vector's fields, given in physical units, give the vector's packet."""
    v = VECTORS[vector]
    f = v.fields
    if vector == "cmd_set_tap":
        items = [f"tap.threshold_g={f['thresh_tap'] * 0.0625}", f"tap.duration_ms={f['dur'] * 0.625}",
                 f"tap.latency_ms={f['latent'] * 1.25}", f"tap.window_ms={f['window'] * 1.25}",
                 f"tap.axes={axes_text(f['tap_axes'])}"]
    elif vector == "cmd_set_free_fall":
        items = [f"free_fall.threshold_g={f['thresh_ff'] * 0.0625}", f"free_fall.time_ms={f['time_ff'] * 5}"]
    else:
        items = [f"filter.beta={f['beta'] / 1000}"]
    plan = plan_settings(items, _hello())
    (packet,) = plan.packets
    assert packet.NAME == v.type and packet.fields() == {k: f[k] for k in packet.fields()}
    assert plan.notes == []


def test_a_group_is_completed_from_hello_or_the_firmwares_defaults():
    plan = plan_settings(["tap.threshold_g=2.5", "stream.raw_rate_hz=50"], _hello())
    stream, tap = plan.packets
    assert (stream.NAME, stream.stream_mode, stream.raw_rate_hz, stream.orientation_rate_hz) == ("SET_STREAM", 7, 50, 100)
    assert tap.fields() == {"thresh_tap": 40, "dur": 32, "latent": 80, "window": 240, "tap_axes": 7}  # adxl345.cpp
    assert len(plan.notes) == 4 and all("firmware's default" in n for n in plan.notes)


def test_stream_off_sends_rate_zero_and_on_needs_a_rate():
    (p,) = plan_settings(["stream.orientation=off"], _hello()).packets
    assert (p.stream_mode, p.raw_rate_hz, p.orientation_rate_hz) == (0b101, 200, 0)  # spec: 0 when its bit is clear
    with pytest.raises(SettingError, match="needs stream.orientation_rate_hz"):
        plan_settings(["stream.orientation=on"], _hello(stream_mode=1, orientation_rate_hz=0))
    # a rate for a stream that is off (and stays off) would go out as 0: refused, not reported as set
    with pytest.raises(SettingError, match="stream.raw is off.*give stream.raw=on too"):
        plan_settings(["stream.raw_rate_hz=50"], _hello(stream_mode=6, raw_rate_hz=0))
    with pytest.raises(SettingError, match="stream.orientation is off"):
        plan_settings(["stream.orientation=off", "stream.orientation_rate_hz=50"], _hello())
    (p,) = plan_settings(["stream.raw=on", "stream.raw_rate_hz=50"], _hello(stream_mode=6, raw_rate_hz=0)).packets
    assert (p.stream_mode, p.raw_rate_hz) == (7, 50)


def test_board_profile():
    (p,) = plan_settings(["board=gy85"], _hello()).packets
    assert p.NAME == "SET_BOARD" and p.board_profile == 2


@pytest.mark.parametrize("item, message", [
    ("tap.threshold_g=0", "0.0625 … 15.9375 g"),
    ("tap.threshold_g=nan", "not a number"),
    ("tap.window_ms=400", "0 … 318.75 ms"),
    ("free_fall.time_ms=0", "5 … 1275 ms"),
    ("filter.beta=2.5", "0 … 2 in steps of 0.001"),
    ("stream.raw_rate_hz=30", "a divisor of 200"),
    ("stream.raw=maybe", "on or off"),
    ("tap.axes=xx", "letters from xyz"),
    ("board=uno", "one of aligned"),
    ("tap.threshold=3", "did you mean tap.threshold_g"),
    ("tap.threshold_g", "expected KEY=VALUE"),
    ("=2", "no KEY before '='"),
    ("tap.threshold_g=2.5g", "give the number alone, the key says the unit (tap.threshold_g=2.5)"),
    ("free_fall.time_ms=100 ms", "(free_fall.time_ms=100)"),
    ("stream.orientation_rate_hz=50Hz", "(stream.orientation_rate_hz=50)"),
    ("stream.orientation_rate_hz=fast", "not a whole number"),
    ("tap.threshold_g=2.5kg", "not a number"),
])
def test_bad_values_say_what_is_allowed(item, message):
    with pytest.raises(SettingError, match=None) as e:
        plan_settings([item], _hello())
    assert message in str(e.value)


def test_every_key_is_documented_with_its_range():
    for key, s in SETTINGS.items():
        assert s.doc and s.describe()


def test_the_settings_reply_vector_reads_as_every_key():
    """GET_SETTINGS's REPLY (spec §5.3 vector reply_settings) gives every key but the board; a set then keeps
    what the sphere reports instead of the firmware's defaults, and says nothing about defaults."""
    from sphere.link.device_settings import current_from_settings, settings_state_text, show
    from sphere.protocol.decoder import decode_all

    v = VECTORS["reply_settings"]
    (reply,), _ = decode_all(v.wire)
    packets, state = reply.settings()
    values = current_from_settings(packets)
    assert set(values) == set(SETTINGS) - {"board"}
    assert {k: show(k, x) for k, x in values.items()} == {
        "stream.raw": "on", "stream.orientation": "on", "stream.status": "off", "stream.raw_rate_hz": "100 Hz",
        "stream.orientation_rate_hz": "50 Hz", "tap.threshold_g": "2.5 g", "tap.duration_ms": "20 ms",
        "tap.latency_ms": "0 ms", "tap.window_ms": "0 ms", "tap.axes": "z", "free_fall.threshold_g": "0.5 g",
        "free_fall.time_ms": "200 ms", "filter.beta": "0.06"}
    assert "saved on the sphere" in settings_state_text(state)
    plan = plan_settings(["tap.threshold_g=3"], _hello(protocol_version=3), values)
    (tap,) = plan.packets
    assert (tap.thresh_tap, tap.dur, tap.latent, tap.window, tap.tap_axes) == (48, 32, 0, 0, 1)
    assert plan.notes == []


@pytest.mark.parametrize("state, words", [(2 | 4, "damaged"), (4, "nothing saved"), (0, "changed since"), (1, "saved")])
def test_settings_state_is_said(state, words):
    from sphere.link.device_settings import settings_state_text

    assert words in settings_state_text(state)


@pytest.mark.parametrize("state, words", [
    (0x31, "accelerometer and magnetometer not calibrated (none saved on the sphere: `sphere calibrate --port P` "
           "makes and saves one); gyro bias measured on the sphere [gyro_bias_valid, eeprom_invalid, gyro_bias_estimated]"),
    (0x37, "accelerometer and magnetometer calibrated, not saved on the sphere; gyro bias measured"),
    (0x0F, "accelerometer and magnetometer calibrated, loaded from the sphere's EEPROM; gyro bias set ["),
    (0x12, "accelerometer calibrated, not saved on the sphere; gyro bias not measured yet"),
])
def test_calibration_state_is_said_in_words(state, words):
    """`sphere device get`'s calibration line: what HELLO's calibration_state means (spec §4.1), then its bits; a new
    sphere's eeprom_invalid reads as 'none saved', not as a fault."""
    from sphere.commands.device import _calibration
    from sphere.protocol.packets import CALIBRATION_STATE_BITS, bit_names

    assert words in _calibration(state, bit_names(state, CALIBRATION_STATE_BITS), "P")
