//! Blitz3D `.b3d` skinned meshes (Minetest characters and mobs, Irrlicht assets), baked from their node keys.
//!
//! Layout (little-endian chunks `tag [u8; 4] | length i32 | body`): `BB3D` (version i32, 0 or 1) holding `TEXS`,
//! `BRUS` (skipped) and the root `NODE`s. A `NODE` is `name (NUL-terminated) | position f32×3 | scale f32×3 |
//! rotation quaternion w x y z f32×4` followed by chunks: one `MESH` (`brush i32 | VRTS | TRIS…`), `BONE`
//! (`vertex i32 | weight f32` pairs on the mesh's vertices), `KEYS` (`flags i32` (1 position, 2 scale, 4 rotation)
//! then per key `frame i32` and the flagged values), `ANIM` (`flags i32 | frames i32 | fps f32`) and child `NODE`s.
//! `VRTS` is `flags i32 (1 normal, 2 colour) | texture sets i32 | set size i32` then per vertex the position, the
//! flagged normal and colour and the texture coordinates; `TRIS` is `brush i32` then `i32×3` triangles.
//!
//! Baking (the Irrlicht loader's rules): every node is a joint whose local transform is T·R·S of its keys at the
//! frame (linear interpolation of positions and scales, spherical of rotations, held before the first and after
//! the last key) and of its rest values where it has no key of a kind. The mesh's vertices are in its node's frame
//! and are first moved by that node's rest transform; then
//! `v_f = Σ_i w_i · G_f(j_i) · G_rest(j_i)⁻¹ · v_rest` (docs/method.md's linear blend skinning), a vertex that no
//! `BONE` weights following its mesh node. The take is every integer frame from the smallest to the largest key
//! frame of the file (`ANIM` gives only the rate). Only files with one `MESH` are read.
//!
//! Blitz3D is left-handed (y up, z into the screen): the baked positions are mirrored to right-handed y-up
//! coordinates, `(x, y, z) → (x, y, −z)`, with each triangle's winding reversed so that faces keep pointing out.

use std::path::Path;

use super::bytes::Bytes;
use super::skeletal::{
    self, Influences, Mat, ReadOptions, SkinStats, TakeInfo, apply, clean_influences, globals, inverse, lerp3, mul,
    normalize_quat, sample_keys, skin_frame, slerp, trs,
};
use crate::clip::Clip;
use crate::error::{DataError, Result};

/// Deepest node nesting read (a deeper file is refused, not recursed into).
pub const MAX_DEPTH: usize = 128;

#[derive(Default)]
struct Keys {
    position: Vec<(i64, [f64; 3])>,
    scale: Vec<(i64, [f64; 3])>,
    /// Quaternions x y z w.
    rotation: Vec<(i64, [f64; 4])>,
}

struct Node {
    parent: Option<usize>,
    position: [f64; 3],
    scale: [f64; 3],
    /// x y z w.
    rotation: [f64; 4],
    keys: Keys,
}

/// The node holding the mesh, its vertices (in that node's frame) and triangles.
type Mesh = (usize, Vec<[f64; 3]>, Vec<[u32; 3]>);

struct B3d {
    nodes: Vec<Node>,
    mesh: Option<Mesh>,
    /// (vertex, node, weight) from the `BONE` chunks.
    weights: Vec<(usize, usize, f64)>,
    fps: f32,
}

/// The next chunk's tag and the offset where its body ends (checked against `end`, its parent's end).
fn chunk(b: &mut Bytes, end: usize) -> Result<([u8; 4], usize)> {
    let tag: [u8; 4] = b.take(4, "chunk")?.try_into().expect("4 bytes");
    let name = String::from_utf8_lossy(&tag).into_owned();
    let len = b.count_i32(&format!("{name} length"))?;
    match b.pos().checked_add(len) {
        Some(body_end) if body_end <= end => Ok((tag, body_end)),
        _ => Err(b.err(
            format!("{name} length"),
            format!(
                "a {len}-byte chunk at offset {} runs past its parent, which ends at {end}",
                b.pos()
            ),
        )),
    }
}

