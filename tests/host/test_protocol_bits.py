"""The packets' bit fields are named once, in sphere.protocol.packets, and those names agree with the two other
places that define them: protocol/spec.md (the field tables: ``bit N `name```) and the firmware's
firmware/src/core/packets.h and settings_image.h (``const uint8_t RAW_ACCEL_OK = 1, …``)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from sphere.protocol import packets

ROOT = Path(__file__).resolve().parents[2]
GROUPS = {"SENSOR_": "SENSOR_BITS", "RAW_": "RAW_FLAGS", "ORI_": "ORIENTATION_FLAGS", "STREAM_": "STREAM_MODE_BITS",
          "CAL_": "CALIBRATION_STATE_BITS", "RESET_": "RESET_CAUSE_BITS", "SETTINGS_": None}
#: the spec calls bit 2 of sensors_found "magnetometer (HMC5883L or QMC5883L)"; the host and firmware HMC5883L
SPEC_ALIASES = {"magnetometer": "hmc5883l"}


def ours(prefix: str) -> dict[str, int]:
    return {k: v for k, v in vars(packets).items()
            if k.startswith(prefix) and type(v) is int and v > 0 and v & (v - 1) == 0}


def spec_bit_fields() -> list[dict[str, int]]:
    """Every table row and every paragraph of the spec that names bits: {name: bit}."""
    rows, blocks, paragraph = [], [], []
    for line in (ROOT / "protocol" / "spec.md").read_text().splitlines() + [""]:
        if line.startswith("|") or not line.strip():
            blocks.append(" ".join(paragraph))
            paragraph = []
            if line.startswith("|"):
                blocks.append(line)
        else:
            paragraph.append(line.strip())
    for line in blocks:
        row = {}
        for m in re.finditer(r"\bbits? (\d+(?:, \d+)*) ((?:`\w+`(?:, )?)+|\w+)", line):
            bits = [int(b) for b in m.group(1).split(", ")]
            names = [SPEC_ALIASES.get(n.lower(), n.lower()) for n in re.findall(r"\w+", m.group(2))]
            if len(bits) == len(names):
                row.update(zip(names, bits))
        if row:
            rows.append(row)
    return rows


def firmware_constants() -> dict[str, int]:
    core = ROOT / "firmware" / "src" / "core"
    text = (core / "packets.h").read_text() + (core / "settings_image.h").read_text()
    out = {}
    for decl in re.findall(r"const uint8_t ([^;]+);", text):
        for name, value in re.findall(r"(\w+)\s*=\s*(\w+)", decl):
            out[name] = int(value, 0)
    return out


@pytest.mark.parametrize("prefix", GROUPS)
def test_each_bit_field_is_the_specs(prefix):
    mine = {k[len(prefix):].lower(): v.bit_length() - 1 for k, v in ours(prefix).items()}
    want = {name: i for i, name in enumerate(getattr(packets, GROUPS[prefix]))} if GROUPS[prefix] else mine
    assert want == mine
    assert want in spec_bit_fields(), f"no row of protocol/spec.md names the bits {want}"


@pytest.mark.parametrize("prefix", GROUPS)
def test_each_bit_is_the_firmwares(prefix):
    fw = firmware_constants()
    mine = ours(prefix)
    named = {k: v for k, v in fw.items() if k.startswith(prefix) and k in mine}
    assert named, f"packets.h names none of {sorted(mine)}"
    assert named == {k: mine[k] for k in named}
    if prefix == "ORI_":  # the firmware writes bits 5-7 as bits 0-2 shifted by ORI_PREV_SHIFT
        shift = fw["ORI_PREV_SHIFT"]
        assert packets.ORI_PREV_SHIFT == shift
        for k in ("MAG_USED", "ACCEL_REJECTED", "MAG_REJECTED"):
            assert mine[f"ORI_PREV_{k}"] == fw[f"ORI_{k}"] << shift
    else:
        assert named.keys() == mine.keys(), f"packets.h lacks {sorted(mine.keys() - named.keys())}"


def test_the_parsers_find_what_they_check():
    """The checks above cannot pass on nothing: the spec has a row per field, packets.h its constants."""
    rows = spec_bit_fields()
    assert len(rows) >= 6 and {"accel_stale": 5, "gyro_stale": 6, "mag_stale": 7}.items() <= rows[[
        i for i, r in enumerate(rows) if "accel_ok" in r][0]].items()
    assert firmware_constants()["RAW_TAP_ACTIVE"] == 16
