//! ACAP features: round trip through the sparse reconstruction, rigid and translated sequences, degenerate
//! meshes, bad input, and agreement with the independent numpy/scipy reference `scripts/acap_reference.py`
//! (run when python3 with numpy and scipy is available, otherwise the test prints `skipped: <reason>`).

use std::f32::consts::PI;
use std::process::Command;

use any4d_data::acap::{ACAP_CHANNELS, AcapFrame, AcapTopology, Reconstruction};

type V3 = [f32; 3];

/// A closed-around, open-ended tube of `around × along` vertices with a lumpy cross-section, y from 0 to `len`.
fn tube(around: usize, along: usize, len: f32) -> (Vec<V3>, Vec<[u32; 3]>) {
    let mut p = Vec::new();
    for j in 0..along {
        let y = len * j as f32 / (along - 1) as f32;
        for i in 0..around {
            let a = 2.0 * PI * i as f32 / around as f32;
            let r = 1.0 + 0.2 * (3.0 * a).sin();
            p.push([r * a.cos(), y, r * a.sin()]);
        }
    }
    let mut f = Vec::new();
    for j in 0..along - 1 {
        for i in 0..around {
            let (a, b) = ((j * around + i) as u32, (j * around + (i + 1) % around) as u32);
            let (c, d) = (a + around as u32, b + around as u32);
            f.push([a, b, d]);
            f.push([a, d, c]);
        }
    }
    (p, f)
}

