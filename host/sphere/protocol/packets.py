"""Packet types of protocol/spec.md §4–§5, defined once from a table of fields.

Each packet is a small class whose attributes are the spec's field names holding the integers as they
travel on the wire (arrays as tuples). ``to_json()`` gives the physical values the spec defines.
"""

from __future__ import annotations

import enum
import struct
from typing import ClassVar

from sphere import chips

PROTOCOL_VERSION = 3
# Versions this host decodes: version 2 only appended fields to HELLO and STATUS (a version-1 body is
# their prefix; the new fields then read as their defaults) and added flags and SET_BOARD; version 3 only
# added commands (SET_BAUD, ECHO, the settings commands) and REPLY data for two of them.
SUPPORTED_VERSIONS = (1, 2, 3)
#: SET_BAUD's rates (spec §5.4): the default, and the rates exact on the Nano's 16 MHz
DEFAULT_BAUD = 115200
FAST_BAUDS = (250000, 500000, 1000000)

Q14 = 16384.0


class Result(enum.IntEnum):
    """REPLY result codes (spec §5.1)."""

    OK = 0
    UNKNOWN_COMMAND = 1
    BAD_LENGTH = 2
    BAD_VALUE = 3
    BUSY = 4
    SENSOR_MISSING = 5
    STORAGE_ERROR = 6
    FAILED = 7


EVENT_NAMES = {1: "single_tap", 2: "double_tap", 3: "free_fall"}
CALIBRATION_STEPS = {0: "none", 1: "gyro_bias", 2: "accel", 3: "mag"}

# -- the bits of the packets' bit fields, by name (protocol/spec.md §4; firmware/src/core/packets.h names them the
# same: tests/host/test_protocol_bits.py checks both). Use the names, never the masks.
#: HELLO ``sensors_found`` and STATUS ``sensors_ok`` (spec §4.1; bit 2 is the magnetometer, HMC5883L or QMC5883L)
SENSOR_ADXL345, SENSOR_ITG3200, SENSOR_HMC5883L = 0x01, 0x02, 0x04
#: RAW_SAMPLE ``flags`` (spec §4.2): a sensor present and valid, a new magnetometer conversion, a tap in progress,
#: and (version 2) a value held from the last good read after a failed one
RAW_ACCEL_OK, RAW_GYRO_OK, RAW_MAG_OK, RAW_MAG_FRESH, RAW_TAP_ACTIVE = 0x01, 0x02, 0x04, 0x08, 0x10
RAW_ACCEL_STALE, RAW_GYRO_STALE, RAW_MAG_STALE = 0x20, 0x40, 0x80
#: ORIENTATION ``flags`` (spec §4.3); the PREV_ bits are bits 0-2 of the update one period before
ORI_MAG_USED, ORI_ACCEL_REJECTED, ORI_MAG_REJECTED, ORI_CONVERGING, ORI_GYRO_MISSING = 0x01, 0x02, 0x04, 0x08, 0x10
ORI_PREV_MAG_USED, ORI_PREV_ACCEL_REJECTED, ORI_PREV_MAG_REJECTED = 0x20, 0x40, 0x80
ORI_PREV_SHIFT = 5  # ORI_PREV_X == ORI_X << ORI_PREV_SHIFT
#: HELLO and SET_STREAM ``stream_mode``
STREAM_RAW, STREAM_ORIENTATION, STREAM_STATUS = 0x01, 0x02, 0x04
#: HELLO and STATUS ``calibration_state``
CAL_GYRO_BIAS_VALID, CAL_ACCEL_CALIBRATED, CAL_MAG_CALIBRATED, CAL_FROM_EEPROM = 0x01, 0x02, 0x04, 0x08
CAL_EEPROM_INVALID, CAL_GYRO_BIAS_ESTIMATED = 0x10, 0x20
#: HELLO ``reset_cause`` (the ATmega328P's MCUSR: PORF, EXTRF, BORF, WDRF; version 2)
RESET_POWER_ON, RESET_EXTERNAL, RESET_BROWN_OUT, RESET_WATCHDOG = 0x01, 0x02, 0x04, 0x08


def _bit_names(prefix: str) -> tuple[str, ...]:
    """The lower-case names of this module's one-bit constants ``PREFIX_NAME``, by bit: what ``sphere decode``
    shows for a bit field."""
    bits = {v: k[len(prefix):].lower() for k, v in globals().items()
            if k.startswith(prefix) and type(v) is int and v > 0 and v & (v - 1) == 0}
    return tuple(bits[1 << i] for i in range(max(bits).bit_length()))


