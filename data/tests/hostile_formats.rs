//! Hostile clip files: each reproducer in `tests/fixtures/hostile/` (made by `scripts/make_hostile_fixtures.py`)
//! once made a reader panic, hang, ask for gigabytes or read something wrongly; now each is a clean error naming
//! the file and the field, or (duplicate keys, FRAME) what Python's `pickle.load` reads.

use std::path::{Path, PathBuf};
use std::process::Command;

use any4d_data::Clip;
use any4d_data::formats::dymesh_bin::{read_bin, read_bin_bytes};
use any4d_data::formats::gltf::{
    ExternalBuffers, GltfReadOptions, MAX_WRITE_FRAMES, read_gltf, read_gltf_bytes, write_gltf,
};
use any4d_data::formats::pickle::{ArrayData, DType, NdArray, Value, dumps, loads};
use any4d_data::formats::{PANIC_FIELD, read_clip};

fn hostile(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/hostile")
        .join(name)
}

fn gltf_fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/gltf")
        .join(name)
}

#[test]
fn pickle_bombs_are_refused_quickly() {
    for name in ["memo_bomb.bin", "binput_bomb.bin", "long_binput_bomb.bin"] {
        let e = read_bin(&hostile(name)).unwrap_err();
        assert!(e.path.ends_with(name) && e.field == "pickle", "{name}: {e}");
        assert!(e.reason.contains("pickle bomb"), "{name}: {e}");
    }
}

#[test]
fn frames_that_do_not_hold_their_bytes_are_refused() {
    let e = read_bin(&hostile("frame_overlong.bin")).unwrap_err();
    assert!(
        e.field == "pickle" && e.reason.contains("FRAME claims 1000000 bytes"),
        "{e}"
    );
    let e = read_bin(&hostile("frame_cross.bin")).unwrap_err();
    assert!(e.reason.contains("cross a frame end"), "{e}");
}

fn array(shape: Vec<usize>, data: ArrayData, dtype: DType) -> Value {
    Value::NdArray(NdArray { shape, dtype, data })
}

#[test]
fn duplicate_keys_read_as_python_reads_them() {
    // `vertices` twice: the first is a wrong shape, the last (the one Python keeps) is right.
    let good = array(
        vec![2, 3, 3],
        ArrayData::Float((0..18).map(f64::from).collect()),
        DType::F4,
    );
    let bad = array(vec![6], ArrayData::Float(vec![0.0; 6]), DType::F4);
    let faces = array(vec![1, 3], ArrayData::Int(vec![0, 1, 2]), DType::I8);
    let key = |k: &str| Value::Str(k.into());
    let dict = Value::Dict(vec![
        (key("vertices"), bad),
        (key("faces"), faces),
        (key("vertices"), good),
    ]);
    let clip = read_bin_bytes(&dumps(&dict).unwrap(), "dup.bin").unwrap();
    assert_eq!(
        (clip.frames, clip.n_vertices, clip.vertices[4]),
        (2, 3, [12.0, 13.0, 14.0])
    );
}

