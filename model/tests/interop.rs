//! Weights in and out of safetensors (docs/method.md §12): AnimateAnyMesh's names and shapes at the paper sizes,
//! round trips under both names, and files that are broken or lie.

use std::collections::BTreeMap;
use std::path::Path;

use any4d_model::dymesh_vae::DyMeshVaeConfig;
use any4d_model::frame_vae::{FrameVae, FrameVaeConfig};
use any4d_model::interop::{
    FileTensor, Names, Network, aam_vae_buffers, collect_tensors, file_names, read_file, write_file,
};
use any4d_model::mmdit::{KeyframeConditioning, MmditConfig};
use burn::module::Module;
use burn::prelude::*;

/// `{network: [[key, shape], …]}` of AAM's modules at the paper sizes, written by
/// `python3 scripts/torch_parity.py keys --aam DIR` from AnimateAnyMesh's own `state_dict()`.
fn aam_keys() -> serde_json::Value {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/aam_state_dict_keys.json");
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

fn listed(v: &serde_json::Value) -> BTreeMap<String, Vec<usize>> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|kv| {
            let shape = kv[1]
                .as_array()
                .unwrap()
                .iter()
                .map(|d| d.as_u64().unwrap() as usize)
                .collect();
            (kv[0].as_str().unwrap().to_owned(), shape)
        })
        .collect()
}

fn ours<M: Module>(m: &M, network: Network) -> BTreeMap<String, Vec<usize>> {
    let map: BTreeMap<String, Vec<usize>> = file_names(m, network, Names::AnimateAnyMesh)
        .into_iter()
        .map(|(_, name, shape)| (name, shape))
        .collect();
    assert_eq!(
        map.len(),
        file_names(m, network, Names::AnimateAnyMesh).len(),
        "two parameters, one name"
    );
    map
}

#[test]
fn aam_names_and_shapes_are_animateanymesh_state_dicts_at_the_paper_sizes() {
    let dev = Device::flex();
    let want = aam_keys();
    let mmdit = MmditConfig::paper(KeyframeConditioning::InputMask, 768).init(&dev);
    assert_eq!(ours(&mmdit, Network::Mmdit), listed(&want["mmdit"]));
    for (network, key, cfg) in [
        (Network::FrameVae, "frame_vae", None),
        (Network::DyMeshVae, "dymesh_vae", Some(DyMeshVaeConfig::paper())),
    ] {
        let mut got = match &cfg {
            None => ours(&FrameVaeConfig::paper().init(&dev), network),
            Some(c) => ours(&c.init(&dev), network),
        };
        let (point_freqs, offset_freqs) = match &cfg {
            None => (
                FrameVaeConfig::paper().body.point_freqs,
                FrameVaeConfig::paper().offset_freqs,
            ),
            Some(c) => (c.body.point_freqs, c.offset_freqs),
        };
        for (name, shape, _) in aam_vae_buffers(point_freqs, offset_freqs) {
            got.insert(name, shape);
        }
        assert_eq!(got, listed(&want[key]), "{key}");
    }
}

fn tiny_vae(seed: u64) -> FrameVae {
    let dev = Device::flex();
    dev.seed(seed);
    FrameVaeConfig::tiny().init(&dev)
}

fn values<M: Module>(m: &M) -> Vec<f32> {
    collect_tensors(m, Network::FrameVae, Names::Any4d)
        .into_iter()
        .flat_map(|t| {
            t.bytes
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
                .collect::<Vec<_>>()
        })
        .collect()
}