SENSOR_BITS = _bit_names("SENSOR_")
RAW_FLAGS = _bit_names("RAW_")
ORIENTATION_FLAGS = _bit_names("ORI_")
STREAM_MODE_BITS = _bit_names("STREAM_")
CALIBRATION_STATE_BITS = _bit_names("CAL_")
RESET_CAUSE_BITS = _bit_names("RESET_")
MAG_CHIPS = {0: "none", 1: "hmc5883l", 2: "qmc5883l"}
BOARD_PROFILES = {0: "aligned", 1: "sen10724", 2: "gy85"}


def bit_names(value: int, names: tuple[str, ...]) -> list[str]:
    return [name for i, name in enumerate(names) if value >> i & 1]


class Field:
    """One spec field: struct code, element count, and how to show it in physical units."""

    __slots__ = ("name", "code", "count", "scale", "show", "default")

    def __init__(self, name: str, code: str, count: int = 1, scale: float | None = None, show=None, default=None):
        self.name, self.code, self.count, self.scale, self.show = name, code, count, scale, show
        self.default = default  # a field appended in a later version: its value when absent

    def physical(self, value):
        if self.show is not None:
            return self.show(value)
        if self.scale is None:
            return list(value) if self.count > 1 else value
        if self.count > 1:
            return [round(v * self.scale, 6) for v in value]
        return round(value * self.scale, 6)


def _unpacker(cls, offset: int):
    """A function (buffer, seq) → a ``cls`` packet from the current version's body at ``offset`` of the buffer,
    written out for the class from its FIELDS: one struct unpack, one attribute store per field (a loop over
    the fields takes twice as long; this is the decoder's hot path, once per frame)."""
    names, lines, n = [], [], 0
    for f in cls.FIELDS:
        values = [f"v{n + k}" for k in range(f.count)]
        names += values
        lines.append(f"o.{f.name} = " + (values[0] if f.count == 1 else "(" + ", ".join(values) + ",)"))
        n += f.count
    src = "def unpack(buf, seq):\n"
    if names:
        src += f"    {', '.join(names)}, = unpack_from(buf, {offset})\n"
    src += "    o = new(cls)\n" + "".join(f"    {line}\n" for line in lines) + "    o.seq = seq\n    return o\n"
    namespace = {"unpack_from": cls._struct.unpack_from, "new": cls.__new__, "cls": cls}
    exec(src, namespace)  # from the class's own field table: names that are Python identifiers, nothing read in
    return namespace["unpack"]