fn cstring(b: &mut Bytes, end: usize, field: &str) -> Result<String> {
    let mut raw = Vec::new();
    while b.pos() < end {
        match b.u8(field)? {
            0 => return Ok(String::from_utf8_lossy(&raw).into_owned()),
            c => raw.push(c),
        }
    }
    Err(b.err(field, "the name is not NUL-terminated inside its chunk"))
}

fn vec3(b: &mut Bytes, field: &str) -> Result<[f64; 3]> {
    Ok(b.f32s::<3>(field)?.map(f64::from))
}

/// A file quaternion (w x y z) as x y z w.
fn quat(b: &mut Bytes, field: &str) -> Result<[f64; 4]> {
    let [w, x, y, z] = b.f32s::<4>(field)?.map(f64::from);
    Ok(normalize_quat([x, y, z, w]))
}

fn parse(path: &Path) -> Result<B3d> {
    let data = super::read_clip_file(path)?;
    let p = path.display().to_string();
    let mut b = Bytes::new(&p, &data);
    if data.get(..4) != Some(&b"BB3D"[..]) {
        return Err(b.err("magic", "not a B3D file (no BB3D chunk)"));
    }
    let (_, end) = chunk(&mut b, data.len())?;
    let version = b.i32("version")?;
    if !(0..=1).contains(&version) {
        return Err(b.err("version", format!("version {version}, only 0 and 1 are supported")));
    }
    let mut file = B3d {
        nodes: Vec::new(),
        mesh: None,
        weights: Vec::new(),
        fps: 0.0,
    };
    while b.pos() < end {
        let (tag, body_end) = chunk(&mut b, end)?;
        if &tag == b"NODE" {
            node(&mut b, body_end, None, 0, &mut file)?;
        }
        leave(&mut b, body_end, &tag)?;
    }
    Ok(file)
}

fn node(b: &mut Bytes, end: usize, parent: Option<usize>, depth: usize, file: &mut B3d) -> Result<()> {
    let j = file.nodes.len();
    let field = format!("nodes[{j}]");
    if depth >= MAX_DEPTH {
        return Err(b.err(field, format!("nodes nested deeper than {MAX_DEPTH}")));
    }
    if j >= skeletal::MAX_JOINTS {
        return Err(b.err(field, format!("more than {} nodes", skeletal::MAX_JOINTS)));
    }
    cstring(b, end, &field)?;
    let position = vec3(b, &field)?;
    let scale = vec3(b, &field)?;
    let rotation = quat(b, &field)?;
    file.nodes.push(Node {
        parent,
        position,
        scale,
        rotation,
        keys: Keys::default(),
    });
    while b.pos() < end {
        let (tag, body_end) = chunk(b, end)?;
        match &tag {
            b"MESH" => mesh(b, body_end, j, file)?,
            b"BONE" => {
                let f = format!("{field}.BONE");
                let bytes = left(b, body_end, &f)?;
                let n = bytes / 8;
                if !bytes.is_multiple_of(8) {
                    return Err(b.err(f, "length is not a whole number of (vertex, weight) pairs"));
                }
                file.weights.reserve(n);
                for _ in 0..n {
                    let v = b.count_i32(&f)?;
                    let w = f64::from(b.f32(&f)?);
                    file.weights.push((v, j, w));
                }
            }
            b"KEYS" => keys(b, body_end, &format!("{field}.KEYS"), &mut file.nodes[j].keys)?,
            b"ANIM" => {
                let _flags = b.i32("ANIM")?;
                let _frames = b.i32("ANIM")?;
                file.fps = b.f32("ANIM")?;
            }
            b"NODE" => node(b, body_end, Some(j), depth + 1, file)?,
            _ => {}
        }
        leave(b, body_end, &tag)?;
    }
    Ok(())
}

