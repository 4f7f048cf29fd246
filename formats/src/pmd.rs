//! 0 A.D. models: `.pmd` skinned meshes (version 3–4) baked with `.psa` skeletal animations (version 1). The game
//! package ships these as the cached binary forms of its COLLADA sources (`*.dae.cached.pmd` / `.psa`).
//!
//! Layout (little-endian): PMD = `"PSMD" version u32 size u32 | n_vertices u32 | n_uvs u32 (v4) | vertices
//! (position f32×3, normal f32×3, uv f32×2×n_uvs, bone u8×4 (255 = none), weight f32×4) | n_faces u32 | faces
//! u16×3 | n_bones u32 | rest bones (translation f32×3, rotation quaternion x y z w f32×4, object space) | props`.
//! PSA = `"PSSA" version u32 size u32 | name (u32 length + bytes) | frame length f32 (ms) | n_bones u32 |
//! n_frames u32 | keys (translation f32×3, rotation f32×4, object space) × n_bones per frame`.
//!
//! Skinning: `v_f = Σ_i w_i · K_f(b_i) · R(b_i)⁻¹ · v` with `K_f` the frame's key and `R` the rest bone (the
//! engine's rule). The takes of a `.pmd` are the `.psa` files in its folder with the mesh's bone count (the corpus
//! stage puts each actor's mesh and animations in one folder). 0 A.D. is Y-up: coordinates are kept.

use std::path::{Path, PathBuf};

use super::bytes::Bytes;
use super::skeletal::{
    self, Influences, Mat, ReadOptions, SkinStats, TakeInfo, clean_influences, inverse, mul, skin_frame, trs,
};
use crate::clip::Clip;
use crate::error::{DataError, Result};

struct Pmd {
    positions: Vec<[f64; 3]>,
    influences: Influences,
    faces: Vec<[u32; 3]>,
    rest: Vec<Mat>,
}

fn bone(b: &mut Bytes, field: &str) -> Result<Mat> {
    let t = b.f32s::<3>(field)?.map(f64::from);
    let q = b.f32s::<4>(field)?.map(f64::from);
    Ok(trs(t, q, [1.0; 3]))
}

fn read_file(path: &Path) -> Result<Vec<u8>> {
    super::read_clip_file(path)
}

fn parse_pmd(path: &Path) -> Result<Pmd> {
    let data = read_file(path)?;
    let p = path.display().to_string();
    let mut b = Bytes::new(&p, &data);
    if b.take(4, "magic").ok() != Some(&b"PSMD"[..]) {
        return Err(b.err("magic", "not a PMD file (no PSMD header)"));
    }
    let version = b.u32("version")?;
    if !(3..=4).contains(&version) {
        return Err(b.err("version", format!("version {version}, only 3 and 4 are supported")));
    }
    let _size = b.u32("data_size")?;
    let nv = b.usize("num_vertices")?;
    let nuv = if version >= 4 { b.usize("num_uvs")? } else { 1 };
    if nuv > 16 {
        return Err(b.err("num_uvs", format!("{nuv} UV sets, more than 16")));
    }
    let vsize = 24 + 8 * nuv + 4 + 16;
    b.check_count(nv, vsize, "vertices")?;
    let mut positions = Vec::with_capacity(nv);
    let mut influences = Vec::with_capacity(nv);
    for v in 0..nv {
        let f = format!("vertices[{v}]");
        positions.push(b.f32s::<3>(&f)?.map(f64::from));
        b.take(12 + 8 * nuv, &f)?;
        let bones = b.take(4, &f)?.to_vec();
        let w = b.f32s::<4>(&f)?;
        influences.push(
            bones
                .iter()
                .zip(w)
                .filter(|(j, _)| **j != 255)
                .map(|(&j, w)| (j as usize, w as f64))
                .collect(),
        );
    }
    let nf = b.usize("num_faces")?;
    b.check_count(nf, 6, "faces")?;
    let mut faces = Vec::with_capacity(nf);
    for k in 0..nf {
        let f = format!("faces[{k}]");
        let tri = [b.u16(&f)?, b.u16(&f)?, b.u16(&f)?].map(u32::from);
        if let Some(&i) = tri.iter().find(|&&i| i as usize >= nv) {
            return Err(b.err(f, format!("vertex {i} of {nv}")));
        }
        faces.push(tri);
    }
    let nb = b.usize("num_bones")?;
    if nb > skeletal::MAX_JOINTS {
        return Err(b.err("num_bones", format!("{nb} bones, more than {}", skeletal::MAX_JOINTS)));
    }
    b.check_count(nb, 28, "bones")?;
    let rest = (0..nb)
        .map(|j| bone(&mut b, &format!("bones[{j}]")))
        .collect::<Result<Vec<_>>>()?;
    Ok(Pmd {
        positions,
        influences,
        faces,
        rest,
    })
}

