//! The per-format part of `any4d bench data`: import throughput (read one take + normalise (D1)–(D3) + FPS, one
//! thread) of the benchmark clips written in every format the readers take.
//!
//! Vertex formats (`.bin`, `.glb`, `.anime`, OBJ folders, MD2, MD3) store the clip's frames (MD2 quantised to
//! bytes, MD3 to 1/64 units); the skeletal formats (IQM, MD5, 0 A.D. PMD/PSA, DirectX `.x`) store frame 0
//! rigidly skinned to [`JOINTS`] joints whose translations move per frame, so their reads include the skinning
//! bake (B3D: one moving joint holding every [`JOINTS`]-th vertex, the rest on the still root; SuperTuxKart `.spm`:
//! [`JOINTS`] root joints, each vertex on one). Each clip gets its
//! own folder (MD5 and PMD find their animations beside the mesh).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::clip::Clip;
use crate::error::{DataError, Result};
use crate::formats::skeletal::ReadOptions;
use crate::formats::{self, b3d, dae, fbx, iqm, md2, md3, pmd, spm, x};
use crate::fps::farthest_point_sampling;
use crate::preprocess;

/// Joints of the skeletal benchmark files.
pub const JOINTS: usize = 8;

/// The formats benchmarked, in report order.
const FORMATS: &[&str] = &[
    "bin", "glb", "anime", "obj-seq", "md2", "md3", "iqm", "md5", "pmd", "b3d", "spm", "x", "fbx", "dae",
];

/// Translation of joint `j` at frame `f` (non-negative: IQM's test writer quantises without an offset).
fn joint_shift(f: usize, j: usize) -> [f32; 3] {
    [0.05 * f as f32, 0.02 * (f * j % 5) as f32, 0.01 * j as f32]
}

/// The faces as the 16-bit indices of MD2 and PMD.
fn faces_u16(clip: &Clip) -> Result<Vec<[u16; 3]>> {
    let narrow = |i: u32| {
        u16::try_from(i)
            .map_err(|_| DataError::new("bench data", "vertices", "MD2 and PMD index vertices with 16 bits"))
    };
    clip.faces
        .iter()
        .map(|&[a, b, c]| Ok([narrow(a)?, narrow(b)?, narrow(c)?]))
        .collect()
}

/// `std::fs::write` with the error naming the file.
fn write_bytes(path: &Path, bytes: impl AsRef<[u8]>) -> Result<()> {
    std::fs::write(path, bytes).map_err(|e| DataError::io(path, e))
}

/// Write `clip` as `format` under `dir`; the path to read back.
fn write(format: &str, clip: &Clip, dir: &Path) -> Result<PathBuf> {
    let frame0 = clip.frame(0);
    let n = clip.n_vertices;
    let skin: Vec<u8> = (0..n).map(|v| (v % JOINTS) as u8).collect();
    std::fs::create_dir_all(dir).map_err(|e| DataError::io(dir, e))?;
    let path = match format {
        "bin" | "glb" | "anime" => {
            let path = dir.join(format!("clip.{format}"));
            formats::write_clip(&path, clip)?;
            path
        }
        "obj-seq" => {
            let path = dir.join("frames");
            formats::write_clip(&path, clip)?;
            path
        }
        "md2" => {
            let names: Vec<String> = (0..clip.frames).map(|f| format!("walk{f}")).collect();
            let frames: Vec<(&str, Vec<[u8; 3]>)> = (0..clip.frames)
                .map(|f| {
                    let q = clip
                        .frame(f)
                        .iter()
                        .map(|p| p.map(|x| ((x + 5.0) * 20.0).clamp(0.0, 255.0) as u8));
                    (names[f].as_str(), q.collect())
                })
                .collect();
            let path = dir.join("clip.md2");
            write_bytes(&path, md2::write_md2(&frames, &faces_u16(clip)?))?;
            path
        }
        "md3" => {
            let frames: Vec<Vec<[i16; 3]>> = (0..clip.frames)
                .map(|f| clip.frame(f).iter().map(|p| p.map(|x| (x * 64.0) as i16)).collect())
                .collect();
            let path = dir.join("clip.md3");
            write_bytes(&path, md3::write_test_md3(&frames, &clip.faces))?;
            path
        }
        "iqm" => {
            let names: Vec<String> = (0..JOINTS).map(|j| format!("j{j}")).collect();
            let joints: Vec<(&str, i32, [f32; 3])> = names.iter().map(|s| (s.as_str(), -1, [0.0; 3])).collect();
            let anim: Vec<Vec<[f32; 3]>> = (0..clip.frames)
                .map(|f| (0..JOINTS).map(|j| joint_shift(f, j)).collect())
                .collect();
            let path = dir.join("clip.iqm");
            write_bytes(
                &path,
                iqm::write_test_iqm(frame0, &clip.faces, &skin, &joints, "walk", &anim, true),
            )?;
            path
        }
        "md5" => {
            let (mesh, anim) = md5_text(clip);
            let path = dir.join("clip.md5mesh");
            write_bytes(&path, mesh)?;
            write_bytes(&dir.join("walk.md5anim"), anim)?;
            path
        }
        "pmd" => {
            let path = dir.join("clip.pmd");
            write_bytes(
                &path,
                pmd::write_test_pmd(frame0, &faces_u16(clip)?, &skin, &[[0.0; 3]; JOINTS]),
            )?;
            let keys: Vec<Vec<[f32; 3]>> = (0..clip.frames)
                .map(|f| (0..JOINTS).map(|j| joint_shift(f, j)).collect())
                .collect();
            write_bytes(&dir.join("walk.psa"), pmd::write_test_psa(&keys))?;
            path
        }
        "b3d" => {
            let bone: Vec<u32> = (0..n as u32).step_by(JOINTS).collect();
            let keys: Vec<(i32, [f32; 3])> = (0..clip.frames).map(|f| (f as i32 + 1, joint_shift(f, 1))).collect();
            let path = dir.join("clip.b3d");
            write_bytes(&path, b3d::write_test_b3d(frame0, &clip.faces, [0.0; 3], &bone, &keys))?;
            path
        }
        "spm" => {
            let joints: Vec<(&str, i16)> = (0..JOINTS).map(|_| ("j", -1)).collect();
            let keys: Vec<(u16, Vec<[f32; 3]>)> = (0..clip.frames)
                .map(|f| (f as u16, (0..JOINTS).map(|j| joint_shift(f, j)).collect()))
                .collect();
            let path = dir.join("clip.spm");
            write_bytes(
                &path,
                spm::write_test_spm(frame0, &clip.faces, &skin, &joints, JOINTS as u16, &keys),
            )?;
            path
        }
        "x" | "fbx" | "dae" => {
            let keys: Vec<Vec<[f32; 3]>> = (0..clip.frames)
                .map(|f| (0..JOINTS).map(|j| joint_shift(f, j)).collect())
                .collect();
            let path = dir.join(format!("clip.{format}"));
            match format {
                "x" => write_bytes(&path, x::write_test_x(frame0, &clip.faces, &skin, &keys))?,
                "dae" => write_bytes(&path, dae::write_test_dae(frame0, &clip.faces, &skin, &keys))?,
                _ => write_bytes(&path, fbx::write_test_fbx(frame0, &clip.faces, &skin, &keys))?,
            }
            path
        }
        other => {
            return Err(DataError::new(
                "bench data",
                "format",
                format!("unknown benchmark format {other}"),
            ));
        }
    };
    Ok(path)
}