/// The bytes left in a chunk whose body ends at `end`; an error when its header fields already ran past it.
fn left(b: &Bytes, end: usize, field: &str) -> Result<usize> {
    end.checked_sub(b.pos())
        .ok_or_else(|| b.err(field, format!("the chunk's fields run past its end at offset {end}")))
}

/// Moves to the end of a chunk, refusing one whose fields ran past that end.
fn leave(b: &mut Bytes, end: usize, tag: &[u8; 4]) -> Result<()> {
    left(b, end, &String::from_utf8_lossy(tag))?;
    b.seek(end, "chunk")
}

fn keys(b: &mut Bytes, end: usize, field: &str, out: &mut Keys) -> Result<()> {
    let flags = b.i32(field)?;
    let size = 4 + [(1, 12), (2, 12), (4, 16)]
        .iter()
        .filter(|(bit, _)| flags & bit != 0)
        .map(|(_, s)| s)
        .sum::<usize>();
    let bytes = left(b, end, field)?;
    if !bytes.is_multiple_of(size) {
        return Err(b.err(field, format!("{bytes} bytes of keys are not whole {size}-byte keys")));
    }
    for _ in 0..bytes / size {
        let frame = i64::from(b.i32(field)?);
        if flags & 1 != 0 {
            out.position.push((frame, vec3(b, field)?));
        }
        if flags & 2 != 0 {
            out.scale.push((frame, vec3(b, field)?));
        }
        if flags & 4 != 0 {
            out.rotation.push((frame, quat(b, field)?));
        }
    }
    Ok(())
}

fn mesh(b: &mut Bytes, end: usize, node: usize, file: &mut B3d) -> Result<()> {
    if file.mesh.is_some() {
        return Err(b.err(
            format!("nodes[{node}].MESH"),
            "a second MESH: only files with one mesh are read",
        ));
    }
    let _brush = b.i32("MESH.brush")?;
    let mut positions: Vec<[f64; 3]> = Vec::new();
    let mut faces = Vec::new();
    while b.pos() < end {
        let (tag, body_end) = chunk(b, end)?;
        match &tag {
            b"VRTS" => {
                let flags = b.i32("VRTS.flags")?;
                let (sets, size) = (
                    b.count_i32("VRTS.tex_coord_sets")?,
                    b.count_i32("VRTS.tex_coord_set_size")?,
                );
                if sets > 8 || size > 4 {
                    return Err(b.err("VRTS", format!("{sets} texture sets of {size} values (at most 8 of 4)")));
                }
                let stride =
                    12 + if flags & 1 != 0 { 12 } else { 0 } + if flags & 2 != 0 { 16 } else { 0 } + 4 * sets * size;
                let bytes = left(b, body_end, "VRTS")?;
                if !bytes.is_multiple_of(stride) {
                    return Err(b.err("VRTS", format!("{bytes} bytes are not whole {stride}-byte vertices")));
                }
                positions.reserve(bytes / stride);
                for v in 0..bytes / stride {
                    let f = format!("VRTS[{v}]");
                    positions.push(vec3(b, &f)?);
                    b.take(stride - 12, &f)?;
                }
            }
            b"TRIS" => {
                let _brush = b.i32("TRIS.brush")?;
                let bytes = left(b, body_end, "TRIS")?;
                if !bytes.is_multiple_of(12) {
                    return Err(b.err("TRIS", format!("{bytes} bytes are not whole triangles")));
                }
                for t in 0..bytes / 12 {
                    let f = format!("TRIS[{t}]");
                    let tri = [b.count_i32(&f)?, b.count_i32(&f)?, b.count_i32(&f)?];
                    if let Some(&i) = tri.iter().find(|&&i| i >= positions.len()) {
                        return Err(b.err(f, format!("vertex {i} of {}", positions.len())));
                    }
                    faces.push(tri.map(|i| i as u32));
                }
            }
            _ => {}
        }
        leave(b, body_end, &tag)?;
    }
    file.mesh = Some((node, positions, faces));
    Ok(())
}

