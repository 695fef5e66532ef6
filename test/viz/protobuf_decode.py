"""Decoding the protobuf messages a Foxglove channel sends, from the schema it advertises.

A small reader driven by the channel's FileDescriptorSet (on the wire reader of
``vmas_ros.policy.protobuf_wire``), so the tests need no protobuf package.
"""
from __future__ import annotations

import struct

from vmas_ros.policy.protobuf_wire import read_fields, read_varint

__all__ = ["decode", "schema_descriptors"]


def schema_descriptors(file_descriptor_set: bytes) -> dict:
    """Full message name -> {field number: (name, type, type_name, repeated)} from a FileDescriptorSet."""
    messages = {}

    def message(buf, scope):
        name, fields = None, {}
        nested = []
        for number, _, value in read_fields(buf):
            if number == 1:
                name = value.decode()
            elif number == 2:  # FieldDescriptorProto
                f = {n: v for n, _, v in read_fields(value)}
                fields[f[3]] = (f[1].decode(), f.get(5), f.get(6, b"").decode().lstrip("."), f.get(4) == 3)
            elif number == 3:
                nested.append(value)
        full = f"{scope}.{name}" if scope else name
        messages[full] = fields
        for buf_nested in nested:
            message(buf_nested, full)

    for number, _, file_buf in read_fields(file_descriptor_set):
        if number != 1:
            continue
        package = ""
        bodies = []
        for n, _, v in read_fields(file_buf):
            if n == 2:
                package = v.decode()
            elif n == 4:
                bodies.append(v)
        for body in bodies:
            message(body, package)
    return messages


_SCALAR = {1: "<d", 2: "<f", 6: "<Q", 7: "<I", 15: "<i", 16: "<q"}


def decode(descriptors: dict, type_name: str, buf: bytes) -> dict:
    fields = descriptors[type_name]
    out = {}
    for number, wire, raw in read_fields(buf):
        if number not in fields:
            continue
        name, ftype, sub, repeated = fields[number]
        if ftype == 11:
            values = [decode(descriptors, sub, raw)]
        elif ftype == 9:
            values = [raw.decode()]
        elif ftype == 12:
            values = [raw]
        elif ftype in _SCALAR:
            fmt = _SCALAR[ftype]
            if wire == 2:  # packed
                size = struct.calcsize(fmt)
                values = [struct.unpack(fmt, raw[k:k + size])[0] for k in range(0, len(raw), size)]
            else:
                values = [struct.unpack(fmt, raw)[0]]
        else:  # varint kinds (int, uint, bool, enum)
            values = [raw] if wire == 0 else []
            if wire == 2:
                k = 0
                while k < len(raw):
                    v, k = read_varint(raw, k)
                    values.append(v)
        if repeated:
            out.setdefault(name, []).extend(values)
        else:
            out[name] = values[-1]
    return out
