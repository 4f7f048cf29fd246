//! What the animated-mesh readers share: takes (which animation of a file), the frame limit, joint transforms,
//! linear blend skinning and the weight clean-up they count.
//!
//! Skinning is docs/method.md's linear blend skinning, the same as the glTF reader's:
//! `v_f = Σ_i w_i · G_f(j_i) · G_bind(j_i)⁻¹ · v_bind`, with `G` a joint's object-space transform. Weights are
//! kept however many a vertex has (the formats here never need truncation); a vertex whose weights do not sum to
//! 1 (|Σw − 1| > [`WEIGHT_SUM_TOLERANCE`]) is renormalised, and both cases are counted in [`SkinStats`].
//!
//! Z-up formats (IQM, MD5, MD2, MD3) are turned to the Y-up frame of glTF and of the contact sheets with
//! [`z_up_to_y_up`]: `(x, y, z) → (x, z, −y)`, a rotation, so shapes and motion are unchanged.

use std::path::{Path, PathBuf};

use crate::error::{DataError, Result};

/// The longest animation a reader bakes, in frames: a take that claims more is refused before anything is
/// allocated for it (override with [`ReadOptions::max_frames`]).
pub const MAX_FRAMES: usize = 4096;

/// Most joints a skeleton may have.
pub const MAX_JOINTS: usize = 4096;

/// A vertex whose weights sum further than this from 1 is renormalised (and counted).
pub const WEIGHT_SUM_TOLERANCE: f64 = 1e-3;

/// Which take (animation) of a file to read.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum TakeSel {
    /// The first take the file lists.
    #[default]
    First,
    /// The take at this position in the list (zero-based).
    Index(usize),
    /// The take with this name.
    Name(String),
}

impl TakeSel {
    /// `--take` text: all digits is an index, anything else a name.
    pub fn parse(s: &str) -> Self {
        match s.parse::<usize>() {
            Ok(i) => Self::Index(i),
            Err(_) => Self::Name(s.to_owned()),
        }
    }
}

/// How to read an animated file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReadOptions {
    pub take: TakeSel,
    /// Refuse takes longer than this many frames.
    pub max_frames: usize,
}

impl Default for ReadOptions {
    fn default() -> Self {
        Self {
            take: TakeSel::First,
            max_frames: MAX_FRAMES,
        }
    }
}

/// One take of a file as listed by `data inspect`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TakeInfo {
    /// Name (the animation's name, or the animation file's stem when that is all there is).
    pub name: String,
    /// Frames the take has in the file.
    pub frames: usize,
    /// The file's frame rate for this take (0 when the file does not say).
    pub fps: f32,
    /// The file holding the animation when it is not the mesh file itself.
    pub file: Option<PathBuf>,
}

/// Skin weights that needed attention, counted over all vertices of a read.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct SkinStats {
    /// Skinned vertices.
    pub vertices: usize,
    /// Vertices with more than 4 weights (kept: the skinning here takes any number).
    pub over_four_weights: usize,
    /// Vertices whose weights did not sum to 1 and were renormalised.
    pub renormalised: usize,
}

impl SkinStats {
    /// Add another read's counts to these.
    pub fn add(&mut self, other: &SkinStats) {
        self.vertices += other.vertices;
        self.over_four_weights += other.over_four_weights;
        self.renormalised += other.renormalised;
    }

    /// A one-line summary, empty when nothing was skinned.
    pub fn line(&self) -> String {
        if self.vertices == 0 {
            return String::new();
        }
        format!(
            "{} skinned vertices, {} with more than 4 weights, {} renormalised",
            self.vertices, self.over_four_weights, self.renormalised
        )
    }
}

