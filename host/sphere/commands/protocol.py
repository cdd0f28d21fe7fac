"""`sphere protocol ...`: facts about the wire protocol, computed from the codec."""

from __future__ import annotations

from sphere.protocol.budget import budget_table
from sphere.protocol.packets import ALL_TYPES, PROTOCOL_VERSION, body_sizes
from sphere.protocol.framing import MAX_FRAME, MAX_PAYLOAD

HELP = "print the protocol's packet sizes and link budget"


def add_arguments(p) -> None:
    p.add_argument("what", choices=["budget", "types"], metavar="{budget,types}", help="budget: spec §6 table; types: every packet type and size")


def run(args) -> int:
    if args.what == "budget":
        print(budget_table())
    else:
        print(f"protocol version {PROTOCOL_VERSION}; payload ≤ {MAX_PAYLOAD} bytes, frame ≤ {MAX_FRAME} bytes on the wire")
        for cls in ALL_TYPES:
            sizes = "/".join(str(s) for s in body_sizes(cls))
            print(f"0x{cls.TYPE:02X} {cls.NAME:<18} {cls.DIRECTION:<6} body {sizes} bytes")
    return 0