/// `repr()` of what Python's pickle module reads from `bytes`, or `None` without python3.
fn python_repr(bytes: &[u8]) -> Option<String> {
    let hex: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
    let out = Command::new("python3")
        .args([
            "-c",
            "import pickle,sys; print(repr(pickle.loads(bytes.fromhex(sys.argv[1]))))",
            &hex,
        ])
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// Python's `repr()` of the plain values these tests use.
fn repr(v: &Value) -> String {
    let all = |items: &[Value]| items.iter().map(repr).collect::<Vec<_>>().join(", ");
    match v {
        Value::None => "None".into(),
        Value::Bool(b) => if *b { "True" } else { "False" }.into(),
        Value::Int(i) => i.to_string(),
        Value::Float(f) => format!("{f:?}"),
        Value::Str(s) => format!("'{s}'"),
        Value::List(items) => format!("[{}]", all(items)),
        Value::Tuple(items) if items.len() == 1 => format!("({},)", repr(&items[0])),
        Value::Tuple(items) => format!("({})", all(items)),
        Value::Dict(kv) => format!(
            "{{{}}}",
            kv.iter()
                .map(|(k, v)| format!("{}: {}", repr(k), repr(v)))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        other => format!("{other:?}"),
    }
}

#[test]
fn plain_pickles_read_as_python_reads_them() {
    let cases: Vec<Vec<u8>> = vec![
        // {'a': 1, 'b': 2, 'a': 3}
        b"\x80\x02}(\x8c\x01aK\x01\x8c\x01bK\x02\x8c\x01aK\x03u.".to_vec(),
        // {1: 'x', True: 'y', 1.0: 'z'}
        b"\x80\x02(K\x01\x8c\x01x\x88\x8c\x01yG?\xf0\x00\x00\x00\x00\x00\x00\x8c\x01zd.".to_vec(),
        // x = [1]; (x, x) as protocol 4 writes it, in a FRAME
        b"\x80\x04\x95\x0a\x00\x00\x00\x00\x00\x00\x00]\x94K\x01ah\x00\x86\x94.".to_vec(),
        // x = [1]; {'a': x, 'b': x} as protocol 2 writes it
        b"\x80\x02}q\x00(X\x01\x00\x00\x00aq\x01]q\x02K\x01aX\x01\x00\x00\x00bq\x03h\x02u.".to_vec(),
    ];
    for bytes in cases {
        let ours = repr(&loads(&bytes, "t").unwrap());
        match python_repr(&bytes) {
            None => {
                println!("skipped: python3 not found");
                return;
            }
            Some(theirs) => assert_eq!(ours, theirs, "{bytes:?}"),
        }
    }
}

/// A glTF hostile fixture, read: the error must name the file and never be a caught panic.
fn gltf_error(name: &str) -> any4d_data::DataError {
    let e = read_gltf(&hostile(name), &GltfReadOptions::default()).unwrap_err();
    assert!(e.path.ends_with(name), "{name}: {e}");
    assert_ne!(e.field, PANIC_FIELD, "{name}: {e}");
    e
}

#[test]
fn unbounded_frame_counts_are_refused_or_cut() {
    let e = gltf_error("key_time_1e8.gltf");
    assert!(
        e.field == "animations" && e.reason.contains("more than the limit of 10000 frames"),
        "{e}"
    );
    let opts = GltfReadOptions {
        max_frames: Some(40),
        ..GltfReadOptions::default()
    };
    assert_eq!(read_gltf(&hostile("key_time_1e8.gltf"), &opts).unwrap().frames, 40);
}

#[test]
fn the_seven_gltf_crate_panics_are_errors() {
    for (name, field, reason) in [
        (
            "indices_float.gltf",
            "indices (accessors[1])",
            "is SCALAR of FLOAT, expected SCALAR of UNSIGNED_BYTE",
        ),
        ("indices_byte.gltf", "indices (accessors[1])", "is SCALAR of BYTE"),
        ("indices_short.gltf", "indices (accessors[1])", "is SCALAR of SHORT"),
        (
            "output_uint.gltf",
            "channels[0] output (accessors[5])",
            "is SCALAR of UNSIGNED_INT",
        ),
        (
            "stride_small.gltf",
            "POSITION (accessors[0])",
            "byteStride 4 is smaller than one VEC3 element",
        ),
        (
            "target_node_99.gltf",
            "channels[0].target.node",
            "node 99 does not exist",
        ),
        ("target_path_bogus.gltf", "channels[0].target.path", "not translation"),
        ("joints_float.gltf", "JOINTS_0 (accessors[2])", "is VEC4 of FLOAT"),
        ("uri_percent_ff.gltf", "buffers[0]", "not UTF-8"),
    ] {
        let e = gltf_error(name);
        assert!(e.field.contains(field) && e.reason.contains(reason), "{name}: {e}");
    }
}

#[test]
fn wrong_types_and_out_of_buffer_targets_are_errors() {
    for (name, field, reason) in [
        (
            "position_vec2.gltf",
            "POSITION (accessors[0])",
            "is VEC2 of FLOAT, expected VEC3 of FLOAT",
        ),
        (
            "position_ubyte.gltf",
            "POSITION (accessors[0])",
            "is VEC3 of UNSIGNED_BYTE",
        ),
        (
            "morph_outside_buffer.gltf",
            "morph target 1 POSITION",
            "buffer view 3 covers bytes 180..180+48",
        ),
        (
            "buffer_short.gltf",
            "buffers[0]",
            "holds 192 bytes, byteLength says 400",
        ),
        ("glb_header_short.glb", "glb", "header length 8"),
    ] {
        let e = gltf_error(name);
        assert!(e.field.contains(field) && e.reason.contains(reason), "{name}: {e}");
    }
}

#[test]
fn buffer_uris_stay_inside_the_folder() {
    for (name, reason) in [
        ("uri_absolute.gltf", "not a relative path"),
        ("uri_parent.gltf", "not a relative path"),
        ("uri_dev_zero.gltf", "not a relative path"),
    ] {
        let e = gltf_error(name);
        assert!(e.field == "buffers[0]" && e.reason.contains(reason), "{name}: {e}");
    }
    let dir = tempfile::tempdir().unwrap();
    let gltf = dir.path().join("uri_fifo.gltf");
    std::fs::copy(hostile("uri_fifo.gltf"), &gltf).unwrap();
    // A symlink inside the folder that leads out of it (to /dev/zero, to a regular file elsewhere).
    #[cfg(unix)]
    {
        let outside = tempfile::tempdir().unwrap();
        std::fs::write(outside.path().join("data.bin"), vec![0u8; 192]).unwrap();
        for target in [Path::new("/dev/zero").to_path_buf(), outside.path().join("data.bin")] {
            let link = dir.path().join("fifo.bin");
            let _ = std::fs::remove_file(&link);
            std::os::unix::fs::symlink(&target, &link).unwrap();
            let e = read_gltf(&gltf, &GltfReadOptions::default()).unwrap_err();
            assert!(e.reason.contains("outside the glTF file's folder"), "{target:?}: {e}");
        }
        std::fs::remove_file(dir.path().join("fifo.bin")).unwrap();
    }
    // A FIFO (reading it would block forever).
    let made = Command::new("mkfifo").arg(dir.path().join("fifo.bin")).status();
    if made.is_ok_and(|s| s.success()) {
        let e = read_gltf(&gltf, &GltfReadOptions::default()).unwrap_err();
        assert!(e.reason.contains("not a regular file"), "{e}");
    } else {
        println!("skipped the FIFO case: mkfifo not available");
    }
    // The same buffer as a regular file next to the glTF reads exactly like the embedded one.
    std::fs::remove_file(dir.path().join("fifo.bin")).ok();
    let doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(gltf_fixture("morph_square.gltf")).unwrap()).unwrap();
    let uri = doc["buffers"][0]["uri"].as_str().unwrap();
    let raw = base64_decode(uri.split_once(',').unwrap().1);
    std::fs::write(dir.path().join("fifo.bin"), raw).unwrap();
    let external = read_gltf(&gltf, &GltfReadOptions::default()).unwrap();
    let embedded = read_gltf(&gltf_fixture("morph_square.gltf"), &GltfReadOptions::default()).unwrap();
    assert_eq!(external.vertices, embedded.vertices);
    // Read from memory without a folder, a file URI is refused.
    let bytes = std::fs::read(&gltf).unwrap();
    let e = read_gltf_bytes(&bytes, &gltf, &GltfReadOptions::default(), &ExternalBuffers::Refuse).unwrap_err();
    assert!(e.reason.contains("external buffers are not read here"), "{e}");
}

fn base64_decode(s: &str) -> Vec<u8> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' => 62,
        _ => 63,
    };
    let digits: Vec<u8> = s.bytes().filter(|&c| c != b'=').map(value).collect();
    digits
        .chunks(4)
        .flat_map(|c| {
            let w = c
                .iter()
                .enumerate()
                .fold(0u32, |w, (i, &d)| w | (d as u32) << (18 - 6 * i));
            let n = c.len() * 6 / 8;
            (0..n).map(move |k| (w >> (16 - 8 * k)) as u8)
        })
        .collect()
}

