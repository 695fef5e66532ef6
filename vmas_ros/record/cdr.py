"""CDR bytes with every alignment padding byte zeroed.

Why: rclpy's ``serialize_message`` (rmw_fastrtps) allocates its buffer with
``malloc`` and skips over the padding CDR puts before aligned fields without
writing it. Those bytes hold whatever the heap held before: two runs that
publish identical messages send (and record) different bytes, and bits of the
process's memory end up in bags. ``serialize_zeroed`` serialises with rclpy and
then zeroes the padding, so identical messages give identical bytes.

Where the padding sits follows from the message's types and its string and
sequence lengths: CDR (XCDR1, as ROS 2 uses it) aligns every primitive to its
own size (8 at most), counted from the end of the 4-byte encapsulation header;
a string or sequence starts with a 4-byte aligned uint32 length; nested
messages add no alignment of their own; an empty message is one byte. The walk
below reads only the types (``SLOT_TYPES``) and lengths, never the bytes, and
refuses the result unless it ends exactly where rclpy's bytes end, so a layout
rule it got wrong cannot go unnoticed.
"""
from __future__ import annotations

from typing import Any, Dict, List, Tuple

from rosidl_parser import definition as idl

__all__ = ["padding_ranges", "serialize_zeroed", "zero_padding"]

#: bytes (= alignment) of each IDL primitive a ROS message can hold
_PRIMITIVE_SIZES: Dict[str, int] = {
    "boolean": 1, "octet": 1, "char": 1, "int8": 1, "uint8": 1,
    "int16": 2, "uint16": 2, "short": 2, "unsigned short": 2,
    "int32": 4, "uint32": 4, "long": 4, "unsigned long": 4, "float": 4,
    "int64": 8, "uint64": 8, "long long": 8, "unsigned long long": 8, "double": 8,
}
_HEADER = 4  # encapsulation: representation id and options
_CDR_LE = b"\x00\x01"

_FIELDS: Dict[type, List[Tuple[str, object]]] = {}  # message class -> [(field name, IDL type)]


def _fields(message_class: type) -> List[Tuple[str, object]]:
    fields = _FIELDS.get(message_class)
    if fields is None:
        names = list(message_class.get_fields_and_field_types())
        fields = _FIELDS[message_class] = list(zip(names, message_class.SLOT_TYPES))
    return fields


class _Walk:
    """Offsets relative to the CDR body (after the encapsulation header), and the padding met."""

    def __init__(self) -> None:
        self.pos = 0
        self.padding: List[Tuple[int, int]] = []

    def align(self, size: int) -> None:
        gap = -self.pos % size
        if gap:
            self.padding.append((self.pos, self.pos + gap))
            self.pos += gap

    def message(self, message) -> None:
        fields = _fields(type(message))
        if not fields:  # an empty message holds one placeholder byte
            self.pos += 1
            return
        for name, kind in fields:
            self.value(getattr(message, name), kind, name)

    def value(self, value, kind, name: str) -> None:
        if isinstance(kind, idl.BasicType):
            size = self._primitive(kind, name)
            self.align(size)
            self.pos += size
        elif isinstance(kind, idl.AbstractString):  # not AbstractWString: wide strings are refused below
            self.align(4)
            self.pos += 4 + len(value.encode("utf-8")) + 1  # length, bytes, NUL
        elif isinstance(kind, idl.NamespacedType):
            self.message(value)
        elif isinstance(kind, idl.AbstractSequence):
            self.align(4)
            self.pos += 4
            self.elements(value, kind.value_type, name)
        elif isinstance(kind, idl.Array):
            self.elements(value, kind.value_type, name)
        else:
            raise NotImplementedError(f"field {name!r}: cannot lay out {type(kind).__name__} in CDR "
                                      f"(expected primitives, strings, messages, arrays and sequences)")

    def elements(self, values, kind, name: str) -> None:
        count = len(values)
        if isinstance(kind, idl.BasicType):
            if count:  # primitives are contiguous once the first one is aligned
                size = self._primitive(kind, name)
                self.align(size)
                self.pos += size * count
            return
        for item in values:
            self.value(item, kind, name)

    @staticmethod
    def _primitive(kind, name: str) -> int:
        size = _PRIMITIVE_SIZES.get(kind.typename)
        if size is None:
            raise NotImplementedError(f"field {name!r}: cannot lay out the primitive {kind.typename!r} in CDR")
        return size


def _fixed_kind(kind) -> bool:
    """Whether values of IDL type ``kind`` always take the same bytes: no string or sequence inside."""
    if isinstance(kind, idl.Array):
        return _fixed_kind(kind.value_type)
    if isinstance(kind, idl.BasicType):
        return True
    if isinstance(kind, idl.NamespacedType):
        import importlib

        return _fixed_layout(getattr(importlib.import_module(".".join(kind.namespaces)), kind.name))
    return False  # strings and sequences: their lengths move everything after them


def _fixed_layout(message_class: type) -> bool:
    """Whether every message of this class has the same layout, hence the same padding."""
    fixed = _FIXED.get(message_class)
    if fixed is None:
        fixed = _FIXED[message_class] = all(_fixed_kind(kind) for _, kind in _fields(message_class))
    return fixed


_FIXED: Dict[type, bool] = {}  # message class -> layout independent of the values
_PADDING: Dict[Tuple[type, int], List[Tuple[int, int]]] = {}  # fixed-layout (class, length) -> padding


def padding_ranges(message: Any, length: int) -> List[Tuple[int, int]]:
    """[start, end) byte ranges of the alignment padding in ``message``'s CDR bytes of ``length`` bytes.

    Offsets count from the start of the bytes (encapsulation header included).
    Raises ValueError when the layout does not end at ``length`` (or within the
    last 3 bytes before it: rmw pads the whole message to 4 bytes). Types
    without strings or sequences are walked once (their padding never moves).
    """
    key = (type(message), length)
    cached = _PADDING.get(key)
    if cached is not None:
        return cached
    walk = _Walk()
    walk.message(message)
    end = _HEADER + walk.pos
    if not 0 <= length - end < 4:
        raise ValueError(f"{type(message).__module__}.{type(message).__name__}: the CDR layout ends at byte "
                         f"{end}, but the serialised message has {length} bytes; cannot find its padding")
    ranges = [(_HEADER + a, _HEADER + b) for a, b in walk.padding]
    if length > end:
        ranges.append((end, length))
    if _fixed_layout(type(message)):
        _PADDING[key] = ranges
    return ranges


def zero_padding(message: Any, data: bytes) -> bytes:
    """``data`` (the CDR bytes of ``message``) with every padding byte set to 0."""
    if data[:2] != _CDR_LE:
        raise ValueError(f"expected little-endian plain CDR (encapsulation 0001), got {data[:4].hex()}")
    ranges = padding_ranges(message, len(data))
    if not ranges:
        return data
    out = bytearray(data)
    for a, b in ranges:
        out[a:b] = bytes(b - a)
    return bytes(out)


def serialize_zeroed(message: Any) -> bytes:
    """``rclpy.serialization.serialize_message(message)`` with its padding bytes zeroed."""
    from rclpy.serialization import serialize_message

    return zero_padding(message, serialize_message(message))