/// An `.md5mesh` (frame 0, vertex `v` fully on root joint `v % JOINTS`) and an `.md5anim` moving each joint by
/// [`joint_shift`].
fn md5_text(clip: &Clip) -> (String, String) {
    let head = "MD5Version 10\ncommandline \"\"\n";
    let mut m = format!("{head}numJoints {JOINTS}\nnumMeshes 1\njoints {{\n");
    (0..JOINTS).for_each(|j| _ = writeln!(m, "\"j{j}\" -1 ( 0 0 0 ) ( 0 0 0 )"));
    let n = clip.n_vertices;
    let _ = writeln!(m, "}}\nmesh {{\nnumverts {n}");
    (0..n).for_each(|v| _ = writeln!(m, "vert {v} ( 0 0 ) {v} 1"));
    let _ = writeln!(m, "numtris {}", clip.faces.len());
    for (k, t) in clip.faces.iter().enumerate() {
        let _ = writeln!(m, "tri {k} {} {} {}", t[0], t[2], t[1]);
    }
    let _ = writeln!(m, "numweights {n}");
    for (v, p) in clip.frame(0).iter().enumerate() {
        let _ = writeln!(m, "weight {v} {} 1 ( {} {} {} )", v % JOINTS, p[0], p[1], p[2]);
    }
    m += "}\n";
    let mut a = format!(
        "{head}numFrames {}\nnumJoints {JOINTS}\nframeRate 24\nnumAnimatedComponents {}\nhierarchy {{\n",
        clip.frames,
        3 * JOINTS
    );
    (0..JOINTS).for_each(|j| _ = writeln!(a, "\"j{j}\" -1 7 {}", 3 * j));
    a += "}\nbounds {\n";
    a += &"( 0 0 0 ) ( 1 1 1 )\n".repeat(clip.frames);
    a += "}\nbaseframe {\n";
    a += &"( 0 0 0 ) ( 0 0 0 )\n".repeat(JOINTS);
    a += "}\n";
    for f in 0..clip.frames {
        let _ = writeln!(a, "frame {f} {{");
        for j in 0..JOINTS {
            let s = joint_shift(f, j);
            let _ = writeln!(a, "{} {} {}", s[0], s[1], s[2]);
        }
        a += "}\n";
    }
    (m, a)
}

/// Write `clips` in every format under `dir` and time reading them back (one thread); `(format, clips/s)` rows.
pub fn per_format(clips: &[Clip], dir: &Path, p: usize) -> Result<Vec<(&'static str, f64)>> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .map_err(|e| DataError::new("bench data", "threads", e.to_string()))?;
    let mut rows = Vec::new();
    for &format in FORMATS {
        let paths = clips
            .iter()
            .enumerate()
            .map(|(i, c)| write(format, c, &dir.join(format).join(format!("clip_{i:05}"))))
            .collect::<Result<Vec<_>>>()?;
        let seconds = pool.install(|| -> Result<f64> {
            let start = Instant::now();
            for path in &paths {
                let clip = formats::read_take(path, &ReadOptions::default())?.clip;
                let (clip, _norm) = preprocess::normalize(&clip);
                std::hint::black_box(farthest_point_sampling(clip.frame(0), p));
            }
            Ok(start.elapsed().as_secs_f64())
        })?;
        rows.push((format, clips.len() as f64 / seconds));
    }
    Ok(rows)
}