class Packet:
    """Base of every packet type. Subclasses set TYPE, NAME, DIRECTION and FIELDS."""

    TYPE: ClassVar[int]
    NAME: ClassVar[str]
    DIRECTION: ClassVar[str]  # "device" (device → host) or "host" (host → device)
    FIELDS: ClassVar[tuple[Field, ...]] = ()
    # fields of protocol version 1 when a later version appended some (None: the body never changed)
    V1_FIELDS: ClassVar[int | None] = None
    _struct: ClassVar[struct.Struct]
    _v1_struct: ClassVar[struct.Struct | None]
    _plan: ClassVar[tuple[tuple[str, int], ...]]
    _from_body: ClassVar  # (body, seq) -> packet, the current version's body (see _unpacker)
    _from_payload: ClassVar  # (payload, seq) -> packet, the same inside a whole payload

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        cls._struct = struct.Struct("<" + "".join(f"{f.count}{f.code}" for f in cls.FIELDS))
        cls._plan = tuple((f.name, f.count) for f in cls.FIELDS)
        cls._v1_struct = None
        if cls.V1_FIELDS is not None:
            cls._v1_struct = struct.Struct("<" + "".join(f"{f.count}{f.code}" for f in cls.FIELDS[: cls.V1_FIELDS]))
        cls._from_body = _unpacker(cls, 0)
        cls._from_payload = _unpacker(cls, 2)

    def __init__(self, *args, seq: int = 0, **kwargs):
        names = [f.name for f in self.FIELDS]
        if len(args) > len(names):
            raise TypeError(f"{self.NAME} takes {len(names)} fields, got {len(args)}")
        values = dict(zip(names, args))
        for key, value in kwargs.items():
            if key not in names:
                raise TypeError(f"{self.NAME} has no field {key!r}")
            values[key] = value
        for f in self.FIELDS:
            if f.name not in values and f.default is not None:
                values[f.name] = f.default
        missing = [n for n in names if n not in values]
        if missing:
            raise TypeError(f"{self.NAME} is missing {', '.join(missing)}")
        for f in self.FIELDS:
            v = values[f.name]
            setattr(self, f.name, tuple(v) if f.count > 1 else v)
        self.seq = seq

    # -- wire ------------------------------------------------------------------------------------
    @classmethod
    def body_size(cls) -> int:
        return cls._struct.size

    @classmethod
    def body_sizes(cls) -> tuple[int, ...]:
        """Every body length this host decodes: the current one, and version 1's where it differed."""
        return (cls._struct.size,) if cls._v1_struct is None else (cls._struct.size, cls._v1_struct.size)

    @classmethod
    def payload_decoders(cls) -> dict:
        """For the frame decoder: each body length of :meth:`body_sizes` → a function (payload, seq) → packet
        that reads the body inside the whole payload (type, seq, body, CRC), the length already checked."""
        out = {n: (lambda payload, seq, unpack=cls.unpack_body: unpack(payload[2:-2], seq)) for n in cls.body_sizes()}
        out[cls._struct.size] = cls._from_payload
        return out

    def pack_body(self) -> bytes:
        flat = []
        for f in self.FIELDS:
            v = getattr(self, f.name)
            if f.count > 1:
                flat.extend(v)
            else:
                flat.append(v)
        return self._struct.pack(*flat)

    @classmethod
    def unpack_body(cls, body: bytes, seq: int = 0) -> "Packet":
        if len(body) == cls._struct.size:  # the current version (every frame of a live link)
            return cls._from_body(body, seq)
        if cls._v1_struct is None or len(body) != cls._v1_struct.size:
            raise struct.error(f"{cls.NAME}: a body of {len(body)} bytes, not {' or '.join(map(str, cls.body_sizes()))}")
        flat = cls._v1_struct.unpack(body)  # version 1's shorter body: the fields appended since take their defaults
        obj = cls.__new__(cls)
        i = 0
        for k, (name, count) in enumerate(cls._plan):
            if k >= cls.V1_FIELDS:
                setattr(obj, name, cls.FIELDS[k].default)
            else:
                setattr(obj, name, flat[i] if count == 1 else flat[i : i + count])
            i += count
        obj.seq = seq
        return obj

    # -- people ----------------------------------------------------------------------------------
    def fields(self) -> dict:
        """The body fields as on the wire."""
        return {f.name: (list(getattr(self, f.name)) if f.count > 1 else getattr(self, f.name)) for f in self.FIELDS}

    def to_json(self, raw: bool = False) -> dict:
        """``type``, ``seq`` and the fields: physical values where the spec gives a unit, unless raw."""
        out = {"type": self.NAME.lower(), "seq": self.seq}
        for f in self.FIELDS:
            v = getattr(self, f.name)
            out[f.name] = (list(v) if f.count > 1 else v) if raw else f.physical(v)
        return out

    def __eq__(self, other):
        return type(self) is type(other) and self.seq == other.seq and self.fields() == other.fields()

    def __repr__(self):
        inner = ", ".join(f"{k}={v!r}" for k, v in self.fields().items())
        return f"{type(self).__name__}(seq={self.seq}, {inner})"


# ---- device → host -----------------------------------------------------------------------------


class Hello(Packet):
    TYPE, NAME, DIRECTION = 0x01, "HELLO", "device"
    FIELDS = (
        Field("protocol_version", "B"),
        Field("firmware_version", "B", 3, show=lambda v: "%d.%d.%d" % tuple(v)),
        Field("sensors_found", "B", show=lambda v: bit_names(v, SENSOR_BITS)),
        Field("adxl345_devid", "B"),
        Field("itg3200_whoami", "B"),
        Field("hmc5883l_id", "B", 3, show=lambda v: bytes(v).decode("latin-1")),
        Field("imu_rate_hz", "H"),
        Field("mag_rate_hz", "B"),
        Field("stream_mode", "B", show=lambda v: bit_names(v, STREAM_MODE_BITS)),
        Field("raw_rate_hz", "H"),
        Field("orientation_rate_hz", "H"),
        Field("calibration_state", "B", show=lambda v: bit_names(v, CALIBRATION_STATE_BITS)),
        # version 2
        # 0: unknown (a boot loader cleared MCUSR without handing it over, or a version-1 HELLO)
        Field("reset_cause", "B", show=lambda v: bit_names(v, RESET_CAUSE_BITS) or ["unknown"], default=0),
        Field("mag_chip", "B", show=lambda v: MAG_CHIPS.get(v, v), default=0),
        Field("board_profile", "B", show=lambda v: BOARD_PROFILES.get(v, v), default=0),
    )
    V1_FIELDS = 12