/// Index of the take `sel` names in `takes`; the error lists what exists.
pub fn pick(path: &Path, takes: &[TakeInfo], sel: &TakeSel) -> Result<usize> {
    let names = || {
        let list: Vec<String> = takes
            .iter()
            .enumerate()
            .map(|(i, t)| format!("{i}: {}", t.name))
            .collect();
        if list.is_empty() {
            "the file has no animation".to_owned()
        } else {
            format!("takes are {}", list.join(", "))
        }
    };
    if takes.is_empty() {
        return Err(DataError::new(
            path,
            "animations",
            "no animation: a static mesh is not a clip",
        ));
    }
    match sel {
        TakeSel::First => Ok(0),
        TakeSel::Index(i) if *i < takes.len() => Ok(*i),
        TakeSel::Index(i) => Err(DataError::new(path, "take", format!("no take {i}; {}", names()))),
        TakeSel::Name(n) => takes
            .iter()
            .position(|t| &t.name == n)
            .ok_or_else(|| DataError::new(path, "take", format!("no take named {n:?}; {}", names()))),
    }
}

/// The takes of a format that stores one animation: `all` with its `frames` when there are at least 2, none
/// otherwise (one frame is no motion).
pub fn single_take(frames: usize) -> Vec<TakeInfo> {
    if frames < 2 {
        return Vec::new();
    }
    vec![TakeInfo {
        name: "all".into(),
        frames,
        fps: 0.0,
        file: None,
    }]
}

/// The take of a one-animation file that `opts` asks for ([`single_take`]), its frame count checked against
/// `opts.max_frames` before anything is allocated for it.
pub fn pick_single(path: &Path, frames: usize, opts: &ReadOptions) -> Result<TakeInfo> {
    let takes = single_take(frames);
    let info = takes[pick(path, &takes, &opts.take)?].clone();
    check_frames(path, &info.name, frames, opts.max_frames)?;
    Ok(info)
}

/// Refuse a take of `frames` frames over `max` (before anything is allocated for it).
pub fn check_frames(path: &Path, take: &str, frames: usize, max: usize) -> Result<()> {
    if frames > max {
        return Err(DataError::new(
            path,
            "frames",
            format!("take {take:?} has {frames} frames, more than the maximum of {max}"),
        ));
    }
    if frames < 2 {
        return Err(DataError::new(
            path,
            "frames",
            format!("take {take:?} has {frames} frame(s): a clip needs at least 2"),
        ));
    }
    Ok(())
}

/// Refuse a bake of `frames` × `vertices` rows over the clip limit
/// ([`CLIP_VERTICES`](crate::limits::CLIP_VERTICES), `--limit-clip-vertices`) before anything is allocated for it.
pub fn check_rows(path: &Path, frames: usize, vertices: usize) -> Result<()> {
    let max = crate::limits::CLIP_VERTICES.get_usize();
    if frames.checked_mul(vertices).is_none_or(|rows| rows > max) {
        return Err(DataError::new(
            path,
            "vertices",
            format!(
                "{frames} frames × {vertices} vertices is more than the limit of {max} baked vertices{}",
                crate::limits::CLIP_VERTICES.hint()
            ),
        ));
    }
    Ok(())
}

/// `(x, y, z)` of a Z-up file in Y-up coordinates.
pub fn z_up_to_y_up(p: [f64; 3]) -> [f64; 3] {
    [p[0], p[2], -p[1]]
}

/// Row-major affine 4×4 matrix: `m[r][c]`, points are columns.
pub type Mat = [[f64; 4]; 4];

pub const IDENTITY: Mat = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
];

pub fn mul(a: &Mat, b: &Mat) -> Mat {
    std::array::from_fn(|r| std::array::from_fn(|c| (0..4).map(|k| a[r][k] * b[k][c]).sum()))
}

pub fn apply(m: &Mat, p: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2] + m[r][3])
}

/// Rotation about axis `axis` (0 x, 1 y, 2 z) by `deg` degrees.
pub fn axis_rotation(axis: usize, deg: f64) -> Mat {
    let (s, c) = deg.to_radians().sin_cos();
    let (i, j) = ((axis + 1) % 3, (axis + 2) % 3);
    let mut m = IDENTITY;
    m[i][i] = c;
    m[i][j] = -s;
    m[j][i] = s;
    m[j][j] = c;
    m
}

/// Highest frame rate a file may state.
pub const MAX_FPS: f64 = 100_000.0;

