"""Link budget (spec §6): bytes per second of each stream mode against common baud rates.

Computed from the packet definitions, so the table in protocol/spec.md cannot drift from the codec.
"""

from __future__ import annotations

from sphere.protocol.framing import MAX_PAYLOAD
from sphere.protocol.packets import Orientation, RawSample, Status

BAUD_RATES = (9600, 38400, 57600, 115200)
#: A mode fits when it uses less than this share of the link.
FIT_LIMIT = 0.70
BITS_PER_BYTE = 10  # 8N1: start bit, eight data bits, stop bit


def wire_bytes(packet_cls) -> int:
    """Bytes one frame of this type takes on the wire: payload, COBS overhead, delimiter."""
    payload = 2 + packet_cls.body_size() + 2
    return payload + (payload + 253) // 254 + 1


def budget_rows():
    raw, ori, status = wire_bytes(RawSample), wire_bytes(Orientation), wire_bytes(Status)
    rows = []
    for name, size, rate in (
        ("raw", raw, 200),
        ("raw", raw, 100),
        ("orientation", ori, 200),
        ("orientation", ori, 100),
        ("orientation", ori, 50),
        ("orientation", ori, 25),
    ):
        rows.append((f"{name} {rate} Hz", size, rate, size * rate))
    for label, raw_hz, ori_hz in (
        ("raw 200 Hz + orientation 100 Hz + status (default)", 200, 100),
        ("raw 200 Hz + orientation 200 Hz + status", 200, 200),
        ("raw 100 Hz + orientation 100 Hz + status", 100, 100),
        ("orientation 100 Hz + status", 0, 100),
        ("orientation 25 Hz + status", 0, 25),
    ):
        rows.append((label, None, None, raw * raw_hz + ori * ori_hz + status))
    return rows


def budget_table() -> str:
    """The Markdown table of spec §6."""
    head = "| stream | frame bytes | rate (Hz) | bytes/s | " + " | ".join(f"{b} baud" for b in BAUD_RATES) + " |"
    lines = [head, "|" + "---|" * (4 + len(BAUD_RATES))]
    for label, size, rate, bps in budget_rows():
        cells = []
        for baud in BAUD_RATES:
            share = bps * BITS_PER_BYTE / baud
            cells.append(f"{share * 100:.0f} % {'✓' if share < FIT_LIMIT else '✗'}")
        lines.append(
            f"| {label} | {size if size else '–'} | {rate if rate else '–'} | {bps} | " + " | ".join(cells) + " |"
        )
    return "\n".join(lines)


assert wire_bytes(RawSample) <= MAX_PAYLOAD + 2