class RawSample(Packet):
    TYPE, NAME, DIRECTION = 0x02, "RAW_SAMPLE", "device"
    FIELDS = (
        Field("t_us", "I"),
        Field("flags", "B", show=lambda v: bit_names(v, RAW_FLAGS)),
        Field("accel", "h", 3, scale=1.0 / chips.ADXL345_LSB_PER_G),
        Field("gyro", "h", 3, scale=1.0 / chips.ITG3200_LSB_PER_DPS),
        Field("mag", "h", 3, scale=1.0 / chips.HMC5883L_LSB_PER_UT),
    )

    @property
    def accel_g(self):
        return chips.accel_lsb_to_g(self.accel)

    @property
    def gyro_dps(self):
        return chips.gyro_lsb_to_dps(self.gyro)

    @property
    def mag_uT(self):
        return chips.mag_lsb_to_uT(self.mag)


class Orientation(Packet):
    TYPE, NAME, DIRECTION = 0x03, "ORIENTATION", "device"
    FIELDS = (
        Field("t_us", "I"),
        Field("flags", "B", show=lambda v: bit_names(v, ORIENTATION_FLAGS)),
        Field("quat", "h", 4, scale=1.0 / Q14),
    )

    @property
    def quat_float(self) -> tuple[float, float, float, float]:
        """w, x, y, z as floats, sensor-to-NWU."""
        return tuple(v / Q14 for v in self.quat)


def _tap_axes(status: int) -> list[str]:
    return [axis for bit, axis in ((2, "x"), (1, "y"), (0, "z")) if status >> bit & 1]


class Event(Packet):
    TYPE, NAME, DIRECTION = 0x04, "EVENT", "device"
    FIELDS = (
        Field("t_us", "I"),
        Field("event", "B", show=lambda v: EVENT_NAMES.get(v, v)),
        Field("int_source", "B"),
        Field("act_tap_status", "B"),
        Field("tap_sign", "b"),
    )

    @property
    def event_name(self) -> str:
        return EVENT_NAMES.get(self.event, f"unknown_{self.event}")

    @property
    def tap_axes(self) -> list[str]:
        return _tap_axes(self.act_tap_status)

    def to_json(self, raw: bool = False) -> dict:
        out = super().to_json(raw)
        out["tap_axes"] = self.tap_axes
        return out


class Status(Packet):
    TYPE, NAME, DIRECTION = 0x05, "STATUS", "device"
    FIELDS = (
        Field("t_us", "I"),
        Field("sensors_ok", "B", show=lambda v: bit_names(v, SENSOR_BITS)),
        Field("i2c_errors", "H", 3),
        Field("i2c_recoveries", "H"),
        Field("loop_overruns", "H"),
        Field("frames_dropped", "H"),
        Field("rx_errors", "H"),
        Field("calibration_state", "B", show=lambda v: bit_names(v, CALIBRATION_STATE_BITS)),
        Field("calibration_step", "B", show=lambda v: CALIBRATION_STEPS.get(v, v)),
        Field("cpu_load", "H", scale=0.001),
        Field("battery_mv", "H"),
        # version 2
        Field("probe_failures", "H", default=0),
        Field("sensor_losses", "H", default=0),
    )
    V1_FIELDS = 11