#[test]
fn a_network_round_trips_under_both_names_and_aam_layouts_are_transposed() {
    let dir = tempfile::tempdir().unwrap();
    let original = tiny_vae(1);
    for names in [Names::Any4d, Names::AnimateAnyMesh] {
        let path = dir.path().join(format!("{}.safetensors", names.name()));
        let tensors = collect_tensors(&original, Network::FrameVae, names);
        write_file(&path, &tensors, BTreeMap::from([("k".to_owned(), "v".to_owned())])).unwrap();
        let mut other = tiny_vae(2);
        assert_ne!(values(&other), values(&original));
        let report = read_file(&mut other, &path, Network::FrameVae, names, &[]).unwrap();
        assert_eq!(values(&other), values(&original), "{names:?}");
        assert_eq!(report.metadata["k"], "v");
    }
    // A Linear weight is [in, out] under any4d's names and [out, in] under AAM's, with the same values.
    let find = |names, name: &str| {
        collect_tensors(&original, Network::FrameVae, names)
            .into_iter()
            .find(|t| t.name == name)
            .unwrap()
    };
    let ours = find(Names::Any4d, "body.point_embed.linear.weight");
    let theirs = find(Names::AnimateAnyMesh, "point_embed.mlp.weight");
    assert_eq!(ours.shape, [theirs.shape[1], theirs.shape[0]]);
    let f = |t: &FileTensor, i: usize| f32::from_le_bytes(t.bytes[4 * i..4 * i + 4].try_into().unwrap());
    let (rows, cols) = (ours.shape[0], ours.shape[1]);
    for (r, c) in [(0, 0), (1, 2), (rows - 1, cols - 1)] {
        assert_eq!(f(&ours, r * cols + c), f(&theirs, c * rows + r));
    }
}

/// A safetensors file of `tensors` (name, dtype, shape, little-endian bytes) as the format lays it out.
fn raw_file(tensors: &[(&str, &str, Vec<usize>, Vec<u8>)]) -> Vec<u8> {
    let mut header = serde_json::Map::new();
    let mut data: Vec<u8> = Vec::new();
    for (name, dtype, shape, bytes) in tensors {
        header.insert(
            (*name).to_owned(),
            serde_json::json!({"dtype": dtype, "shape": shape, "data_offsets": [data.len(), data.len() + bytes.len()]}),
        );
        data.extend(bytes);
    }
    let mut head = serde_json::to_vec(&header).unwrap();
    while !head.len().is_multiple_of(8) {
        head.push(b' ');
    }
    let mut out = (head.len() as u64).to_le_bytes().to_vec();
    out.extend(head);
    out.extend(data);
    out
}

#[test]
fn broken_and_lying_files_are_refused_naming_the_tensor_and_leave_the_network_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let original = tiny_vae(1);
    let good = collect_tensors(&original, Network::FrameVae, Names::Any4d);
    let as_raw = |t: &FileTensor| (t.name.clone(), "F32", t.shape.clone(), t.bytes.clone());
    let mut cases: Vec<(&str, Vec<u8>, &str)> = Vec::new();
    let entries: Vec<(String, &str, Vec<usize>, Vec<u8>)> = good.iter().map(as_raw).collect();
    let file = |e: &[(String, &str, Vec<usize>, Vec<u8>)]| {
        let refs: Vec<(&str, &str, Vec<usize>, Vec<u8>)> = e
            .iter()
            .map(|(n, d, s, b)| (n.as_str(), *d, s.clone(), b.clone()))
            .collect();
        raw_file(&refs)
    };
    let missing = good[3].name.clone();
    cases.push((
        "missing",
        file(&entries[..3].iter().chain(&entries[4..]).cloned().collect::<Vec<_>>()),
        &missing,
    ));
    let mut extra = entries.clone();
    extra.push(("body.spare.weight".into(), "F32", vec![1], vec![0; 4]));
    cases.push(("extra", file(&extra), "body.spare.weight"));
    let mut shape = entries.clone();
    let s = &mut shape[5];
    s.2 = vec![s.3.len() / 4];
    let shape_name = s.0.clone();
    cases.push(("shape", file(&shape), &shape_name));
    let mut dtype = entries.clone();
    dtype[7].1 = "I32";
    let dtype_name = dtype[7].0.clone();
    cases.push(("dtype", file(&dtype), &dtype_name));
    let whole = file(&entries);
    cases.push(("truncated header", whole[..40].to_vec(), ""));
    let mut long = whole.clone();
    long[..8].copy_from_slice(&(1u64 << 40).to_le_bytes());
    cases.push(("header past the end", long, ""));
    cases.push(("empty", Vec::new(), ""));
    for (what, bytes, tensor) in cases {
        let path = dir.path().join(format!("{what}.safetensors"));
        std::fs::write(&path, bytes).unwrap();
        let mut target = tiny_vae(2);
        let before = values(&target);
        let e = read_file(&mut target, &path, Network::FrameVae, Names::Any4d, &[]).unwrap_err();
        assert_eq!(e.tensor, tensor, "{what}: {e}");
        assert!(e.to_string().contains(&*path.display().to_string()), "{what}: {e}");
        assert_eq!(values(&target), before, "{what}: the network changed");
    }
    // A float tensor stored in f64 or f16 is read (cast to f32).
    let mut wide = entries.clone();
    let w = &mut wide[0];
    w.1 = "F64";
    w.3 =
        w.3.chunks_exact(4)
            .flat_map(|b| f64::from(f32::from_le_bytes(b.try_into().unwrap())).to_le_bytes())
            .collect();
    let path = dir.path().join("f64.safetensors");
    std::fs::write(&path, file(&wide)).unwrap();
    let mut target = tiny_vae(2);
    read_file(&mut target, &path, Network::FrameVae, Names::Any4d, &[]).unwrap();
    assert_eq!(values(&target), values(&original));
    // In f16 too, within its rounding.
    let mut half = entries.clone();
    let h = &mut half[0];
    h.1 = "F16";
    let floats: Vec<f32> =
        h.3.chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect();
    let n16 = floats.len();
    h.3 = burn::tensor::TensorData::new(floats, [n16])
        .convert_dtype(burn::tensor::DType::F16)
        .as_bytes()
        .to_vec();
    let path = dir.path().join("f16.safetensors");
    std::fs::write(&path, file(&half)).unwrap();
    read_file(&mut target, &path, Network::FrameVae, Names::Any4d, &[]).unwrap();
    let first = &good[0];
    let n = first.bytes.len() / 4;
    for (got, want) in values(&target)[..n].iter().zip(values(&original)[..n].iter()) {
        assert!((got - want).abs() <= 1e-3 * want.abs().max(1e-2), "{got} vs {want}");
    }
}