impl Node {
    fn local(&self, frame: Option<i64>) -> Mat {
        let at = |f: i64| {
            (
                sample_keys(&self.keys.position, f, lerp3).unwrap_or(self.position),
                sample_keys(&self.keys.rotation, f, slerp).unwrap_or(self.rotation),
                sample_keys(&self.keys.scale, f, lerp3).unwrap_or(self.scale),
            )
        };
        let (t, q, s) = match frame {
            Some(f) => at(f),
            None => (self.position, self.rotation, self.scale),
        };
        trs(t, q, s)
    }
}

/// The key frames of the file: (first, last), or `None` when no node has a key.
fn key_range(nodes: &[Node]) -> Option<(i64, i64)> {
    let frames = nodes.iter().flat_map(|n| {
        n.keys
            .position
            .iter()
            .map(|k| k.0)
            .chain(n.keys.scale.iter().map(|k| k.0))
            .chain(n.keys.rotation.iter().map(|k| k.0))
    });
    frames.fold(None, |r, f| match r {
        None => Some((f, f)),
        Some((lo, hi)) => Some((lo.min(f), hi.max(f))),
    })
}

fn takes(file: &B3d) -> Vec<TakeInfo> {
    let Some((lo, hi)) = key_range(&file.nodes) else {
        return Vec::new();
    };
    let frames = usize::try_from(hi - lo + 1).unwrap_or(usize::MAX);
    let mut t = skeletal::single_take(frames);
    t.iter_mut().for_each(|t| t.fps = file.fps);
    t
}

/// The file's one take (every key frame), or none for a file without keys.
pub fn list_takes(path: &Path) -> Result<Vec<TakeInfo>> {
    Ok(takes(&parse(path)?))
}

/// Bake the take of a `.b3d` into a clip (id = file stem, caption empty).
pub fn read(path: &Path, opts: &ReadOptions) -> Result<(Clip, SkinStats, TakeInfo)> {
    let mut file = parse(path)?;
    let Some((mesh_node, positions, faces)) = file.mesh.take() else {
        return Err(DataError::new(path, "MESH", "no mesh in the file"));
    };
    let all = takes(&file);
    let info = all[skeletal::pick(path, &all, &opts.take)?].clone();
    skeletal::check_frames(path, &info.name, info.frames, opts.max_frames)?;
    let (first, _) = key_range(&file.nodes).expect("a take has keys");
    for n in &mut file.nodes {
        n.keys.position.sort_by_key(|k| k.0);
        n.keys.scale.sort_by_key(|k| k.0);
        n.keys.rotation.sort_by_key(|k| k.0);
    }
    let n = positions.len();
    let mut infl: Influences = vec![Vec::new(); n];
    for &(v, j, w) in &file.weights {
        let list = infl
            .get_mut(v)
            .ok_or_else(|| DataError::new(path, format!("nodes[{j}].BONE"), format!("vertex {v} of {n}")))?;
        list.push((j, w));
    }
    for list in &mut infl {
        if list.iter().all(|&(_, w)| w == 0.0) {
            *list = vec![(mesh_node, 1.0)];
        }
    }
    let stats = clean_influences(path, "BONE", &mut infl, file.nodes.len())?;
    let parents: Vec<Option<usize>> = file.nodes.iter().map(|n| n.parent).collect();
    let frame_globals = |frame: Option<i64>| {
        let locals: Vec<Mat> = file.nodes.iter().map(|n| n.local(frame)).collect();
        globals(&parents, &locals)
    };
    let rest = frame_globals(None);
    let bind: Vec<[f64; 3]> = positions.iter().map(|&p| apply(&rest[mesh_node], p)).collect();
    let inv_rest: Vec<Mat> = rest
        .iter()
        .enumerate()
        .map(|(j, m)| inverse(m).ok_or_else(|| DataError::new(path, format!("nodes[{j}]"), "singular rest transform")))
        .collect::<Result<_>>()?;
    skeletal::check_rows(path, info.frames, n)?;
    let mut vertices = Vec::with_capacity(info.frames * n);
    for f in 0..info.frames {
        let g = frame_globals(Some(first + f as i64));
        let skin: Vec<Mat> = g.iter().zip(&inv_rest).map(|(g, inv)| mul(g, inv)).collect();
        skin_frame(&bind, &infl, &skin, &mut vertices);
    }
    let faces = skeletal::to_right_handed(&mut vertices, faces);
    let clip = Clip::new(
        skeletal::stem(path),
        vertices,
        info.frames,
        n,
        faces,
        "",
        path.display().to_string(),
    )?;
    Ok((clip, stats, info))
}

