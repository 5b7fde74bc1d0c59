#!/usr/bin/env python3
"""Rewrites a desplat checkpoint (include/desplat/io/checkpoint.hpp, format version 1) with
valid checksums after an edit, for hostile-input tests of what lies past the CRCs.

Usage: edit_checkpoint.py FILE EDIT
EDIT is Python run with `meta` (the metadata dict) and `arrays` (name -> [type, dims, bytearray])
in scope, plus helpers f32(name) / set_f32(name, values) and i32(name) / set_i32(name, values).
Example: edit_checkpoint.py ck.ckpt 'meta["step"] = -5'
"""
import json
import struct
import sys
import zlib

TYPES = {1: "f", 2: "i", 3: "B", 4: "Q"}


def read(path):
    b = open(path, "rb").read()
    magic, version, count, _reserved, _crc = struct.unpack_from("<8sIIII", b, 0)
    at = 24
    sections = []
    for _ in range(count):
        t, rank, name_len, size = struct.unpack_from("<BBHQ", b, at)
        at += 12
        dims = list(struct.unpack_from("<%dQ" % rank, b, at))
        at += 8 * rank
        name = b[at:at + name_len].decode()
        at += name_len + 4
        payload = bytearray(b[at:at + size])
        at += size + 4
        sections.append([t, dims, name, payload])
    return magic, version, sections


def write(path, magic, version, sections):
    head = struct.pack("<8sIII", magic, version, len(sections), 0)
    out = bytearray(head + struct.pack("<I", zlib.crc32(head)))
    for t, dims, name, payload in sections:
        h = struct.pack("<BBHQ", t, len(dims), len(name), len(payload)) + struct.pack("<%dQ" % len(dims), *dims) + name.encode()
        out += h + struct.pack("<I", zlib.crc32(h)) + payload + struct.pack("<I", zlib.crc32(payload))
    open(path, "wb").write(out)


def main():
    path, edit = sys.argv[1], sys.argv[2]
    magic, version, sections = read(path)
    meta = json.loads(sections[0][3].decode())
    arrays = {s[2]: [s[0], s[1], s[3]] for s in sections[1:]}

    def values(name, code):
        a = arrays[name]
        return list(struct.unpack("<%d%s" % (len(a[2]) // 4, code), a[2]))

    def set_values(name, code, v):
        arrays[name][2] = bytearray(struct.pack("<%d%s" % (len(v), code), *v))

    scope = {"meta": meta, "arrays": arrays, "nan": float("nan"), "inf": float("inf"),
             "f32": lambda n: values(n, "f"), "i32": lambda n: values(n, "i"),
             "set_f32": lambda n, v: set_values(n, "f", v), "set_i32": lambda n, v: set_values(n, "i", v)}
    exec(edit, scope)
    text = json.dumps(scope["meta"], allow_nan=False).encode()
    out = [[0, [len(text)], "metadata", bytearray(text)]]
    for name in sorted(arrays):
        t, dims, payload = arrays[name]
        out.append([t, dims, name, payload])
    write(path, magic, version, out)


if __name__ == "__main__":
    main()