#[derive(Debug)]
struct Psa {
    fps: f32,
    bones: usize,
    frames: usize,
    /// Offset of the first key in the file.
    keys_at: usize,
}

fn psa_header(b: &mut Bytes) -> Result<Psa> {
    if b.take(4, "magic").ok() != Some(&b"PSSA"[..]) {
        return Err(b.err("magic", "not a PSA file (no PSSA header)"));
    }
    let version = b.u32("version")?;
    if version != 1 {
        return Err(b.err("version", format!("version {version}, only 1 is supported")));
    }
    let _size = b.u32("data_size")?;
    let name_len = b.usize("name")?;
    b.take(name_len, "name")?;
    let frame_ms = b.f32("frame_length")?;
    let bones = b.usize("num_bones")?;
    let frames = b.usize("num_frames")?;
    let keys = bones
        .checked_mul(frames)
        .ok_or_else(|| b.err("num_frames", "bones × frames overflows"))?;
    b.check_count(keys, 28, "keys")?;
    if !(frame_ms.is_finite() && frame_ms >= 0.0) {
        return Err(b.err(
            "frame_length",
            format!("{frame_ms} ms per frame: must be finite and not negative"),
        ));
    }
    let fps = if frame_ms > 0.0 {
        1000.0 / f64::from(frame_ms)
    } else {
        0.0
    };
    if !super::skeletal::fps_in_range(fps) {
        return Err(b.err(
            "frame_length",
            format!(
                "{frame_ms} ms per frame is {fps} frames per second, more than {}",
                super::skeletal::MAX_FPS
            ),
        ));
    }
    Ok(Psa {
        fps: fps as f32,
        bones,
        frames,
        keys_at: b.pos(),
    })
}

fn takes_of(path: &Path, bones: usize) -> Vec<TakeInfo> {
    skeletal::companions(path, &["psa"], false)
        .into_iter()
        .filter_map(|p| {
            let data = read_file(&p).ok()?;
            let s = p.display().to_string();
            let h = psa_header(&mut Bytes::new(&s, &data)).ok()?;
            (h.bones == bones).then(|| TakeInfo {
                name: skeletal::stem(&p),
                frames: h.frames,
                fps: h.fps,
                file: Some(p),
            })
        })
        .collect()
}

/// The takes of a `.pmd` (see the module doc).
pub fn list_takes(path: &Path) -> Result<Vec<TakeInfo>> {
    let pmd = parse_pmd(path)?;
    Ok(takes_of(path, pmd.rest.len()))
}

