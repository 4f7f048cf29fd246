#!/usr/bin/env python3
"""Write the clip-format test fixtures of the data crate (docs/method.md §2.1) into data/tests/fixtures/.

bin/   DyMesh-style pickles made by real `pickle` + `numpy`: good ones (protocols 2/4/5, float32 Fortran order,
       big-endian, float16, bytes caption, ...) and bad ones (hostile globals, truncated, wrong rank, ...).
       bin/expected.json holds, for every good fixture, the float32 vertices numpy gives (`astype(float32)`),
       the faces and the caption, so the Rust tests compare against numpy rather than against themselves.
obj/   small OBJ sequences (natural frame order, quads, v/vt/vn syntax, caption.txt) and two bad ones.
gltf/  a morph-target cube and a skinned two-joint strip, written by hand with json + struct (no exporter),
       with their expected key positions stated in the Rust tests.

Usage: python3 scripts/make_fixtures.py   (needs numpy; prints every file it writes)
"""

import base64
import json
import os
import pickle
import struct
import sys

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "data", "tests", "fixtures")
# The hostile pickles would create these files if anything ever executed them; the tests assert they never appear.
PWNED_OS = "/tmp/any4d_fixture_pwned_os_system"
PWNED_EVAL = "/tmp/any4d_fixture_pwned_eval"


def write(rel, data):
    path = os.path.join(ROOT, rel)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    mode = "wb" if isinstance(data, bytes) else "w"
    with open(path, mode) as f:
        f.write(data)
    print(f"wrote {os.path.relpath(path)} ({len(data)} bytes)")


def verts(dtype="f8", frames=2, n=4):
    """v[f, n, c] = f + 0.1 n + 0.01 c, so float64 → float32 rounding is visible."""
    f = np.arange(frames, dtype=np.float64)[:, None, None]
    i = np.arange(n, dtype=np.float64)[None, :, None]
    c = np.arange(3, dtype=np.float64)[None, None, :]
    return (f + 0.1 * i + 0.01 * c).astype(dtype)


FACES = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)


class Hostile:
    """Pickles as a call of `func(arg)`; pickle.dumps never calls it."""

    def __init__(self, func, arg):
        self.func, self.arg = func, arg

    def __reduce__(self):
        return (self.func, (self.arg,))


