"""Register words on the wire: unsigned 16 bit, signed int16 by two's complement, uint32 pairs."""

from __future__ import annotations

from collections.abc import Sequence


def to_int16(word: int) -> int:
    """Interpret an unsigned 16-bit register word as two's-complement int16."""
    if not 0 <= word <= 0xFFFF:
        raise ValueError(f"register word {word} is not in 0…65535")
    return word - 0x10000 if word & 0x8000 else word


def to_word(value: int) -> int:
    """Signed int16 → the unsigned 16-bit word sent on the wire."""
    if not -0x8000 <= value <= 0x7FFF:
        raise ValueError(f"{value} does not fit a signed 16-bit register")
    return value & 0xFFFF


def uint32(words: Sequence[int]) -> int:
    """Two register words, high word first (lower address), as an unsigned 32-bit integer."""
    high, low = words
    return (high << 16) | low


def uint32_words(value: int) -> list[int]:
    """An unsigned 32-bit integer as two register words, high word first (inverse of
    :func:`uint32`)."""
    if not 0 <= value <= 0xFFFFFFFF:
        raise ValueError(f"{value} does not fit an unsigned 32-bit register pair")
    return [value >> 16, value & 0xFFFF]