/// Bake one take of a `.pmd` into a clip (id = file stem, caption empty).
pub fn read(path: &Path, opts: &ReadOptions) -> Result<(Clip, SkinStats, TakeInfo)> {
    let pmd = parse_pmd(path)?;
    let takes = takes_of(path, pmd.rest.len());
    let info = takes[skeletal::pick(path, &takes, &opts.take)?].clone();
    let anim_path: PathBuf = info.file.clone().expect("pmd takes are files");
    skeletal::check_frames(&anim_path, &info.name, info.frames, opts.max_frames)?;
    let mut infl = pmd.influences;
    let stats = clean_influences(path, "vertices", &mut infl, pmd.rest.len())?;
    let inv_rest: Vec<Mat> = pmd
        .rest
        .iter()
        .enumerate()
        .map(|(j, m)| inverse(m).ok_or_else(|| DataError::new(path, format!("bones[{j}]"), "singular rest transform")))
        .collect::<Result<_>>()?;
    let data = read_file(&anim_path)?;
    let s = anim_path.display().to_string();
    let mut b = Bytes::new(&s, &data);
    let h = psa_header(&mut b)?;
    b.seek(h.keys_at, "keys")?;
    let n = pmd.positions.len();
    skeletal::check_rows(path, h.frames, n)?;
    let mut vertices = Vec::with_capacity(h.frames * n);
    for f in 0..h.frames {
        let skin: Vec<Mat> = inv_rest
            .iter()
            .enumerate()
            .map(|(j, inv)| Ok(mul(&bone(&mut b, &format!("keys[{f}][{j}]"))?, inv)))
            .collect::<Result<_>>()?;
        skin_frame(&pmd.positions, &infl, &skin, &mut vertices);
    }
    let clip = Clip::new(
        skeletal::stem(path),
        vertices,
        h.frames,
        n,
        pmd.faces,
        "",
        path.display().to_string(),
    )?;
    Ok((clip, stats, info))
}

/// Bytes of a version-4 PMD (one UV set, no props) for tests: `bones` rest translations, each vertex rigidly on
/// `skin[v]` (255 = unskinned).
#[doc(hidden)]
pub fn write_test_pmd(positions: &[[f32; 3]], faces: &[[u16; 3]], skin: &[u8], bones: &[[f32; 3]]) -> Vec<u8> {
    let mut body = Vec::new();
    let f = |body: &mut Vec<u8>, xs: &[f32]| xs.iter().for_each(|x| body.extend(x.to_le_bytes()));
    body.extend((positions.len() as u32).to_le_bytes());
    body.extend(1u32.to_le_bytes());
    for (p, &j) in positions.iter().zip(skin) {
        f(&mut body, p);
        f(&mut body, &[0.0, 1.0, 0.0, 0.0, 0.0]);
        body.extend([j, 255, 255, 255]);
        f(&mut body, &[1.0, 0.0, 0.0, 0.0]);
    }
    body.extend((faces.len() as u32).to_le_bytes());
    faces.iter().flatten().for_each(|i| body.extend(i.to_le_bytes()));
    body.extend((bones.len() as u32).to_le_bytes());
    for t in bones {
        f(&mut body, t);
        f(&mut body, &[0.0, 0.0, 0.0, 1.0]);
    }
    body.extend(0u32.to_le_bytes());
    let mut out = b"PSMD".to_vec();
    out.extend(4u32.to_le_bytes());
    out.extend((body.len() as u32).to_le_bytes());
    out.extend(body);
    out
}

