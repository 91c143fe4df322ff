"""The one content hash: SHA-256 of a value's data, injective over the values it takes.

Each value is fed with a type tag and its length, so no two different values share a
byte stream: text, numbers (floats by their 8 bytes, so 0.1 and 0.1000001 differ), None,
booleans, lists/tuples, dicts (keys sorted), numpy arrays (dtype, shape, bytes) and
dataclasses (their fields by name). Task definitions, case data and operating points are
hashed with it (run folders: docs/CONTRACTS.md).
"""

from __future__ import annotations

import dataclasses
import hashlib
import struct

import numpy as np


def digest(value: object) -> str:
    """Hex SHA-256 of `value` (see the module docstring); TypeError for other types."""
    h = hashlib.sha256()
    _feed(h, value)
    return h.hexdigest()


def _tag(h: "hashlib._Hash", tag: bytes, payload: bytes) -> None:
    h.update(tag + struct.pack("<Q", len(payload)) + payload)


def _feed(h: "hashlib._Hash", value: object) -> None:
    if value is None:
        _tag(h, b"N", b"")
    elif isinstance(value, (bool, np.bool_)):
        _tag(h, b"B", b"1" if value else b"0")
    elif isinstance(value, (int, np.integer)):
        _tag(h, b"I", str(int(value)).encode())
    elif isinstance(value, (float, np.floating)):
        _tag(h, b"F", struct.pack("<d", float(value)))
    elif isinstance(value, complex):
        _tag(h, b"C", struct.pack("<dd", value.real, value.imag))
    elif isinstance(value, str):
        _tag(h, b"S", value.encode("utf-8", "surrogatepass"))
    elif isinstance(value, bytes):
        _tag(h, b"Y", value)
    elif isinstance(value, np.ndarray):
        array = np.ascontiguousarray(value)
        if array.dtype.kind == "O":
            _tag(h, b"O", str(array.shape).encode())
            for item in array.reshape(-1):
                _feed(h, item)
        else:
            _tag(h, b"A", f"{array.dtype.str}{array.shape}".encode())
            h.update(array.tobytes())
    elif isinstance(value, (list, tuple)):
        _tag(h, b"L", str(len(value)).encode())
        for item in value:
            _feed(h, item)
    elif isinstance(value, dict):
        _tag(h, b"D", str(len(value)).encode())
        for key in sorted(value, key=str):
            _feed(h, str(key))
            _feed(h, value[key])
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        _tag(h, b"R", type(value).__qualname__.encode())
        for f in dataclasses.fields(value):
            _feed(h, f.name)
            _feed(h, getattr(value, f.name))
    else:
        raise TypeError(f"cannot hash a {type(value).__name__}")