class Reply(Packet):
    """REPLY: three fixed fields and, for GET_CALIBRATION, 43 bytes of data; for GET_SETTINGS, 15 (spec §4.6)."""

    TYPE, NAME, DIRECTION = 0x06, "REPLY", "device"
    FIELDS = (
        Field("cmd_seq", "B"),
        Field("cmd_type", "B", show=lambda v: _COMMAND_NAMES.get(v, v)),
        Field("result", "B", show=lambda v: Result(v).name.lower() if v in Result._value2member_map_ else v),
    )
    DATA_SIZES = (0, 4, 15, 43)  # nothing; ECHO's device_t_us; GET_SETTINGS' block (version 3); GET_CALIBRATION's

    def __init__(self, *args, data: bytes = b"", **kwargs):
        super().__init__(*args, **kwargs)
        self.data = bytes(data)

    def pack_body(self) -> bytes:
        return super().pack_body() + self.data

    @classmethod
    def unpack_body(cls, body: bytes, seq: int = 0) -> "Reply":
        obj = super().unpack_body(body[: cls._struct.size], seq)
        obj.data = bytes(body[cls._struct.size :])
        return obj

    @classmethod
    def body_sizes(cls) -> tuple[int, ...]:
        return tuple(cls._struct.size + n for n in cls.DATA_SIZES)

    @classmethod
    def payload_decoders(cls) -> dict:
        return {n: (lambda payload, seq: cls.unpack_body(payload[2:-2], seq)) for n in cls.body_sizes()}

    @property
    def ok(self) -> bool:
        return self.result == Result.OK

    def calibration(self) -> tuple["CalibrationBlock", int]:
        """The block and calibration_state carried by a GET_CALIBRATION reply."""
        if len(self.data) != CalibrationBlock.SIZE + 1:
            raise ValueError(f"this REPLY carries {len(self.data)} data bytes, not a calibration")
        return CalibrationBlock.unpack(self.data[:-1]), self.data[-1]

    def settings(self) -> tuple[tuple["Packet", ...], int]:
        """The settings block (spec §5.3) as the four commands it is the bodies of (SetStream, SetTap,
        SetFreeFall, SetFilter), and settings_state, carried by a GET_SETTINGS reply."""
        if len(self.data) != SETTINGS_BLOCK_SIZE + 1:
            raise ValueError(f"this REPLY carries {len(self.data)} data bytes, not the settings")
        return settings_from_block(self.data[:-1]), self.data[-1]

    def fields(self) -> dict:
        out = super().fields()
        out["data"] = self.data.hex()
        return out

    def to_json(self, raw: bool = False) -> dict:
        out = super().to_json(raw)
        out["data"] = self.data.hex()
        return out


# ---- host → device -----------------------------------------------------------------------------


class GetHello(Packet):
    TYPE, NAME, DIRECTION = 0x40, "GET_HELLO", "host"


class SetStream(Packet):
    TYPE, NAME, DIRECTION = 0x41, "SET_STREAM", "host"
    FIELDS = (Field("stream_mode", "B"), Field("raw_rate_hz", "H"), Field("orientation_rate_hz", "H"))


class SetTap(Packet):
    TYPE, NAME, DIRECTION = 0x42, "SET_TAP", "host"
    FIELDS = (
        Field("thresh_tap", "B", scale=0.0625),  # g
        Field("dur", "B", scale=0.625),  # ms
        Field("latent", "B", scale=1.25),  # ms
        Field("window", "B", scale=1.25),  # ms
        Field("tap_axes", "B"),
    )


class SetFreeFall(Packet):
    TYPE, NAME, DIRECTION = 0x43, "SET_FREE_FALL", "host"
    FIELDS = (Field("thresh_ff", "B", scale=0.0625), Field("time_ff", "B", scale=5.0))  # g, ms


class SetFilter(Packet):
    TYPE, NAME, DIRECTION = 0x44, "SET_FILTER", "host"
    FIELDS = (Field("beta", "H", scale=0.001),)


class CalibrationStep(Packet):
    TYPE, NAME, DIRECTION = 0x45, "CALIBRATION_STEP", "host"
    FIELDS = (Field("step", "B", show=lambda v: CALIBRATION_STEPS.get(v, v)), Field("action", "B"))


_CAL_FIELDS = (
    Field("gyro_bias", "h", 3),
    Field("accel_offset", "h", 3),
    Field("accel_scale", "h", 3, scale=1.0 / Q14),
    Field("mag_offset", "h", 3),
    Field("mag_soft_iron", "h", 9, scale=1.0 / Q14),
)


class SetCalibration(Packet):
    TYPE, NAME, DIRECTION = 0x46, "SET_CALIBRATION", "host"
    FIELDS = _CAL_FIELDS


class CalibrationBlock:
    """The 42-byte calibration block (spec §5.2), shared by SET_CALIBRATION and GET_CALIBRATION."""

    SIZE = SetCalibration.body_size()

    @staticmethod
    def default() -> SetCalibration:
        return SetCalibration(
            gyro_bias=(0, 0, 0),
            accel_offset=(0, 0, 0),
            accel_scale=(16384,) * 3,
            mag_offset=(0, 0, 0),
            mag_soft_iron=(16384, 0, 0, 0, 16384, 0, 0, 0, 16384),
        )

    @staticmethod
    def unpack(data: bytes) -> SetCalibration:
        return SetCalibration.unpack_body(data)


