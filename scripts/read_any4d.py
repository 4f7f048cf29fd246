#!/usr/bin/env python3
"""Reading any4d's files from Python with numpy alone (docs/pytorch.md): a store's `clips.bin` and a
safetensors export (`any4d model export`), so a PyTorch user can train on any4d stores and compare with any4d's
models without Rust.

  python3 scripts/read_any4d.py store STORE_DIR             # T, P, clip count, the first clip's fields
  python3 scripts/read_any4d.py weights FILE.safetensors    # metadata, tensor names, shapes, dtypes
  python3 scripts/read_any4d.py check FILE.safetensors EXPECTED.json
      # every tensor of FILE against EXPECTED (written by any4d's test: its parameters in burn's layout and which
      # AnimateAnyMesh name each has): same names, shapes, and values (Linear weights transposed)

Import the functions (`read_safetensors`, `read_store`) into your own code; with torch installed,
`torch.from_numpy(array)` turns any array into a tensor.
"""

import json
import struct
import sys

import numpy as np

DTYPES = {"F64": np.float64, "F32": np.float32, "F16": np.float16, "I64": np.int64, "I32": np.int32,
          "U8": np.uint8, "BOOL": np.bool_}


def read_safetensors(path):
    """(metadata dict, {name: numpy array}) of a safetensors file: an 8-byte little-endian header length, a JSON
    header naming each tensor's dtype, shape and byte range, then the data."""
    with open(path, "rb") as f:
        data = f.read()
    (n,) = struct.unpack("<Q", data[:8])
    if n > len(data) - 8:
        raise ValueError(f"{path}: header of {n} bytes in a file of {len(data)}")
    header = json.loads(data[8:8 + n])
    meta = header.pop("__metadata__", {})
    body = memoryview(data)[8 + n:]
    tensors = {}
    for name, info in header.items():
        start, end = info["data_offsets"]
        if info["dtype"] == "BF16":  # numpy has no bfloat16: its 16 bits are the top half of a float32
            raw = np.frombuffer(body[start:end], dtype="<u2").astype(np.uint32) << 16
            tensors[name] = raw.view(np.float32).reshape(info["shape"])
            continue
        if info["dtype"] not in DTYPES:
            raise ValueError(f"{path}: tensor {name}: dtype {info['dtype']} is not read here")
        dtype = DTYPES[info["dtype"]]
        tensors[name] = np.frombuffer(body[start:end], dtype=np.dtype(dtype).newbyteorder("<")).reshape(info["shape"])
    return meta, tensors


def read_store(store_dir):
    """(T, P, [clip dicts]) of a store's clips.bin (layout in data/src/store/mod.rs): each clip with `id`, `caption`,
    `source`, `vertices` (T, N, 3) float32 normalised, `faces` (M, 3) uint32, `fps` (P,) uint32, `center` (3,),
    `scale`, `split` ("train" or "val") and `scene` (None, or `vertices` (S, 3) and `faces` (M, 3) of the static scene,
    normalised as the clip). Positions in the file's units are `vertices * scale + center`."""
    with open(f"{store_dir}/clips.bin", "rb") as f:
        data = f.read()
    if data[:8] != b"A4DSTORE" or data[-8:] != b"A4DTABLE":
        raise ValueError(f"{store_dir}/clips.bin: not an any4d store (or a truncated one)")
    version, t, p, flags = struct.unpack_from("<4I", data, 8)
    if version != 1:
        raise ValueError(f"{store_dir}/clips.bin: layout version {version}, this reader knows 1")
    table, count = struct.unpack_from("<QQ", data, len(data) - 24)
    clips = []
    for k in range(count):
        offset, split = struct.unpack_from("<QB", data, table + 9 * k)
        at = offset
        fields = []
        for _ in range(3):
            (n,) = struct.unpack_from("<I", data, at)
            fields.append(data[at + 4:at + 4 + n].decode("utf-8"))
            at += 4 + n
        ct, cn, cm, cp = struct.unpack_from("<4I", data, at)
        at += 16

        def take(dtype, count, shape):
            nonlocal at
            a = np.frombuffer(data, dtype=dtype, count=count, offset=at).reshape(shape)
            at += a.nbytes
            return a

        vertices = take("<f4", ct * cn * 3, (ct, cn, 3))
        faces = take("<u4", cm * 3, (cm, 3))
        fps = take("<u4", cp, (cp,))
        center = take("<f4", 3, (3,))
        (scale,) = take("<f4", 1, (1,))
        scene = None
        if flags & 1:  # a scene section: counts, then vertices (normalised as the clip) and faces; 0, 0 = none
            sv, sm = struct.unpack_from("<2I", data, at)
            at += 8
            sverts, sfaces = take("<f4", sv * 3, (sv, 3)), take("<u4", sm * 3, (sm, 3))
            scene = {"vertices": sverts, "faces": sfaces} if sv or sm else None
        clips.append({"id": fields[0], "caption": fields[1], "source": fields[2], "vertices": vertices,
                      "faces": faces, "fps": fps, "center": center, "scale": float(scale),
                      "split": "val" if split else "train", "scene": scene})
    return t, p, clips


def check(path, expected_path):
    """Compares a safetensors export with the parameters any4d's test wrote; raises on the first difference."""
    meta, tensors = read_safetensors(path)
    with open(expected_path) as f:
        expected = json.load(f)
    names = {aam: ours for aam, ours in expected["pairs"]}
    extra = set(tensors) - set(names) - set(expected.get("buffers", []))
    if extra:
        raise ValueError(f"tensors with no any4d parameter: {sorted(extra)}")
    for aam, ours in names.items():
        if aam not in tensors:
            raise ValueError(f"missing {aam}")
        want = np.array(expected["params"][ours]["values"], dtype=np.float32).reshape(expected["params"][ours]["shape"])
        if want.ndim == 2 and ours.endswith(".weight"):
            want = want.T  # burn keeps a Linear weight [in, out], PyTorch [out, in]
        got = tensors[aam]
        if got.dtype != np.float32 or got.shape != want.shape or not np.array_equal(got, want):
            raise ValueError(f"{aam}: {got.dtype} {got.shape} differs from {ours} {want.shape}")
    print(f"ok: {len(names)} tensors match; metadata {sorted(meta)}")


def main(argv):
    if len(argv) >= 2 and argv[0] == "store":
        t, p, clips = read_store(argv[1])
        print(f"T {t} P {p} clips {len(clips)}")
        if clips:
            c = clips[0]
            print(f"first: {c['id']!r} {c['caption']!r} vertices {c['vertices'].shape} faces {c['faces'].shape} "
                  f"fps {c['fps'].shape} split {c['split']}")
            scenes = sum(c["scene"] is not None for c in clips)
            print(f"scenes {scenes}")
    elif len(argv) >= 2 and argv[0] == "weights":
        meta, tensors = read_safetensors(argv[1])
        print(json.dumps({k: v for k, v in meta.items() if k != "any4d.config"}))
        for name, a in sorted(tensors.items()):
            print(f"{name} {a.dtype} {list(a.shape)}")
    elif len(argv) >= 3 and argv[0] == "check":
        check(argv[1], argv[2])
    else:
        print(__doc__, file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main(sys.argv[1:])