/// Bytes of a B3D for tests: a root node holding the mesh (positions, triangles) and one child bone node at
/// `bone_at` (rest position) that weights `bone_vertices` fully and has position keys `keys` (frame, position).
#[doc(hidden)]
pub fn write_test_b3d(
    positions: &[[f32; 3]],
    faces: &[[u32; 3]],
    bone_at: [f32; 3],
    bone_vertices: &[u32],
    keys: &[(i32, [f32; 3])],
) -> Vec<u8> {
    fn chunk(tag: &[u8; 4], body: &[u8]) -> Vec<u8> {
        let mut out = tag.to_vec();
        out.extend((body.len() as i32).to_le_bytes());
        out.extend(body);
        out
    }
    let floats = |xs: &[f32]| xs.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    let node_head = |name: &str, at: [f32; 3]| {
        let mut h = name.as_bytes().to_vec();
        h.push(0);
        h.extend(floats(&at));
        h.extend(floats(&[1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0]));
        h
    };
    let mut vrts = [0i32, 0, 0].iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    positions.iter().for_each(|p| vrts.extend(floats(p)));
    let mut tris = (-1i32).to_le_bytes().to_vec();
    faces
        .iter()
        .flatten()
        .for_each(|&i| tris.extend((i as i32).to_le_bytes()));
    let mut mesh = (-1i32).to_le_bytes().to_vec();
    mesh.extend(chunk(b"VRTS", &vrts));
    mesh.extend(chunk(b"TRIS", &tris));
    let mut bone = Vec::new();
    bone_vertices.iter().for_each(|&v| {
        bone.extend((v as i32).to_le_bytes());
        bone.extend(1.0f32.to_le_bytes());
    });
    let mut key_body = 1i32.to_le_bytes().to_vec();
    keys.iter().for_each(|(f, p)| {
        key_body.extend(f.to_le_bytes());
        key_body.extend(floats(p));
    });
    let mut child = node_head("bone", bone_at);
    child.extend(chunk(b"BONE", &bone));
    child.extend(chunk(b"KEYS", &key_body));
    let mut root = node_head("root", [0.0; 3]);
    root.extend(chunk(b"MESH", &mesh));
    let mut anim = 0i32.to_le_bytes().to_vec();
    anim.extend((keys.len() as i32).to_le_bytes());
    anim.extend(25.0f32.to_le_bytes());
    root.extend(chunk(b"ANIM", &anim));
    root.extend(chunk(b"NODE", &child));
    let mut file = 1i32.to_le_bytes().to_vec();
    file.extend(chunk(b"NODE", &root));
    chunk(b"BB3D", &file)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn triangle_file(keys: &[(i32, [f32; 3])]) -> Vec<u8> {
        let pos = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 1.0]];
        write_test_b3d(&pos, &[[0, 1, 2]], [0.0, 1.0, 0.0], &[2], keys)
    }

    #[test]
    fn bakes_node_keys_mirrors_z_and_reverses_winding() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("guy.b3d");
        // The bone rises from its rest height 1 to 3 between frames 1 and 5; vertex 2 rides on it.
        std::fs::write(&path, triangle_file(&[(1, [0.0, 1.0, 0.0]), (5, [0.0, 3.0, 0.0])])).unwrap();
        let takes = list_takes(&path).unwrap();
        assert_eq!((takes.len(), takes[0].frames, takes[0].fps), (1, 5, 25.0));
        let (clip, stats, _) = read(&path, &ReadOptions::default()).unwrap();
        assert_eq!((clip.frames, clip.n_vertices, stats.vertices), (5, 3, 3));
        assert_eq!(clip.faces, vec![[0, 2, 1]]);
        assert_eq!(clip.frame(0)[2], [0.0, 1.0, -1.0]);
        assert_eq!(clip.frame(2)[2], [0.0, 2.0, -1.0]);
        assert_eq!(clip.frame(4)[2], [0.0, 3.0, -1.0]);
        // Vertices no bone weights follow the mesh node (here: still).
        assert_eq!(clip.frame(4)[1], [1.0, 0.0, 0.0]);
    }

    #[test]
    fn refuses_static_truncated_huge_and_overlong_files() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.b3d");
        std::fs::write(&path, triangle_file(&[])).unwrap();
        let e = read(&path, &ReadOptions::default()).unwrap_err();
        assert!(e.reason.contains("static mesh"), "{e}");
        let good = triangle_file(&[(1, [0.0; 3]), (3, [0.0; 3])]);
        // Every truncation is an error, never a panic or a clip.
        for cut in 0..good.len() {
            std::fs::write(&path, &good[..cut]).unwrap();
            assert!(read(&path, &ReadOptions::default()).is_err(), "cut {cut}");
        }
        // A chunk that claims more bytes than its parent holds.
        let mut huge = good.clone();
        huge[4..8].copy_from_slice(&i32::MAX.to_le_bytes());
        std::fs::write(&path, &huge).unwrap();
        assert!(
            read(&path, &ReadOptions::default())
                .unwrap_err()
                .reason
                .contains("runs past")
        );
        // Keys a billion frames apart: refused by the frame limit before anything is allocated.
        std::fs::write(&path, triangle_file(&[(1, [0.0; 3]), (1_000_000_000, [0.0; 3])])).unwrap();
        let e = read(&path, &ReadOptions::default()).unwrap_err();
        assert!(e.field == "frames" && e.reason.contains("maximum"), "{e}");
        // A weight on a vertex the mesh does not have.
        let pos = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 1.0]];
        let bad = write_test_b3d(&pos, &[[0, 1, 2]], [0.0; 3], &[7], &[(1, [0.0; 3]), (2, [0.0; 3])]);
        std::fs::write(&path, bad).unwrap();
        let e = read(&path, &ReadOptions::default()).unwrap_err();
        assert!(e.reason.contains("vertex 7 of 3"), "{e}");
        std::fs::write(&path, b"BB3Dxxxx").unwrap();
        assert!(read(&path, &ReadOptions::default()).is_err());
    }

    #[test]
    fn refuses_chunks_shorter_than_their_own_fields() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.b3d");
        let good = triangle_file(&[(1, [0.0; 3]), (3, [0.0; 3])]);
        for tag in [b"TRIS", b"VRTS", b"KEYS", b"ANIM", b"BONE"] {
            let at = good.windows(4).position(|w| w == tag).unwrap();
            // Two bytes claimed: fewer than the chunk's header fields (a brush, flags or counts) need.
            let mut short = good.clone();
            short[at + 4..at + 8].copy_from_slice(&2i32.to_le_bytes());
            std::fs::write(&path, &short).unwrap();
            let e = read(&path, &ReadOptions::default()).unwrap_err();
            assert!(!e.reason.contains("panicked"), "{}: {e}", String::from_utf8_lossy(tag));
        }
    }
}