def bin_fixtures():
    good = {
        "p2_f64": (dict(vertices=verts(), faces=FACES, caption="a square lifts"), 2),
        "p4_f64": (dict(vertices=verts(), faces=FACES, caption="a square lifts"), 4),
        "p5_f64": (dict(vertices=verts(), faces=FACES, caption="a square lifts"), 5),
        "fortran_f32": (dict(vertices=np.asfortranarray(verts("f4")),
                             faces=np.asfortranarray(FACES.astype(np.int32)), caption="fortran"), 4),
        "big_endian_f4": (dict(vertices=verts(">f4"), faces=FACES.astype(">i8"), caption="big"), 4),
        "float16": (dict(vertices=verts("f2"), faces=FACES.astype(np.uint32), caption="half"), 2),
        "bytes_caption": (dict(vertices=verts(), faces=FACES, caption="caf\u00e9 spins".encode("utf-8")), 2),
        "empty_caption": (dict(vertices=verts(), faces=FACES, caption=""), 4),
        "no_caption": (dict(vertices=verts(), faces=FACES), 4),
        "three_frames": (dict(vertices=verts(frames=3, n=5), faces=np.array([[0, 1, 4]]), caption="x"), 3),
    }
    expected = {}
    for name, (d, proto) in good.items():
        write(f"bin/{name}.bin", pickle.dumps(d, protocol=proto))
        cap = d.get("caption", " ")
        expected[name] = {
            "shape": list(d["vertices"].shape),
            "vertices": d["vertices"].astype(np.float32).reshape(-1).tolist(),
            "faces": d["faces"].reshape(-1).tolist(),
            "caption": cap.decode("utf-8") if isinstance(cap, bytes) else cap,
        }
    write("bin/expected.json", json.dumps(expected, indent=1) + "\n")

    ok = dict(vertices=verts(), faces=FACES, caption="c")
    nan = verts()
    nan[1, 2, 0] = np.nan
    bad = {
        "hostile_os_system": Hostile(os.system, f"echo pwned > {PWNED_OS}"),
        "hostile_builtins_eval": Hostile(eval, f"open({PWNED_EVAL!r}, 'w').write('pwned')"),
        "no_vertices": dict(faces=FACES, caption="c"),
        "no_faces": dict(vertices=verts(), caption="c"),
        "vertices_rank2": dict(vertices=verts()[0], faces=FACES, caption="c"),
        "vertices_last_dim4": dict(vertices=np.zeros((2, 4, 4)), faces=FACES, caption="c"),
        "faces_rank1": dict(vertices=verts(), faces=FACES.reshape(-1), caption="c"),
        "nan_coords": dict(vertices=nan, faces=FACES, caption="c"),
        "face_out_of_range": dict(vertices=verts(), faces=np.array([[0, 1, 4]]), caption="c"),
        "face_negative": dict(vertices=verts(), faces=np.array([[0, -1, 2]]), caption="c"),
        "zero_frames": dict(vertices=np.zeros((0, 4, 3)), faces=FACES, caption="c"),
        "caption_not_utf8": dict(vertices=verts(), faces=FACES, caption=b"\xff\xfe bad"),
        "caption_int": dict(vertices=verts(), faces=FACES, caption=7),
        "not_a_dict": [verts(), FACES],
    }
    for name, obj in bad.items():
        write(f"bin/bad_{name}.bin", pickle.dumps(obj, protocol=2 if "os_system" in name else 4))
    full = pickle.dumps(ok, protocol=4)
    write("bin/bad_truncated.bin", full[: len(full) // 2])
    write("bin/bad_not_pickle.bin", b"solid mesh\nthis is an STL file, not a pickle\n")


def obj_fixtures():
    # A unit quad (two triangles' worth, written as one polygon) lifted in z; files named 1, 2, 10 (natural order).
    quad = [(0, 0), (1, 0), (1, 1), (0, 1)]
    for k, z in [(1, 0.0), (2, 0.5), (10, 1.0)]:
        lines = [f"# frame {k}", "o quad"]
        lines += [f"v {x} {y} {z + 0.25 * x}" for x, y in quad]
        lines += ["vt 0 0", "vt 1 0", "vt 1 1", "vt 0 1", "vn 0 0 1"]
        lines += ["f 1/1/1 2/2/1 3/3/1 4/4/1"]
        write(f"obj/quad_seq/frame_{k}.obj", "\n".join(lines) + "\n")
    write("obj/quad_seq/caption.txt", "a quad rises\n")
    for k, n in [(0, 4), (1, 3)]:
        lines = [f"v {i} {i * i} 0" for i in range(n)] + ["f 1 2 3"]
        write(f"obj/bad_vertex_count/f{k}.obj", "\n".join(lines) + "\n")
    write("obj/bad_line/a.obj", "v 0 0 0\nv 1 0 0\nv 0 one 0\nf 1 2 3\n")
    write("obj/bad_line/b.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")


def gltf_doc(positions, indices, extra_buffers, nodes, mesh_extra, animations, skins=None):
    """Assemble a one-buffer embedded glTF from (name, bytes, accessor dict) pieces."""
    blobs, views, accessors = [], [], []

    def add(data, acc):
        off = sum(len(b) for b in blobs)
        blobs.append(data + b"\0" * (-len(data) % 4))
        views.append({"buffer": 0, "byteOffset": off, "byteLength": len(data)})
        accessors.append(dict(acc, bufferView=len(views) - 1))
        return len(accessors) - 1

    pos = np.asarray(positions, np.float32)
    ids = {"POSITION": add(pos.tobytes(), {"componentType": 5126, "count": len(pos), "type": "VEC3",
                                           "min": pos.min(0).tolist(), "max": pos.max(0).tolist()})}
    ids["indices"] = add(np.asarray(indices, np.uint16).tobytes(),
                         {"componentType": 5123, "count": len(indices), "type": "SCALAR"})
    for key, data, acc in extra_buffers:
        ids[key] = add(data, acc)
    buf = b"".join(blobs)
    prim = {"attributes": {"POSITION": ids["POSITION"]}, "indices": ids["indices"]}
    mesh = {"primitives": [prim]}
    mesh_extra(prim, mesh, ids)
    doc = {
        "asset": {"version": "2.0", "generator": "any4d scripts/make_fixtures.py"},
        "scene": 0, "scenes": [{"nodes": [0]}], "nodes": nodes, "meshes": [mesh],
        "animations": [animations(ids)], "accessors": accessors, "bufferViews": views,
        "buffers": [{"byteLength": len(buf),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(buf).decode()}],
    }
    if skins:
        doc["skins"] = skins(ids)
    return doc


def f32(a):
    return np.asarray(a, np.float32).tobytes()


def gltf_fixtures():
    # Morph: a unit square; target 0 lifts the square by +1 in z, target 1 moves x by +2. LINEAR weights
    # (0,0) at t=0, (1,0) at t=0.5, (0,1) at t=1.
    square = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    t0 = [[0, 0, 1]] * 4
    t1 = [[2, 0, 0]] * 4

    def morph_extra(prim, mesh, ids):
        prim["targets"] = [{"POSITION": ids["t0"]}, {"POSITION": ids["t1"]}]
        mesh["weights"] = [0.0, 0.0]

    vec3 = lambda a: {"componentType": 5126, "count": len(a), "type": "VEC3",
                      "min": np.min(a, 0).tolist(), "max": np.max(a, 0).tolist()}
    scalar = lambda a: {"componentType": 5126, "count": len(a), "type": "SCALAR",
                        "min": [float(min(a))], "max": [float(max(a))]}
    times = [0.0, 0.5, 1.0]
    weights = [0, 0, 1, 0, 0, 1]
    doc = gltf_doc(
        square, [0, 1, 2, 0, 2, 3],
        [("t0", f32(t0), vec3(t0)), ("t1", f32(t1), vec3(t1)),
         ("times", f32(times), scalar(times)),
         ("weights", f32(weights), {"componentType": 5126, "count": 6, "type": "SCALAR"})],
        [{"mesh": 0, "name": "square"}], morph_extra,
        lambda ids: {"channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}],
                     "samplers": [{"input": ids["times"], "output": ids["weights"], "interpolation": "LINEAR"}]},
    )
    write("gltf/morph_square.gltf", json.dumps(doc, indent=1) + "\n")

    # Skin: a strip of three rows (y = 0, 1, 2; x = ±0.5). Joint 0 (node 1) at the origin, joint 1 (node 2) its
    # child at y = 1. Rows: joint 0 only, half/half, joint 1 only. Joint 1 rotates 90° about z (LINEAR, t 0→1);
    # joint 0 jumps by x +1 at t = 0.5 (STEP).
    strip = [[-0.5, 0, 0], [0.5, 0, 0], [-0.5, 1, 0], [0.5, 1, 0], [-0.5, 2, 0], [0.5, 2, 0]]
    joints = np.array([[0, 1, 0, 0]] * 6, np.uint8)
    wts = np.array([[1, 0, 0, 0]] * 2 + [[0.5, 0.5, 0, 0]] * 2 + [[0, 1, 0, 0]] * 2, np.float32)
    ibm = np.stack([np.eye(4), np.eye(4)]).astype(np.float32)
    ibm[1, 3, 1] = -1.0  # column-major: translation (0, -1, 0) sits in the 4th column = ibm[1][3]
    s = np.sqrt(0.5)
    rot_t, rot = [0.0, 1.0], [0, 0, 0, 1, 0, 0, s, s]
    step_t, step = [0.0, 0.5], [0, 0, 0, 1, 0, 0]

    def skin_extra(prim, mesh, ids):
        prim["attributes"]["JOINTS_0"] = ids["joints"]
        prim["attributes"]["WEIGHTS_0"] = ids["wts"]

    doc = gltf_doc(
        strip, [0, 1, 3, 0, 3, 2, 2, 3, 5, 2, 5, 4],
        [("joints", joints.tobytes(), {"componentType": 5121, "count": 6, "type": "VEC4"}),
         ("wts", wts.tobytes(), {"componentType": 5126, "count": 6, "type": "VEC4"}),
         ("ibm", ibm.tobytes(), {"componentType": 5126, "count": 2, "type": "MAT4"}),
         ("rot_t", f32(rot_t), scalar(rot_t)),
         ("rot", f32(rot), {"componentType": 5126, "count": 2, "type": "VEC4"}),
         ("step_t", f32(step_t), scalar(step_t)),
         ("step", f32(step), {"componentType": 5126, "count": 2, "type": "VEC3"})],
        [{"mesh": 0, "skin": 0, "children": [1]}, {"children": [2]}, {"translation": [0, 1, 0]}],
        skin_extra,
        lambda ids: {"channels": [{"sampler": 0, "target": {"node": 2, "path": "rotation"}},
                                  {"sampler": 1, "target": {"node": 1, "path": "translation"}}],
                     "samplers": [{"input": ids["rot_t"], "output": ids["rot"], "interpolation": "LINEAR"},
                                  {"input": ids["step_t"], "output": ids["step"], "interpolation": "STEP"}]},
        skins=lambda ids: [{"joints": [1, 2], "inverseBindMatrices": ids["ibm"]}],
    )
    write("gltf/skin_strip.gltf", json.dumps(doc, indent=1) + "\n")

    # The morph square with its animation removed: reading it must fail with "no animation".
    del doc
    static = json.loads(open(os.path.join(ROOT, "gltf/morph_square.gltf")).read())
    static.pop("animations")
    write("gltf/static_square.gltf", json.dumps(static, indent=1) + "\n")


if __name__ == "__main__":
    print(f"numpy {np.__version__}, python {sys.version.split()[0]}")
    bin_fixtures()
    obj_fixtures()
    gltf_fixtures()