/// A torus (no boundary, every one-ring well spread) of `around × along` vertices, radii 2 and 0.7.
fn torus(around: usize, along: usize) -> (Vec<V3>, Vec<[u32; 3]>) {
    let mut p = Vec::new();
    for j in 0..along {
        let b = 2.0 * PI * j as f32 / along as f32;
        for i in 0..around {
            let a = 2.0 * PI * i as f32 / around as f32;
            let r = 2.0 + 0.7 * a.cos();
            p.push([r * b.cos(), 0.7 * a.sin(), r * b.sin()]);
        }
    }
    let mut f = Vec::new();
    for j in 0..along {
        for i in 0..around {
            let at = |i: usize, j: usize| ((j % along) * around + i % around) as u32;
            f.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            f.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    (p, f)
}

fn rot_y(a: f32) -> impl Fn(V3) -> V3 {
    move |[x, y, z]| [a.cos() * x + a.sin() * z, y, -a.sin() * x + a.cos() * z]
}

/// Bend about the z axis with curvature `k` (y runs along the arc).
fn bend(p: &[V3], k: f32) -> Vec<V3> {
    p.iter()
        .map(|&[x, y, z]| {
            let (r, th) = (1.0 / k, y * k);
            [r - (r - x) * th.cos(), (r - x) * th.sin(), z]
        })
        .collect()
}

/// Twist about the y axis by `rate` radians per unit of y.
fn twist(p: &[V3], rate: f32) -> Vec<V3> {
    p.iter().map(|&q| rot_y(q[1] * rate)(q)).collect()
}

/// ‖(p − g) − mean(p − g)‖ / ‖g − mean(g)‖ over all vertices.
fn relative_error(p: &[V3], g: &[V3]) -> f64 {
    let n = g.len() as f64;
    let mean =
        |f: &dyn Fn(usize) -> [f64; 3]| (0..g.len()).fold([0.0; 3], |m, v| std::array::from_fn(|k| m[k] + f(v)[k] / n));
    let d = |v: usize| std::array::from_fn(|k| p[v][k] as f64 - g[v][k] as f64);
    let gv = |v: usize| std::array::from_fn(|k| g[v][k] as f64);
    let (md, mg) = (mean(&d), mean(&gv));
    let (mut num, mut den) = (0.0, 0.0);
    for v in 0..g.len() {
        for k in 0..3 {
            num += (d(v)[k] - md[k]).powi(2);
            den += (gv(v)[k] - mg[k]).powi(2);
        }
    }
    (num / den).sqrt()
}

fn features(topo: &AcapTopology, frames: &[Vec<V3>]) -> Vec<AcapFrame> {
    let refs: Vec<&[V3]> = frames.iter().map(|f| f.as_slice()).collect();
    topo.features(&refs).expect("features")
}

#[test]
fn a_mesh_sequence_round_trips_to_1e4_relative() {
    // 4096 vertices; moderate bends and twists (angles past π included), then rigid motions and a global scaling.
    let (p, faces) = tube(64, 64, 6.0);
    let mut frames = vec![p.clone()];
    for s in 1..8 {
        let t = s as f32 / 7.0;
        frames.push(twist(&bend(&p, 0.02 + 0.1 * t), 0.6 * t));
    }
    frames.push(
        p.iter()
            .map(|&q| rot_y(4.0)(q))
            .map(|[x, y, z]| [x + 3.0, y - 1.0, z])
            .collect(),
    );
    frames.push(p.iter().map(|&[x, y, z]| [1.3 * x, 0.8 * y, 1.1 * z]).collect());
    let topo = AcapTopology::new("tube", &p, &faces).unwrap();
    assert_eq!(topo.components(), 1);
    for (f, (frame, feat)) in frames.iter().zip(features(&topo, &frames)).enumerate() {
        let rec = topo.reconstruct(&feat, Reconstruction::RingMoments).unwrap();
        let err = relative_error(&rec, frame);
        assert!(err <= 1e-4, "frame {f}: relative error {err:.2e}");
        // Gao et al.'s system is exact only where the deformation is affine on every one-ring.
        let poisson = relative_error(&topo.reconstruct(&feat, Reconstruction::EdgePoisson).unwrap(), frame);
        println!("frame {f}: ring moments {err:.1e}, edge Poisson {poisson:.1e}");
        let bound = if f == 0 || f >= 8 { 1e-4 } else { 1e-3 };
        assert!(poisson <= bound, "frame {f}: edge Poisson relative error {poisson:.2e}");
    }
}

#[test]
fn rigid_motion_gives_identity_stretch_and_a_constant_rotation_field() {
    let (p, faces) = tube(16, 12, 3.0);
    let topo = AcapTopology::new("tube", &p, &faces).unwrap();
    // 1.0 → 2.5 → 4.0 rad about y: the last is past π and must continue the sequence, not flip to −(2π − 4).
    let frames: Vec<Vec<V3>> = [0.0, 1.0, 2.5, 4.0]
        .iter()
        .map(|&a| {
            p.iter()
                .map(|&q| rot_y(a)(q))
                .map(|[x, y, z]| [x - 2.0, y + 5.0, z])
                .collect()
        })
        .collect();
    for (feat, angle) in features(&topo, &frames).iter().zip([0.0f32, 1.0, 2.5, 4.0]) {
        for f in feat {
            let want = [0.0, angle, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 1.0];
            for c in 0..ACAP_CHANNELS {
                assert!(
                    (f[c] - want[c]).abs() < 1e-4,
                    "angle {angle}: channel {c} = {} (want {})",
                    f[c],
                    want[c]
                );
            }
        }
    }
}

#[test]
fn features_are_invariant_to_a_global_translation() {
    // A closed mesh: the f32 rounding of the translated coordinates is not amplified by a poorly spread
    // boundary one-ring (an open tube's boundary rings amplify it to ~2e-4).
    let (p, faces) = torus(16, 24);
    let topo = AcapTopology::new("tube", &p, &faces).unwrap();
    let frames = vec![p.clone(), twist(&p, 0.3), bend(&p, 0.2)];
    let moved: Vec<Vec<V3>> = frames
        .iter()
        .map(|f| f.iter().map(|&[x, y, z]| [x + 7.0, y - 3.0, z + 0.5]).collect())
        .collect();
    for (a, b) in features(&topo, &frames).iter().zip(features(&topo, &moved)) {
        for (i, (x, y)) in a.iter().flatten().zip(b.iter().flatten()).enumerate() {
            assert!((x - y).abs() < 1e-4, "{i}: {x} vs {y}");
        }
    }
}

#[test]
fn degenerate_triangles_isolated_vertices_and_flat_rings_stay_finite() {
    // A flat 4 × 4 grid (planar one-rings everywhere), a collapsed triangle on two coincident vertices, a
    // sliver, and an isolated vertex.
    let mut p: Vec<V3> = (0..16).map(|i| [(i % 4) as f32, (i / 4) as f32, 0.0]).collect();
    let mut faces = Vec::new();
    for j in 0..3u32 {
        for i in 0..3u32 {
            let a = j * 4 + i;
            faces.push([a, a + 1, a + 5]);
            faces.push([a, a + 5, a + 4]);
        }
    }
    p.push([3.0, 3.0, 0.0]); // 16: on top of vertex 15
    faces.push([15, 16, 11]);
    p.push([1.5, 0.0, 0.0]); // 17: on the edge 1–2, a zero-area sliver
    faces.push([1, 17, 2]);
    faces.push([5, 5, 6]); // a repeated index
    p.push([9.0, 9.0, 9.0]); // 18: isolated
    let topo = AcapTopology::new("degenerate", &p, &faces).unwrap();
    assert_eq!(topo.bridges(), 1, "the isolated vertex is bridged to the grid");
    assert_eq!(topo.components(), 1);
    let spin: Vec<V3> = p.iter().map(|&q| rot_y(0.7)(q)).collect();
    let wave: Vec<V3> = p.iter().map(|&[x, y, z]| [x, y, z + 0.2 * (x + y).sin()]).collect();
    let frames = vec![p.clone(), spin.clone(), wave];
    let feats = features(&topo, &frames);
    for (f, feat) in feats.iter().enumerate() {
        assert!(feat.iter().flatten().all(|x| x.is_finite()), "frame {f}");
        for method in [Reconstruction::RingMoments, Reconstruction::EdgePoisson] {
            let rec = topo.reconstruct(feat, method).unwrap();
            assert!(rec.iter().flatten().all(|x| x.is_finite()), "frame {f}, {method:?}");
        }
    }
    // The planar grid still rotates rigidly: the normal direction follows the ring's best rotation.
    for (v, f) in feats[1].iter().take(16).enumerate() {
        assert!(
            (f[1] - 0.7).abs() < 1e-4 && (f[3] - 1.0).abs() < 1e-4,
            "vertex {v}: {f:?}"
        );
    }
    // The bridged isolated vertex turns with the rest.
    let rec = topo.reconstruct(&feats[1], Reconstruction::RingMoments).unwrap();
    assert!(
        relative_error(&rec, &spin) < 1e-4,
        "{:.2e}",
        relative_error(&rec, &spin)
    );
    // A one-vertex mesh: no edges at all, the identity fallback.
    let single = AcapTopology::new("one", &[[1.0, 2.0, 3.0]], &[]).unwrap();
    let f = single.features(&[&[[5.0, 5.0, 5.0]]]).unwrap();
    assert_eq!(f[0][0], [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 1.0]);
    assert_eq!(
        single.reconstruct(&f[0], Reconstruction::RingMoments).unwrap(),
        vec![[1.0, 2.0, 3.0]]
    );
}

#[test]
fn bad_input_names_the_field() {
    let (p, faces) = tube(8, 4, 1.0);
    let e = AcapTopology::new("clip7", &p, &[[0, 1, 99]]).unwrap_err();
    assert_eq!((e.path.as_str(), e.field.as_str()), ("clip7", "faces"));
    let e = AcapTopology::new("clip7", &[], &[]).unwrap_err();
    assert_eq!(e.field, "vertices");
    let topo = AcapTopology::new("clip7", &p, &faces).unwrap();
    let e = topo.features(&[&p[..5]]).unwrap_err();
    assert!(e.reason.contains("frame 0 has 5 vertices"), "{e}");
    let mut bad = p.clone();
    bad[3][1] = f32::NAN;
    let e = topo.features(&[&p, &bad]).unwrap_err();
    assert!(e.reason.contains("frame 1, vertex 3"), "{e}");
    let mut feat = topo.features(&[&p]).unwrap().remove(0);
    feat[2][4] = f32::INFINITY;
    let e = topo.reconstruct(&feat, Reconstruction::RingMoments).unwrap_err();
    assert_eq!(e.field, "features");
    let e = topo.reconstruct(&feat[..3], Reconstruction::EdgePoisson).unwrap_err();
    assert!(e.reason.contains("3 feature rows"), "{e}");
}

/// `python3 -c 'import numpy, scipy'` or the reason it failed.
fn python_with_scipy() -> Result<(), String> {
    match Command::new("python3").args(["-c", "import numpy, scipy"]).output() {
        Ok(o) if o.status.success() => Ok(()),
        Ok(o) => Err(format!(
            "python3 has no numpy/scipy ({})",
            String::from_utf8_lossy(&o.stderr).trim()
        )),
        Err(e) => Err(format!("python3 not runnable ({e})")),
    }
}

#[test]
fn agrees_with_the_numpy_scipy_reference() {
    if let Err(why) = python_with_scipy() {
        println!("skipped: {why}");
        return;
    }
    // Two tubes side by side (two components, bridged), the second sliding along the first.
    let (one, one_faces) = tube(24, 20, 4.0);
    let n1 = one.len() as u32;
    let mut p = one.clone();
    p.extend(one.iter().map(|&[x, y, z]| [x + 3.0, y, z]));
    let mut faces = one_faces.clone();
    faces.extend(one_faces.iter().map(|f| f.map(|v| v + n1)));
    let mut frames = vec![p.clone()];
    for s in 1..6 {
        let t = s as f32 / 5.0;
        let mut frame = twist(&bend(&one, 0.05 + 0.3 * t), 0.9 * t);
        frame.extend(one.iter().map(|&[x, y, z]| [x + 3.0, y + t, z]));
        frames.push(frame);
    }
    frames.push(p.iter().map(|&q| rot_y(3.5)(q)).collect());
    let dir = tempfile::tempdir().unwrap();
    let (input, output) = (dir.path().join("clip.json"), dir.path().join("out.json"));
    let json = serde_json::json!({ "faces": faces, "frames": frames });
    std::fs::write(&input, json.to_string()).unwrap();
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/../scripts/acap_reference.py");
    let out = Command::new("python3")
        .arg(script)
        .arg("--features")
        .arg(&input)
        .arg(&output)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "reference failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let reference: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&output).unwrap()).unwrap();
    let read = |key: &str| -> Vec<Vec<Vec<f64>>> { serde_json::from_value(reference[key].clone()).unwrap() };
    let ref_feat = read("features");
    let methods = [
        (Reconstruction::RingMoments, read("ring_moments")),
        (Reconstruction::EdgePoisson, read("edge_poisson")),
    ];

    let topo = AcapTopology::new("tubes", &p, &faces).unwrap();
    assert_eq!(topo.bridges(), 1);
    let feats = features(&topo, &frames);
    let mut worst = (0.0f64, 0.0f64);
    for (f, feat) in feats.iter().enumerate() {
        for (v, row) in feat.iter().enumerate() {
            for c in 0..ACAP_CHANNELS {
                let d = (row[c] as f64 - ref_feat[f][v][c]).abs();
                worst.0 = worst.0.max(d);
                assert!(
                    d < 1e-5,
                    "frame {f}, vertex {v}, channel {c}: {} vs {}",
                    row[c],
                    ref_feat[f][v][c]
                );
            }
        }
        for (method, ref_rec) in &methods {
            let rec = topo.reconstruct(feat, *method).unwrap();
            for (v, x) in rec.iter().enumerate() {
                for k in 0..3 {
                    let d = (x[k] as f64 - ref_rec[f][v][k]).abs();
                    worst.1 = worst.1.max(d);
                    assert!(
                        d < 1e-5,
                        "{method:?}, frame {f}, vertex {v}: {x:?} vs {:?}",
                        ref_rec[f][v]
                    );
                }
            }
        }
    }
    println!(
        "largest difference to the reference: features {:.1e}, positions {:.1e}",
        worst.0, worst.1
    );
}

#[test]
fn every_synthetic_family_round_trips() {
    use any4d_data::synth::{MotionFamily, ShapeFamily, SynthConfig, generate_with};
    let cfg = SynthConfig {
        clips: 1,
        seed: 5,
        frames: 16,
        min_vertices: 512,
        max_vertices: 1024,
        body: None,
        family: Default::default(),
        scenes: false,
    };
    let mut worst = (0.0f64, String::new());
    for (s, shape) in ShapeFamily::ALL.into_iter().enumerate() {
        for (m, motion) in MotionFamily::ALL.into_iter().enumerate() {
            let clip = generate_with(&cfg, s * 7 + m, shape, motion).unwrap();
            let topo = AcapTopology::new(&clip.id, clip.frame(0), &clip.faces).unwrap();
            let frames: Vec<&[V3]> = (0..clip.frames).map(|f| clip.frame(f)).collect();
            let feats = topo.features(&frames).unwrap();
            for (f, feat) in feats.iter().enumerate() {
                let rec = topo.reconstruct(feat, Reconstruction::RingMoments).unwrap();
                let err = relative_error(&rec, frames[f]);
                if err > worst.0 {
                    worst = (err, format!("{} frame {f} ({} bridges)", clip.id, topo.bridges()));
                }
            }
        }
    }
    println!("largest relative round-trip error: {:.1e} at {}", worst.0, worst.1);
    assert!(worst.0 <= 1e-4, "{:.2e} at {}", worst.0, worst.1);
}
