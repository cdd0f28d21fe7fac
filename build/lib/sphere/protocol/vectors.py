"""Reading the golden-vector file protocol/vectors/frames.txt (format in protocol/spec.md §7)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from sphere.paths import vectors_file

OUTCOMES = ("ok", "oversize", "framing_error", "crc_error", "unknown_type", "bad_length")


@dataclass
class Vector:
    name: str
    direction: str = "device"
    wire: bytes = b""
    outcome: str = "ok"
    type: str | None = None
    seq: int | None = None
    fields: dict[str, object] = field(default_factory=dict)
    line: int = 0


def default_path() -> Path:
    return vectors_file()


def parse_value(text: str):
    """An integer, a comma-separated list of integers, or (for REPLY data) a hex string."""
    text = text.strip()
    if "," in text:
        return [int(v, 0) for v in text.split(",")]
    try:
        return int(text, 0)
    except ValueError:
        return text


def load_vectors(path: Path | str | None = None) -> list[Vector]:
    path = Path(path) if path is not None else default_path()
    vectors: list[Vector] = []
    current: Vector | None = None
    for lineno, raw in enumerate(path.read_text().splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        if line.startswith("[") and line.endswith("]"):
            current = Vector(name=line[1:-1], line=lineno)
            vectors.append(current)
            continue
        if current is None or "=" not in line:
            raise ValueError(f"{path}:{lineno}: expected [name] or key = value, got {raw!r}")
        key, value = (s.strip() for s in line.split("=", 1))
        if key == "direction":
            current.direction = value
        elif key == "wire":
            current.wire = bytes.fromhex(value)
        elif key == "outcome":
            if value not in OUTCOMES:
                raise ValueError(f"{path}:{lineno}: unknown outcome {value!r}")
            current.outcome = value
        elif key == "type":
            current.type = value
        elif key == "seq":
            current.seq = int(value, 0)
        elif key == "data":  # REPLY data: hex digits, no spaces (empty when there is none)
            current.fields[key] = value.replace(" ", "").lower()
        else:
            current.fields[key] = parse_value(value)
    return vectors