/// Bytes of a PSA for tests: `keys[f][j]` = translation of bone `j` at frame `f` (rotation identity), 30 fps.
#[doc(hidden)]
pub fn write_test_psa(keys: &[Vec<[f32; 3]>]) -> Vec<u8> {
    let mut body = Vec::new();
    body.extend(0u32.to_le_bytes());
    body.extend((1000.0f32 / 30.0).to_le_bytes());
    body.extend((keys.first().map_or(0, Vec::len) as u32).to_le_bytes());
    body.extend((keys.len() as u32).to_le_bytes());
    for t in keys.iter().flatten() {
        t.iter()
            .chain(&[0.0, 0.0, 0.0, 1.0])
            .for_each(|x| body.extend(x.to_le_bytes()));
    }
    let mut out = b"PSSA".to_vec();
    out.extend(1u32.to_le_bytes());
    out.extend((body.len() as u32).to_le_bytes());
    out.extend(body);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bakes_world_space_keys_against_rest_bones() {
        let dir = tempfile::tempdir().unwrap();
        let pos = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let mesh = write_test_pmd(&pos, &[[0, 1, 2]], &[0, 0, 1], &[[0.0; 3], [0.0, 1.0, 0.0]]);
        std::fs::write(dir.path().join("deer.pmd"), mesh).unwrap();
        // Bone 1 rises by f; bone 0 stays.
        let keys: Vec<Vec<[f32; 3]>> = (0..4).map(|f| vec![[0.0; 3], [0.0, 1.0 + f as f32, 0.0]]).collect();
        std::fs::write(dir.path().join("walk.psa"), write_test_psa(&keys)).unwrap();
        std::fs::write(dir.path().join("bird.psa"), write_test_psa(&vec![vec![[0.0; 3]; 3]; 4])).unwrap();
        let path = dir.path().join("deer.pmd");
        let takes = list_takes(&path).unwrap();
        assert_eq!(takes.len(), 1, "three-bone animation is not a take: {takes:?}");
        assert!((takes[0].fps - 30.0).abs() < 1e-3);
        let (clip, stats, info) = read(&path, &ReadOptions::default()).unwrap();
        assert_eq!((clip.frames, info.name.as_str(), stats.vertices), (4, "walk", 3));
        assert_eq!(clip.frame(3)[2], [0.0, 4.0, 0.0]);
        assert_eq!(clip.frame(3)[1], [1.0, 0.0, 0.0]);
    }

    #[test]
    fn a_psa_frame_length_that_is_not_a_finite_rate_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let pos = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let mesh = write_test_pmd(&pos, &[[0, 1, 2]], &[0, 0, 1], &[[0.0; 3], [0.0, 1.0, 0.0]]);
        std::fs::write(dir.path().join("deer.pmd"), mesh).unwrap();
        let keys: Vec<Vec<[f32; 3]>> = (0..4).map(|f| vec![[0.0; 3], [0.0, 1.0 + f as f32, 0.0]]).collect();
        let good = write_test_psa(&keys);
        let ms = (1000.0f32 / 30.0).to_le_bytes();
        let at = good.windows(4).position(|w| w == ms).unwrap();
        for bad in [f32::NAN, f32::INFINITY, -5.0, 1e-30] {
            let mut b = good.clone();
            b[at..at + 4].copy_from_slice(&bad.to_le_bytes());
            let psa = dir.path().join("walk.psa");
            std::fs::write(&psa, b).unwrap();
            let data = std::fs::read(&psa).unwrap();
            let e = psa_header(&mut Bytes::new("walk.psa", &data)).unwrap_err();
            assert!(e.field.contains("frame_length"), "{bad}: {e}");
        }
    }

    #[test]
    fn refuses_bad_bones_truncation_and_huge_counts() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.pmd");
        let pos = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        // A vertex weighted to bone 3 of a 2-bone skeleton.
        std::fs::write(&path, write_test_pmd(&pos, &[[0, 1, 2]], &[0, 3, 1], &[[0.0; 3]; 2])).unwrap();
        std::fs::write(dir.path().join("a.psa"), write_test_psa(&vec![vec![[0.0; 3]; 2]; 2])).unwrap();
        let e = read(&path, &ReadOptions::default()).unwrap_err();
        assert!(e.reason.contains("joint 3") && e.reason.contains("2 joints"), "{e}");
        // An unskinned vertex has no weight.
        std::fs::write(&path, write_test_pmd(&pos, &[[0, 1, 2]], &[0, 255, 1], &[[0.0; 3]; 2])).unwrap();
        assert!(
            read(&path, &ReadOptions::default())
                .unwrap_err()
                .reason
                .contains("no joint weight")
        );
        let good = write_test_pmd(&pos, &[[0, 1, 2]], &[0, 0, 1], &[[0.0; 3]; 2]);
        let mut huge = good.clone();
        huge[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
        std::fs::write(&path, &huge).unwrap();
        let e = list_takes(&path).unwrap_err();
        assert!(e.field == "vertices" && e.reason.contains("more than"), "{e}");
        for cut in [3, 30, good.len() - 5] {
            std::fs::write(&path, &good[..cut]).unwrap();
            assert!(list_takes(&path).is_err(), "cut {cut}");
        }
    }
}
