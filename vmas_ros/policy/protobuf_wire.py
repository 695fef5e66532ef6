"""Protobuf's wire format, read with the standard library alone.

ONNX files are protobuf messages, and so are Foxglove's schemas; checking one
for a field or two does not justify a dependency on the protobuf package (a
policy runner needs only numpy and onnxruntime). Every read is bounded: bytes
that are not a well-formed message raise :class:`ProtobufFormatError` instead
of reading past the end.
"""
from __future__ import annotations

from typing import Iterator, Tuple

__all__ = ["ProtobufFormatError", "read_fields", "read_varint"]

#: wire types: varint, 64-bit, length-delimited, 32-bit
VARINT, FIXED64, LENGTH_DELIMITED, FIXED32 = 0, 1, 2, 5


class ProtobufFormatError(ValueError):
    """The bytes are not a well-formed protobuf message."""


def read_varint(data: bytes, i: int) -> Tuple[int, int]:
    """The varint starting at byte ``i`` of ``data``, and the index just after it."""
    value = shift = 0
    while True:
        if i >= len(data) or shift > 63:
            raise ProtobufFormatError("truncated or oversized varint")
        byte = data[i]
        i += 1
        value |= (byte & 0x7F) << shift
        if not byte & 0x80:
            return value, i
        shift += 7


def read_fields(data: bytes) -> Iterator[Tuple[int, int, object]]:
    """(field number, wire type, value) of each field of one message, in order.

    Varints come as ints; the other wire types as the raw bytes of the value
    (a length-delimited field's payload: a string, bytes, a nested message or
    a packed repeated field, which the caller knows from the schema).
    """
    i = 0
    while i < len(data):
        key, i = read_varint(data, i)
        number, wire = key >> 3, key & 7
        if wire == VARINT:
            value, i = read_varint(data, i)
        elif wire in (FIXED64, FIXED32):
            size = 8 if wire == FIXED64 else 4
            if i + size > len(data):
                raise ProtobufFormatError("fixed-size field runs past the end")
            value, i = data[i:i + size], i + size
        elif wire == LENGTH_DELIMITED:
            size, i = read_varint(data, i)
            if i + size > len(data):
                raise ProtobufFormatError("length-delimited field runs past the end")
            value, i = data[i:i + size], i + size
        else:
            raise ProtobufFormatError(f"unsupported wire type {wire}")
        yield number, wire, value