/// AnimateAnyMesh's training checkpoint (a dictionary holding `model_state_dict`, an optimiser state and argparse
/// options) is read by burn's pickle reader; a pickle that would run code when loaded is refused without running it
/// (both written by scripts/make_interop_fixtures.py).
#[test]
fn pytorch_checkpoints_are_read_by_burns_reader_and_code_in_a_pickle_never_runs() {
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures");
    let mut vae = tiny_vae(3);
    let path = fixtures.join("aam_tiny_frame_vae.pth");
    let tiny = FrameVaeConfig::tiny();
    let constants = aam_vae_buffers(tiny.body.point_freqs, tiny.offset_freqs);
    let report = read_file(&mut vae, &path, Network::FrameVae, Names::AnimateAnyMesh, &constants).unwrap();
    assert_eq!(report.ignored, ["point_embed.basis", "traj_embed.freq_bands"]);
    for t in collect_tensors(&vae, Network::FrameVae, Names::AnimateAnyMesh) {
        for (i, b) in t.bytes.chunks_exact(4).enumerate() {
            let want = (i % 97) as f32 / 97.0 - 0.5;
            let got = f32::from_le_bytes(b.try_into().unwrap());
            assert!(
                (got - want).abs() < 1e-6,
                "{}[{i}] = {got}, the file holds {want}",
                t.name
            );
        }
    }
    let mut target = tiny_vae(3);
    let before = values(&target);
    let read = |file: &str, target: &mut FrameVae| {
        read_file(
            target,
            &fixtures.join(file),
            Network::FrameVae,
            Names::AnimateAnyMesh,
            &constants,
        )
        .unwrap_err()
    };
    let e = read("evil.pt", &mut target);
    assert!(e.reason.contains("burn's reader can read"), "{e}");
    // A stride-0 view standing for 2^31 floats (8 GiB) under a name the network does not have: refused by its
    // name before any of its bytes is made.
    let e = read("huge_view.pt", &mut target);
    assert_eq!(e.tensor, "x", "{e}");
    assert_eq!(values(&target), before);
}