class GetCalibration(Packet):
    TYPE, NAME, DIRECTION = 0x47, "GET_CALIBRATION", "host"


class SaveCalibration(Packet):
    TYPE, NAME, DIRECTION = 0x48, "SAVE_CALIBRATION", "host"


class LoadCalibration(Packet):
    TYPE, NAME, DIRECTION = 0x49, "LOAD_CALIBRATION", "host"


class ResetCalibration(Packet):
    TYPE, NAME, DIRECTION = 0x4A, "RESET_CALIBRATION", "host"


class Identify(Packet):
    TYPE, NAME, DIRECTION = 0x4B, "IDENTIFY", "host"
    FIELDS = (Field("seconds", "B"),)


REBOOT_MAGIC = 0xB007


class Reboot(Packet):
    TYPE, NAME, DIRECTION = 0x4C, "REBOOT", "host"
    FIELDS = (Field("magic", "H"),)


class GetStatus(Packet):
    TYPE, NAME, DIRECTION = 0x4D, "GET_STATUS", "host"


class SetBoard(Packet):
    TYPE, NAME, DIRECTION = 0x4E, "SET_BOARD", "host"
    FIELDS = (Field("board_profile", "B", show=lambda v: BOARD_PROFILES.get(v, v)),)


class SetBaud(Packet):
    """Version 3: the link to another rate, confirmed by the host's next frame (spec §5.4)."""

    TYPE, NAME, DIRECTION = 0x4F, "SET_BAUD", "host"
    FIELDS = (Field("baud", "I"),)


class Echo(Packet):
    """Version 3: REPLY data is the device's micros() when the frame was complete (spec §5.5)."""

    TYPE, NAME, DIRECTION = 0x50, "ECHO", "host"
class GetSettings(Packet):
    TYPE, NAME, DIRECTION = 0x54, "GET_SETTINGS", "host"


class SaveSettings(Packet):
    TYPE, NAME, DIRECTION = 0x55, "SAVE_SETTINGS", "host"


class ClearSettings(Packet):
    TYPE, NAME, DIRECTION = 0x56, "CLEAR_SETTINGS", "host"


#: The settings block (spec §5.3): the bodies of these commands, in this order.
SETTINGS_GROUPS: tuple[type[Packet], ...] = (SetStream, SetTap, SetFreeFall, SetFilter)
SETTINGS_BLOCK_SIZE = sum(c.body_size() for c in SETTINGS_GROUPS)
#: settings_state bits (spec §5.3)
SETTINGS_SAVED, SETTINGS_EEPROM_INVALID, SETTINGS_NONE_SAVED = 1, 2, 4


def settings_from_block(block: bytes) -> tuple[Packet, ...]:
    """The four commands whose bodies make the settings block."""
    out, i = [], 0
    for cls in SETTINGS_GROUPS:
        n = cls.body_size()
        out.append(cls.unpack_body(block[i : i + n]))
        i += n
    return tuple(out)


def settings_block(packets) -> bytes:
    """The settings block from the four commands (in :data:`SETTINGS_GROUPS` order)."""
    return b"".join(p.pack_body() for p in packets)


ALL_TYPES: tuple[type[Packet], ...] = (
    Hello,
    RawSample,
    Orientation,
    Event,
    Status,
    Reply,
    GetHello,
    SetStream,
    SetTap,
    SetFreeFall,
    SetFilter,
    CalibrationStep,
    SetCalibration,
    GetCalibration,
    SaveCalibration,
    LoadCalibration,
    ResetCalibration,
    Identify,
    Reboot,
    GetStatus,
    SetBoard,
    SetBaud,
    Echo,
    GetSettings,
    SaveSettings,
    ClearSettings,
)
BY_TYPE = {cls.TYPE: cls for cls in ALL_TYPES}
BY_NAME = {cls.NAME: cls for cls in ALL_TYPES}
_COMMAND_NAMES = {cls.TYPE: cls.NAME.lower() for cls in ALL_TYPES if cls.DIRECTION == "host"}


def packet_class(type_or_name: int | str) -> type[Packet]:
    """The packet class for a type number or a spec name (``"RAW_SAMPLE"``)."""
    if isinstance(type_or_name, str):
        return BY_NAME[type_or_name.upper()]
    return BY_TYPE[type_or_name]


def body_sizes(cls: type[Packet]) -> tuple[int, ...]:
    """The body lengths a packet type may have."""
    return cls.body_sizes()