/// A frame rate a file states (or that its times imply): finite, not negative and at most [`MAX_FPS`]; 0 means the
/// file does not say. Every reader passes its rates through here, so no clip carries a NaN or infinite rate.
pub fn check_fps(path: &Path, field: &str, fps: f64) -> Result<f32> {
    if fps_in_range(fps) {
        Ok(fps as f32)
    } else {
        Err(DataError::new(
            path,
            field,
            format!("frame rate {fps}: must be finite, not negative and at most {MAX_FPS} (0 = not given)"),
        ))
    }
}

/// A rate implied by a file's numbers where a bad one cannot be refused on its own (a take still reads): the
/// rate when [`check_fps`] accepts it, else 0 (not given).
pub fn fps_or_unknown(fps: f64) -> f32 {
    if fps_in_range(fps) { fps as f32 } else { 0.0 }
}

/// The one rule of [`check_fps`] and [`fps_or_unknown`]: finite, not negative, at most [`MAX_FPS`].
pub fn fps_in_range(fps: f64) -> bool {
    fps.is_finite() && (0.0..=MAX_FPS).contains(&fps)
}

/// Unit quaternion `(x, y, z, w)`; a zero quaternion becomes the identity.
pub fn normalize_quat(q: [f64; 4]) -> [f64; 4] {
    let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    if n < 1e-12 {
        [0.0, 0.0, 0.0, 1.0]
    } else {
        q.map(|x| x / n)
    }
}

/// Spherical interpolation of unit quaternions along the shorter arc (normalised linear interpolation when they are
/// nearly parallel); component order does not matter.
pub fn slerp(a: [f64; 4], b: [f64; 4], t: f64) -> [f64; 4] {
    let mut dot: f64 = (0..4).map(|k| a[k] * b[k]).sum();
    let b = if dot < 0.0 {
        dot = -dot;
        b.map(|x| -x)
    } else {
        b
    };
    if dot > 0.9995 {
        return normalize_quat(std::array::from_fn(|k| a[k] + t * (b[k] - a[k])));
    }
    let theta = dot.clamp(-1.0, 1.0).acos();
    let (wa, wb) = (((1.0 - t) * theta).sin() / theta.sin(), (t * theta).sin() / theta.sin());
    std::array::from_fn(|k| wa * a[k] + wb * b[k])
}

/// Hamilton product `a · b` of `(x, y, z, w)` quaternions.
pub fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    let [ax, ay, az, aw] = a;
    let [bx, by, bz, bw] = b;
    [
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ]
}

/// Rotate `v` by the unit quaternion `q`.
pub fn quat_rotate(q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
    let r = quat_mul(quat_mul(q, [v[0], v[1], v[2], 0.0]), [-q[0], -q[1], -q[2], q[3]]);
    [r[0], r[1], r[2]]
}

/// `T · R · S` from translation, unit quaternion and scale.
pub fn trs(t: [f64; 3], q: [f64; 4], s: [f64; 3]) -> Mat {
    let [x, y, z, w] = normalize_quat(q);
    let r = [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - z * w),
            2.0 * (x * z + y * w),
        ],
        [
            2.0 * (x * y + z * w),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - x * w),
        ],
        [
            2.0 * (x * z - y * w),
            2.0 * (y * z + x * w),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ];
    let mut m = IDENTITY;
    for (row, out) in r.iter().zip(m.iter_mut()) {
        for c in 0..3 {
            out[c] = row[c] * s[c];
        }
    }
    for k in 0..3 {
        m[k][3] = t[k];
    }
    m
}

