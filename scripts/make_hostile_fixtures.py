#!/usr/bin/env python3
"""Write the hostile-input reproducers of data/tests/fixtures/hostile/ (standard library only).

Each file is the smallest input that once made a reader panic, hang, allocate gigabytes or read something
wrongly; data/tests/hostile.rs checks that each now gives a clean error naming the file and the field. The glTF
cases are the two committed glTF fixtures with one field changed.

    python3 scripts/make_hostile_fixtures.py
"""

import base64
import copy
import json
import struct
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent / "data" / "tests" / "fixtures"
OUT = ROOT / "hostile"


def load(name):
    return json.loads((ROOT / "gltf" / name).read_text())


def write_json(name, doc):
    (OUT / name).write_text(json.dumps(doc, indent=1) + "\n")


def gltf_cases():
    morph = load("morph_square.gltf")
    skin = load("skin_strip.gltf")

    def variant(base, name, change):
        doc = copy.deepcopy(base)
        change(doc)
        write_json(name, doc)

    def set_last_key_time(doc):
        uri = doc["buffers"][0]["uri"]
        head, data = uri.split(",", 1)
        raw = bytearray(base64.b64decode(data))
        view = doc["bufferViews"][doc["accessors"][4]["bufferView"]]
        struct.pack_into("<f", raw, view["byteOffset"] + 8, 1e8)
        doc["buffers"][0]["uri"] = head + "," + base64.b64encode(bytes(raw)).decode()
        doc["accessors"][4]["max"] = [1e8]

    # One key time of 1e8 s: 3e9 frames at 30 fps (was: 288 GB asked for, abort).
    variant(morph, "key_time_1e8.gltf", set_last_key_time)

    def uri(value, length=None):
        def change(doc):
            doc["buffers"][0]["uri"] = value
            if length is not None:
                doc["buffers"][0]["byteLength"] = length
        return change

    # Buffer URIs outside the file's folder, a FIFO (made by the test), an undecodable escape, a short buffer.
    variant(morph, "uri_absolute.gltf", uri("/etc/passwd"))
    variant(morph, "uri_parent.gltf", uri("../gltf/morph_square.gltf"))
    variant(morph, "uri_dev_zero.gltf", uri("/dev/zero"))
    variant(morph, "uri_fifo.gltf", uri("fifo.bin"))
    variant(morph, "uri_percent_ff.gltf", uri("%ff"))
    variant(morph, "buffer_short.gltf", uri(morph["buffers"][0]["uri"], 400))

    def accessor(index, **fields):
        def change(doc):
            doc["accessors"][index].update(fields)
        return change

    # The seven gltf-crate panics.
    variant(morph, "indices_float.gltf", accessor(1, componentType=5126))
    variant(morph, "indices_byte.gltf", accessor(1, componentType=5120))
    variant(morph, "indices_short.gltf", accessor(1, componentType=5122))
    variant(morph, "output_uint.gltf", accessor(5, componentType=5125))

    def stride(doc):
        doc["bufferViews"][0]["byteStride"] = 4

    variant(morph, "stride_small.gltf", stride)

    def target(**fields):
        def change(doc):
            doc["animations"][0]["channels"][0]["target"].update(fields)
        return change

    variant(morph, "target_node_99.gltf", target(node=99))
    variant(morph, "target_path_bogus.gltf", target(path="bogus"))
    variant(skin, "joints_float.gltf", accessor(2, componentType=5126))

    # Wrong accessor types once read as f32 VEC3; a morph target outside its buffer once read as zeros.
    variant(morph, "position_vec2.gltf", accessor(0, type="VEC2"))
    variant(morph, "position_ubyte.gltf", accessor(0, componentType=5121))

    def view_offset(doc):
        doc["bufferViews"][3]["byteOffset"] = 180

    variant(morph, "morph_outside_buffer.gltf", view_offset)

    # GLB whose header length (8) is shorter than the header: an integer underflow in the gltf crate.
    chunk = b'{"asset":{"version":"2.0"}}  '
    glb = b"glTF" + struct.pack("<II", 2, 8) + struct.pack("<I", len(chunk)) + b"JSON" + chunk
    (OUT / "glb_header_short.glb").write_bytes(glb)


def doubled(doublings):
    """PROTO 4, None, then DUP + TUPLE2 `doublings` times: a tuple tree of 2^(doublings+1) - 1 values."""
    return b"\x80\x04N" + b"2\x86" * doublings


def pickle_cases():
    # The 86-byte memo bomb: 21 doublings, then 40 MEMOIZE (each copied the whole tree: 7.7 GB).
    (OUT / "memo_bomb.bin").write_bytes(doubled(21) + b"\x94" * 40 + b".")
    # BINPUT / LONG_BINPUT of a 65535-value tree, then 40 BINGET + POP: each fetch copies the tree.
    for name, put in [("binput_bomb.bin", b"q\x07"), ("long_binput_bomb.bin", b"r\x07\x00\x00\x00")]:
        (OUT / name).write_bytes(doubled(15) + put + b"h\x070" * 40 + b".")
    # FRAME that claims 1,000,000 bytes with 3 left; FRAME that ends inside an opcode's argument.
    (OUT / "frame_overlong.bin").write_bytes(b"\x80\x04\x95" + struct.pack("<Q", 1_000_000) + b"K\x01.")
    (OUT / "frame_cross.bin").write_bytes(b"\x80\x04\x95" + struct.pack("<Q", 1) + b"K\x01.")


def main():
    OUT.mkdir(exist_ok=True)
    gltf_cases()
    pickle_cases()
    print(f"wrote {len(list(OUT.iterdir()))} files to {OUT}")


if __name__ == "__main__":
    main()