#[test]
fn writer_refuses_clips_it_would_square() {
    let frames = MAX_WRITE_FRAMES + 1;
    let v = (0..frames)
        .flat_map(|f| [[0.0, 0.0, f as f32], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
        .collect();
    let clip = Clip::new("long", v, frames, 3, vec![[0, 1, 2]], "", "mem").unwrap();
    let dir = tempfile::tempdir().unwrap();
    let e = write_gltf(&dir.path().join("long.glb"), &clip, 30.0).unwrap_err();
    assert!(e.field == "frames" && e.reason.contains("at most 4096 frames"), "{e}");
    assert!(
        std::fs::read_dir(dir.path()).unwrap().next().is_none(),
        "nothing is written"
    );
}

#[test]
fn non_regular_files_are_not_read() {
    // A folder named like a clip file, and a device (no allocation from /dev/zero's endless bytes).
    let dir = tempfile::tempdir().unwrap();
    let fake = dir.path().join("folder.bin");
    std::fs::create_dir(&fake).unwrap();
    let e = read_bin(&fake).unwrap_err();
    assert!(e.reason.contains("not a regular file"), "{e}");
    #[cfg(unix)]
    {
        let link = dir.path().join("zero.glb");
        std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
        let e = read_clip(&link).unwrap_err();
        assert!(e.reason.contains("not a regular file"), "{e}");
    }
}