/// Inverse of an affine matrix (general 3×3 part); `None` when it is singular.
pub fn inverse(m: &Mat) -> Option<Mat> {
    let a = |r: usize, c: usize| m[r][c];
    let cof = |r0: usize, r1: usize, c0: usize, c1: usize| a(r0, c0) * a(r1, c1) - a(r0, c1) * a(r1, c0);
    let det = a(0, 0) * cof(1, 2, 1, 2) - a(0, 1) * cof(1, 2, 0, 2) + a(0, 2) * cof(1, 2, 0, 1);
    if det.abs() < 1e-300 || !det.is_finite() {
        return None;
    }
    let inv3 = [
        [cof(1, 2, 1, 2), -cof(0, 2, 1, 2), cof(0, 1, 1, 2)],
        [-cof(1, 2, 0, 2), cof(0, 2, 0, 2), -cof(0, 1, 0, 2)],
        [cof(1, 2, 0, 1), -cof(0, 2, 0, 1), cof(0, 1, 0, 1)],
    ]
    .map(|row| row.map(|x| x / det));
    let mut out = IDENTITY;
    for r in 0..3 {
        out[r][..3].copy_from_slice(&inv3[r]);
        out[r][3] = -(0..3).map(|k| inv3[r][k] * m[k][3]).sum::<f64>();
    }
    Some(out)
}

/// Object-space transforms from local ones: `G_j = G_parent(j) · L_j`. Parents must come before children
/// (checked by [`check_parents`]).
pub fn globals(parents: &[Option<usize>], locals: &[Mat]) -> Vec<Mat> {
    let mut g: Vec<Mat> = Vec::with_capacity(locals.len());
    for (j, l) in locals.iter().enumerate() {
        let m = match parents[j] {
            Some(p) => mul(&g[p], l),
            None => *l,
        };
        g.push(m);
    }
    g
}

/// Parent indices from a file: `-1` (or any negative) is a root; a parent must precede its child, which also
/// rules out cycles.
pub fn check_parents(path: &Path, field: &str, raw: &[i32]) -> Result<Vec<Option<usize>>> {
    raw.iter()
        .enumerate()
        .map(|(j, &p)| match usize::try_from(p) {
            Err(_) => Ok(None),
            Ok(p) if p < j => Ok(Some(p)),
            Ok(p) => Err(DataError::new(
                path,
                field,
                format!("joint {j} names parent {p}, which does not precede it"),
            )),
        })
        .collect()
}

/// Per-vertex `(joint, weight)` lists.
pub type Influences = Vec<Vec<(usize, f64)>>;

/// Check joint indices against `joints`, drop zero weights, renormalise sums ≠ 1 and count what needed it. A
/// vertex without any positive weight, or a weight naming a missing joint, is an error naming the vertex.
pub fn clean_influences(path: &Path, field: &str, infl: &mut Influences, joints: usize) -> Result<SkinStats> {
    let mut stats = SkinStats {
        vertices: infl.len(),
        ..SkinStats::default()
    };
    for (v, list) in infl.iter_mut().enumerate() {
        if let Some(&(j, _)) = list.iter().find(|(j, _)| *j >= joints) {
            return Err(DataError::new(
                path,
                field,
                format!("vertex {v} is weighted to joint {j}, but the skeleton has {joints} joints"),
            ));
        }
        if let Some(&(j, w)) = list.iter().find(|(_, w)| !w.is_finite() || *w < 0.0) {
            return Err(DataError::new(
                path,
                field,
                format!("vertex {v} has weight {w} for joint {j}"),
            ));
        }
        list.retain(|(_, w)| *w > 0.0);
        if list.len() > 4 {
            stats.over_four_weights += 1;
        }
        let sum: f64 = list.iter().map(|(_, w)| w).sum();
        if sum <= 0.0 {
            return Err(DataError::new(path, field, format!("vertex {v} has no joint weight")));
        }
        if (sum - 1.0).abs() > WEIGHT_SUM_TOLERANCE {
            stats.renormalised += 1;
        }
        list.iter_mut().for_each(|(_, w)| *w /= sum);
    }
    Ok(stats)
}

/// A key track's value at `frame` (keys sorted by frame): `lerp` between the surrounding keys, held outside them;
/// `None` for an empty track.
pub fn sample_keys<T: Copy>(keys: &[(i64, T)], frame: i64, lerp: impl Fn(T, T, f64) -> T) -> Option<T> {
    let after = keys.partition_point(|(k, _)| *k <= frame);
    match (after.checked_sub(1).map(|i| keys[i]), keys.get(after)) {
        (Some((_, v)), None) | (None, Some(&(_, v))) => Some(v),
        (Some((k0, v0)), Some(&(k1, v1))) => Some(lerp(v0, v1, (frame - k0) as f64 / (k1 - k0) as f64)),
        (None, None) => None,
    }
}