/// AnimateAnyMesh's VAE buffers are constants of its module: a file whose frequency bands are not the network's
/// describes another function and is refused, naming the buffer.
#[test]
fn aam_buffers_with_other_frequencies_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let vae = tiny_vae(5);
    let tiny = FrameVaeConfig::tiny();
    let constants = aam_vae_buffers(tiny.body.point_freqs, tiny.offset_freqs);
    let write = |bands: Vec<f32>| {
        let mut tensors = collect_tensors(&vae, Network::FrameVae, Names::AnimateAnyMesh);
        for (name, shape, mut values) in constants.clone() {
            if name == "traj_embed.freq_bands" {
                values = bands.clone();
            }
            let bytes = values.iter().flat_map(|v| v.to_le_bytes()).collect();
            tensors.push(FileTensor { name, shape, bytes });
        }
        let path = dir.path().join("v.safetensors");
        write_file(&path, &tensors, BTreeMap::new()).unwrap();
        path
    };
    let ours = constants[1].2.clone();
    let path = write(ours.clone());
    let mut target = tiny_vae(6);
    read_file(&mut target, &path, Network::FrameVae, Names::AnimateAnyMesh, &constants).unwrap();
    // AnimateAnyMesh's `log_sampling=False`: bands spaced linearly from 1 to 2^(n-1).
    let n = ours.len();
    let linear: Vec<f32> = (0..n)
        .map(|i| 1.0 + i as f32 * (2f32.powi(n as i32 - 1) - 1.0) / (n - 1) as f32)
        .collect();
    let path = write(linear);
    let e = read_file(&mut target, &path, Network::FrameVae, Names::AnimateAnyMesh, &constants).unwrap_err();
    assert_eq!(e.tensor, "traj_embed.freq_bands", "{e}");
    assert!(e.reason.contains("other frequencies"), "{e}");
}

/// The export read with numpy alone (`scripts/read_any4d.py`, the reader docs/pytorch.md shows): every tensor's
/// AnimateAnyMesh name, shape and f32 values against the network's parameters in burn's layout, Linear weights
/// transposed by the script itself.
#[test]
fn numpy_reads_an_aam_export_as_the_networks_parameters() {
    if !any4d_data::reference::python3_with(&["numpy"]) {
        println!("skipped: python3/numpy not available");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let vae = tiny_vae(4);
    let path = dir.path().join("model.safetensors");
    write_file(
        &path,
        &collect_tensors(&vae, Network::FrameVae, Names::AnimateAnyMesh),
        BTreeMap::new(),
    )
    .unwrap();
    let ours: BTreeMap<String, FileTensor> = collect_tensors(&vae, Network::FrameVae, Names::Any4d)
        .into_iter()
        .map(|t| (t.name.clone(), t))
        .collect();
    // The AAM name of each parameter: its path after PyTorch's adapter (a LayerNorm's gamma/beta read weight/bias).
    let pairs: Vec<(String, String)> = file_names(&vae, Network::FrameVae, Names::AnimateAnyMesh)
        .into_iter()
        .map(|(adapted, aam, _)| {
            let any4d = [("weight", "gamma"), ("bias", "beta")]
                .iter()
                .find_map(|(from, to)| {
                    let ln = adapted.strip_suffix(from).map(|stem| format!("{stem}{to}"));
                    ln.filter(|n| !ours.contains_key(&adapted) && ours.contains_key(n))
                })
                .unwrap_or(adapted);
            (aam, any4d)
        })
        .collect();
    let params: serde_json::Map<String, serde_json::Value> = ours
        .iter()
        .map(|(name, t)| {
            let values: Vec<f32> = t
                .bytes
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
                .collect();
            (name.clone(), serde_json::json!({"shape": t.shape, "values": values}))
        })
        .collect();
    let expected = dir.path().join("expected.json");
    let json = serde_json::json!({"pairs": pairs, "params": params});
    std::fs::write(&expected, serde_json::to_vec(&json).unwrap()).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/read_any4d.py");
    let out = std::process::Command::new("python3")
        .arg(&script)
        .args(["check".as_ref(), path.as_os_str(), expected.as_os_str()])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", String::from_utf8_lossy(&out.stderr));
    assert!(
        stdout.contains(&format!("ok: {} tensors match", ours.len())),
        "{stdout}"
    );
}