/// Linear interpolation of 3-vectors.
pub fn lerp3(a: [f64; 3], b: [f64; 3], t: f64) -> [f64; 3] {
    std::array::from_fn(|k| a[k] + t * (b[k] - a[k]))
}

/// Left-handed → right-handed (DirectX, Blitz3D): mirror z and reverse every triangle's winding.
pub fn to_right_handed(vertices: &mut [[f32; 3]], faces: Vec<[u32; 3]>) -> Vec<[u32; 3]> {
    vertices.iter_mut().for_each(|v| v[2] = -v[2]);
    faces.into_iter().map(|[a, b, c]| [a, c, b]).collect()
}

/// One frame of linear blend skinning: append `Σ_i w_i · skin_i · p` for each bind position `p`.
pub fn skin_frame(bind: &[[f64; 3]], infl: &Influences, skin: &[Mat], out: &mut Vec<[f32; 3]>) {
    for (p, list) in bind.iter().zip(infl) {
        let mut acc = [0.0; 3];
        for &(j, w) in list {
            let q = apply(&skin[j], *p);
            (0..3).for_each(|c| acc[c] += w * q[c]);
        }
        out.push(acc.map(|x| x as f32));
    }
}

/// The one rule for every sidecar (animation files, `.anm` tables, `animation.cfg`, a BVH's rig), as for glTF's
/// external buffers: it is read only when its real path is a regular file inside the real path of the folder it
/// was found in, so that a link leading out of the folder (to `/dev/zero`, to a file elsewhere) is never followed.
pub fn sidecar_inside(dir: &Path, file: &Path) -> bool {
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    match (dir.canonicalize(), file.canonicalize()) {
        (Ok(d), Ok(f)) => f.starts_with(&d) && f.is_file(),
        _ => false,
    }
}

/// Animation files that may belong to `mesh`: files with one of `exts` (lower-case, no dot) in the mesh's folder
/// and, when `parent` is set, its parent folder, each inside its folder ([`sidecar_inside`]); sorted by path.
pub fn companions(mesh: &Path, exts: &[&str], parent: bool) -> Vec<PathBuf> {
    let mut dirs = Vec::new();
    if let Some(d) = mesh.parent() {
        dirs.push(if d.as_os_str().is_empty() { Path::new(".") } else { d });
        if parent && let Some(pd) = d.parent().filter(|p| !p.as_os_str().is_empty()) {
            dirs.push(pd);
        }
    }
    let mut found = Vec::new();
    for d in dirs {
        let Ok(rd) = std::fs::read_dir(d) else { continue };
        for e in rd.flatten() {
            let p = e.path();
            let ext = p.extension().and_then(|x| x.to_str()).map(str::to_ascii_lowercase);
            if p != mesh && ext.is_some_and(|x| exts.contains(&x.as_str())) && sidecar_inside(d, &p) {
                found.push(p);
            }
        }
    }
    found.sort();
    found
}

/// A baked take of `path` as a clip: id = the file's stem, caption empty, source = the path.
pub fn baked_clip(
    path: &Path,
    vertices: Vec<[f32; 3]>,
    frames: usize,
    faces: Vec<[u32; 3]>,
) -> Result<crate::clip::Clip> {
    let n = vertices.len().checked_div(frames).unwrap_or(0);
    crate::clip::Clip::new(stem(path), vertices, frames, n, faces, "", path.display().to_string())
}

/// The stem of `path` as a take or asset name.
pub fn stem(path: &Path) -> String {
    let name = path
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    // `deer_walk_01.dae.cached.psa` → `deer_walk_01`
    name.split('.').next().unwrap_or_default().to_owned()
}

#[cfg(test)]
mod tests;
