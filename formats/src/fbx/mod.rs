//! Binary FBX 7 (what Mixamo, Maya, 3ds Max and Blender export): meshes, skins and animation stacks, baked per
//! frame of the file's frame rate.
//!
//! The file ([`binary`]) holds an `Objects` section (models, geometries, deformers, animation stacks, layers,
//! curve nodes and curves, each with a 64-bit id) and a `Connections` section linking child ids to parent ids,
//! some by a property name. The takes are the `AnimationStack`s in file order, named by their own names; a stack
//! without a curve that has two keys at different times is no motion and is not a take.
//!
//! **Transforms.** A model's local transform is the FBX SDK's
//! `T · Roff · Rp · Rpre · R · Rpost⁻¹ · Rp⁻¹ · Soff · Sp · S · Sp⁻¹`, from its `Lcl Translation`,
//! `Lcl Rotation` (Euler angles in degrees in the model's `RotationOrder`; `XYZ` turns about x first),
//! `Lcl Scaling`, `PreRotation`, `PostRotation`, the rotation and scaling offsets and pivots, each from the model's
//! own properties, else its object type's property template, else the SDK's default. A child's global transform
//! is its parent's times its local one. An animated channel (`T`, `R`, `S` curve nodes on `Lcl Translation`,
//! `Lcl Rotation`, `Lcl Scaling`) takes each component from its curve (`d|X`, `d|Y`, `d|Z`), linear between
//! keys and held outside them, or the curve node's default when a component has no curve. Layers are not
//! blended: a channel animated in several layers of a stack takes the first layer's curve node.
//!
//! **Geometry.** Every mesh geometry connected to a model is read into one vertex list, polygons split into fans
//! (two-corner polygons, lines, are dropped). A skinned geometry's vertex is `Σ_k w_k · G(bone_k) ·
//! TransformLink_k⁻¹ · G₀(model) · Geo · v` over the clusters of its skin, `G₀` the transform of the model the
//! geometry hangs on in its unanimated pose and `Geo` that model's geometric transform (as assimp does: the
//! clusters' own `Transform` is not used, exporters disagree on it — Blender writes it relative to the bone); a
//! vertex no cluster weights, and every vertex of an unskinned geometry, is `G(model) · Geo · v`. Blend shapes
//! are not read.
//!
//! **Axes.** The `GlobalSettings` axis system (up, front and coordinate axes with their signs) is turned into
//! this crate's Y-up frame: `(x', y', z') = (coord, up, front)`; when that is a reflection the windings are
//! reversed. Units are left as they are (normalisation is preprocessing's job). The frame rate is the
//! `TimeMode`'s (or `CustomFrameRate`); a take spans its stack's `LocalStart` (0 when missing) to `LocalStop`,
//! or its keys when the stack has no `LocalStop` after its start.

use std::collections::HashMap;
use std::path::Path;

use super::skeletal::{
    self, IDENTITY, Influences, Mat, ReadOptions, SkinStats, TakeInfo, clean_influences, globals, inverse, mul,
    sample_keys, skin_frame,
};
use crate::clip::Clip;
use crate::error::Result;
use binary::Prop;
use scene::Scene;
use transform::{Pivots, axes, euler, scaling, translation};
pub use write::{p70_entry, test_fbx_nodes, write_test_fbx};

pub mod binary;
mod scene;
mod transform;
mod write;

/// Largest `.fbx` file read, in bytes.
pub const MAX_FBX_BYTES: u64 = 512 << 20;

/// FBX time unit: ticks per second of `KeyTime` and `LocalStart`/`LocalStop`.
pub const TICKS_PER_SECOND: f64 = 46_186_158_000.0;

/// One animation curve: `(tick, value)` sorted by tick.
type Curve = Vec<(i64, f64)>;

/// An animated `T`, `R` or `S` channel of a model.
struct Channel {
    defaults: [f64; 3],
    curves: [Option<Curve>; 3],
}

impl Channel {
    fn at(&self, tick: i64) -> [f64; 3] {
        std::array::from_fn(|k| {
            self.curves[k]
                .as_ref()
                .and_then(|c| sample_keys(c, tick, |a, b, f| a + f * (b - a)))
                .unwrap_or(self.defaults[k])
        })
    }
}

/// A take: its channels per model index (`[T, R, S]`) and its ticks.
struct Take {
    info: TakeInfo,
    channels: HashMap<usize, [Option<Channel>; 3]>,
    start: i64,
    ticks_per_frame: f64,
}

const CHANNELS: [&str; 3] = ["Lcl Translation", "Lcl Rotation", "Lcl Scaling"];

/// Frames per second of the file's `TimeMode`.
fn frame_rate(scene: &Scene) -> Result<f64> {
    let mode = scene.setting("TimeMode").and_then(Prop::int).unwrap_or(0);
    Ok(match mode {
        1 => 120.0,
        2 => 100.0,
        3 => 60.0,
        4 => 50.0,
        5 => 48.0,
        8 | 9 => 30_000.0 / 1001.0,
        10 => 25.0,
        11 => 24.0,
        12 => 1000.0,
        13 => 24_000.0 / 1001.0,
        14 => {
            let f = scene.setting("CustomFrameRate").and_then(Prop::float).unwrap_or(0.0);
            if !(f.is_finite() && f > 0.0 && f <= 1000.0) {
                return Err(scene.err("GlobalSettings CustomFrameRate", format!("{f} frames per second")));
            }
            f
        }
        15 => 96.0,
        16 => 72.0,
        17 => 60_000.0 / 1001.0,
        18 => 120_000.0 / 1001.0,
        _ => 30.0,
    })
}

fn curve(scene: &Scene, id: i64) -> Result<Curve> {
    let o = &scene.objects[&id];
    let field = || format!("AnimationCurve {:?}", o.name);
    let times = scene.ints(id, "KeyTime")?;
    let values = scene.array(id, "KeyValueFloat")?;
    if times.len() != values.len() {
        return Err(scene.err(
            field(),
            format!("{} key times but {} key values", times.len(), values.len()),
        ));
    }
    if let Some(v) = values.iter().find(|v| !v.is_finite()) {
        return Err(scene.err(field(), format!("a non-finite key value {v}")));
    }
    let mut keys: Curve = times.iter().copied().zip(values.iter().copied()).collect();
    keys.sort_by_key(|k| k.0);
    Ok(keys)
}

/// The takes of the file, given each model id's index, and the names of the stacks that move something over
/// one frame only (poses, not takes).
fn takes(scene: &Scene, model_index: &HashMap<i64, usize>) -> Result<(Vec<Take>, Vec<String>)> {
    let fps = frame_rate(scene)?;
    let ticks_per_frame = TICKS_PER_SECOND / fps;
    let mut out = Vec::new();
    let mut poses = Vec::new();
    for (i, stack) in scene.of_kind("AnimationStack").into_iter().enumerate() {
        let mut channels: HashMap<usize, [Option<Channel>; 3]> = HashMap::new();
        let (mut lo, mut hi, mut moving) = (i64::MAX, i64::MIN, false);
        for layer in scene.children(stack, "AnimationLayer", None) {
            for node in scene.children(layer, "AnimationCurveNode", None) {
                for &(c, p, prop) in &scene.links {
                    let (Some(prop), true) = (prop, c == node) else {
                        continue;
                    };
                    let (Some(&m), Some(k)) = (model_index.get(&p), CHANNELS.iter().position(|x| *x == prop)) else {
                        continue;
                    };
                    let slot = &mut channels.entry(m).or_default()[k];
                    if slot.is_some() {
                        continue;
                    }
                    let mut ch = Channel {
                        defaults: [0.0; 3],
                        curves: [None, None, None],
                    };
                    for (a, axis) in ["d|X", "d|Y", "d|Z"].iter().enumerate() {
                        ch.defaults[a] = scene
                            .prop(node, axis)
                            .and_then(|v| v.first())
                            .and_then(Prop::float)
                            .filter(|v| v.is_finite())
                            .unwrap_or(if k == 2 { 1.0 } else { 0.0 });
                        if let Some(&cid) = scene.children(node, "AnimationCurve", Some(axis)).first() {
                            let keys = curve(scene, cid)?;
                            if let (Some(first), Some(last)) = (keys.first(), keys.last()) {
                                lo = lo.min(first.0);
                                hi = hi.max(last.0);
                                moving |= last.0 > first.0;
                            }
                            ch.curves[a] = Some(keys);
                        }
                    }
                    *slot = Some(ch);
                }
            }
        }
        let span = |name: &str| scene.prop(stack, name).and_then(|v| v.first()).and_then(Prop::int);
        let (start, stop) = match (span("LocalStart").unwrap_or(0), span("LocalStop")) {
            (a, Some(b)) if b > a => (a, b),
            _ => (lo, hi),
        };
        let frames = ((stop as f64 - start as f64) / ticks_per_frame).round() + 1.0;
        let name = scene.objects[&stack].name;
        let name = if name.is_empty() {
            format!("take{i}")
        } else {
            name.to_owned()
        };
        // Keys on one time (or within one frame) hold a pose: listed as such, not a take.
        if !moving || frames < 2.0 {
            if lo <= hi {
                poses.push(name);
            }
            continue;
        }
        out.push(Take {
            info: TakeInfo {
                name,
                frames: if frames >= usize::MAX as f64 {
                    usize::MAX
                } else {
                    frames as usize
                },
                fps: super::skeletal::fps_or_unknown(fps),
                file: None,
            },
            channels,
            start,
            ticks_per_frame,
        });
    }
    Ok((out, poses))
}

/// Model ids with parents before children, and each one's parent index.
fn hierarchy(scene: &Scene) -> Result<(Vec<i64>, Vec<Option<usize>>)> {
    let models = scene.of_kind("Model");
    if models.len() > skeletal::MAX_JOINTS {
        return Err(scene.err(
            "Model",
            format!(
                "{} models, more than the maximum of {}",
                models.len(),
                skeletal::MAX_JOINTS
            ),
        ));
    }
    let mut parent: HashMap<i64, i64> = HashMap::new();
    for &(c, p, prop) in &scene.links {
        if prop.is_none() && scene.objects.get(&p).is_some_and(|o| o.node.name == "Model") {
            parent.entry(c).or_insert(p);
        }
    }
    let parent_of = |id: i64| parent.get(&id).copied();
    let mut depth = Vec::with_capacity(models.len());
    for &m in &models {
        let (mut d, mut at) = (0usize, m);
        while let Some(p) = parent_of(at) {
            d += 1;
            at = p;
            if d > models.len() {
                return Err(scene.err(
                    format!("Model {:?}", scene.objects[&m].name),
                    "its parent chain is a cycle",
                ));
            }
        }
        depth.push((d, m));
    }
    depth.sort_unstable();
    let order: Vec<i64> = depth.into_iter().map(|(_, m)| m).collect();
    let index: HashMap<i64, usize> = order.iter().enumerate().map(|(i, &m)| (m, i)).collect();
    let parents = order.iter().map(|&m| parent_of(m).map(|p| index[&p])).collect();
    Ok((order, parents))
}

fn read_doc(path: &Path) -> Result<binary::Document> {
    let bytes = super::read_file(path, MAX_FBX_BYTES.min(crate::limits::FILE_BYTES.get()))?;
    binary::parse(&path.display().to_string(), &bytes)
}

/// The takes of an `.fbx` file: its animation stacks that move something.
pub fn list_takes(path: &Path) -> Result<Vec<TakeInfo>> {
    let doc = read_doc(path)?;
    let scene = Scene::new(path, &doc);
    let (order, _) = hierarchy(&scene)?;
    let index = order.iter().enumerate().map(|(i, &m)| (m, i)).collect();
    Ok(takes(&scene, &index)?.0.into_iter().map(|t| t.info).collect())
}

/// The animation stacks of an `.fbx` file that move something over one frame only (poses, not takes), by name.
pub fn one_frame_takes(path: &Path) -> Result<Vec<String>> {
    let doc = read_doc(path)?;
    let scene = Scene::new(path, &doc);
    let (order, _) = hierarchy(&scene)?;
    let index = order.iter().enumerate().map(|(i, &m)| (m, i)).collect();
    Ok(takes(&scene, &index)?.1)
}

/// A skin cluster: its bone's model index, `TransformLink⁻¹ · G₀(model) · Geo`, and `(vertex, weight)`.
type Cluster = (usize, Mat, Vec<(usize, f64)>);

/// A mesh geometry placed by a model: its vertices, triangles and skin.
struct Instance {
    model: usize,
    geo: Mat,
    positions: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
    clusters: Vec<Cluster>,
}

/// Geometry `geometry` on model `model` (id `model_id`, unanimated transform `rest`).
fn instance(
    scene: &Scene,
    geometry: i64,
    (model, model_id, rest): (usize, i64, &Mat),
    index: &HashMap<i64, usize>,
) -> Result<Instance> {
    let o = &scene.objects[&geometry];
    let field = |what: &str| format!("Geometry {:?} {what}", o.name);
    let v = scene.array(geometry, "Vertices")?;
    if v.len() % 3 != 0 || v.iter().any(|x| !x.is_finite()) {
        return Err(scene.err(
            field("Vertices"),
            format!("{} values, not finite x, y, z triples", v.len()),
        ));
    }
    let positions: Vec<[f64; 3]> = v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let n = positions.len();
    let mut faces = Vec::new();
    let mut poly: Vec<u32> = Vec::new();
    for (k, &raw) in scene.ints(geometry, "PolygonVertexIndex")?.iter().enumerate() {
        let i = if raw < 0 { !raw } else { raw };
        if i < 0 || i as usize >= n {
            return Err(scene.err(
                field("PolygonVertexIndex"),
                format!("entry {k} names vertex {i}, but the geometry has {n}"),
            ));
        }
        poly.push(i as u32);
        if raw < 0 {
            faces.extend((1..poly.len().saturating_sub(1)).map(|c| [poly[0], poly[c], poly[c + 1]]));
            poly.clear();
        }
    }
    if !poly.is_empty() {
        return Err(scene.err(
            field("PolygonVertexIndex"),
            "the last polygon is not closed (no negative index)",
        ));
    }
    let geo = mul(
        &mul(
            &translation(scene.vec3(model_id, "GeometricTranslation", [0.0; 3])?),
            &euler(scene.vec3(model_id, "GeometricRotation", [0.0; 3])?, 0),
        ),
        &scaling(scene.vec3(model_id, "GeometricScaling", [1.0; 3])?),
    );
    let bind = mul(rest, &geo);
    let mut clusters = Vec::new();
    for skin in scene.children(geometry, "Deformer", None) {
        if scene.objects[&skin].class != "Skin" {
            continue;
        }
        for cluster in scene.children(skin, "Deformer", None) {
            let c = &scene.objects[&cluster];
            let cfield = |what: &str| format!("Cluster {:?} {what}", c.name);
            let bone = scene
                .links
                .iter()
                .find(|(ch, p, prop)| *p == cluster && prop.is_none() && index.contains_key(ch))
                .map(|l| index[&l.0])
                .ok_or_else(|| scene.err(cfield("bone"), "no model (joint) is linked to the cluster"))?;
            let idx = scene.ints(cluster, "Indexes")?;
            let w = scene.array(cluster, "Weights")?;
            if idx.len() != w.len() {
                return Err(scene.err(
                    cfield("Weights"),
                    format!("{} indices but {} weights", idx.len(), w.len()),
                ));
            }
            let mut list = Vec::with_capacity(idx.len());
            for (&i, &wt) in idx.iter().zip(w) {
                let vi = usize::try_from(i)
                    .ok()
                    .filter(|&i| i < n)
                    .ok_or_else(|| scene.err(cfield("Indexes"), format!("vertex {i}, but the geometry has {n}")))?;
                list.push((vi, wt));
            }
            let link = scene.matrix(cluster, "TransformLink")?.unwrap_or(IDENTITY);
            let link_inv = inverse(&link).ok_or_else(|| scene.err(cfield("TransformLink"), "a singular matrix"))?;
            clusters.push((bone, mul(&link_inv, &bind), list));
        }
    }
    Ok(Instance {
        model,
        geo,
        positions,
        faces,
        clusters,
    })
}

/// Bake take `opts.take` of an `.fbx` file into a clip (id = file stem, caption empty).
pub fn read(path: &Path, opts: &ReadOptions) -> Result<(Clip, SkinStats, TakeInfo)> {
    let doc = read_doc(path)?;
    let scene = Scene::new(path, &doc);
    let (order, parents) = hierarchy(&scene)?;
    let index: HashMap<i64, usize> = order.iter().enumerate().map(|(i, &m)| (m, i)).collect();
    let pivots = order
        .iter()
        .map(|&m| Pivots::read(&scene, m))
        .collect::<Result<Vec<_>>>()?;
    let rest = globals(
        &parents,
        &pivots.iter().map(|p| p.local(p.t, p.r, p.s)).collect::<Vec<_>>(),
    );
    let mut instances = Vec::new();
    for g in scene.of_kind("Geometry") {
        if scene.objects[&g].class != "Mesh" {
            continue;
        }
        for &(c, p, prop) in &scene.links {
            if c == g
                && prop.is_none()
                && let Some(&m) = index.get(&p)
            {
                instances.push(instance(&scene, g, (m, p, &rest[m]), &index)?);
            }
        }
    }
    if instances.iter().all(|i| i.positions.is_empty()) {
        return Err(scene.err("Geometry", "no mesh in the file"));
    }
    let (all, _) = takes(&scene, &index)?;
    let list: Vec<TakeInfo> = all.iter().map(|t| t.info.clone()).collect();
    let take = &all[skeletal::pick(path, &list, &opts.take)?];
    let info = take.info.clone();
    skeletal::check_frames(path, &info.name, info.frames, opts.max_frames)?;

    // Skin slots: one per instance (its model's transform times its geometric one), then one per cluster.
    let mut bind = Vec::new();
    let mut infl: Influences = Vec::new();
    let mut faces = Vec::new();
    let mut n_clusters = 0;
    for (s, inst) in instances.iter().enumerate() {
        let base = bind.len() as u32;
        let mut lists: Influences = vec![Vec::new(); inst.positions.len()];
        for (_, _, weights) in &inst.clusters {
            let slot = instances.len() + n_clusters;
            n_clusters += 1;
            weights.iter().for_each(|&(v, w)| lists[v].push((slot, w)));
        }
        for l in &mut lists {
            if l.iter().all(|&(_, w)| w == 0.0) {
                *l = vec![(s, 1.0)];
            }
        }
        bind.extend_from_slice(&inst.positions);
        infl.extend(lists);
        faces.extend(inst.faces.iter().map(|f| f.map(|i| i + base)));
    }
    let stats = clean_influences(path, "Cluster Weights", &mut infl, instances.len() + n_clusters)?;
    let (axes, mirror) = axes(&scene)?;

    skeletal::check_rows(path, info.frames, bind.len())?;
    let mut vertices = Vec::with_capacity(info.frames * bind.len());
    let mut skin = Vec::with_capacity(instances.len() + n_clusters);
    for f in 0..info.frames {
        let tick = take.start + (f as f64 * take.ticks_per_frame).round() as i64;
        let locals: Vec<Mat> = pivots
            .iter()
            .enumerate()
            .map(|(m, p)| {
                let ch = take.channels.get(&m);
                let at = |k: usize, rest: [f64; 3]| ch.and_then(|c| c[k].as_ref()).map_or(rest, |c| c.at(tick));
                p.local(at(0, p.t), at(1, p.r), at(2, p.s))
            })
            .collect();
        let g = globals(&parents, &locals);
        skin.clear();
        skin.extend(instances.iter().map(|i| mul(&g[i.model], &i.geo)));
        for inst in &instances {
            skin.extend(inst.clusters.iter().map(|(bone, offset, _)| mul(&g[*bone], offset)));
        }
        skin_frame(&bind, &infl, &skin, &mut vertices);
    }
    for v in &mut vertices {
        let p = v.map(f64::from);
        *v = std::array::from_fn(|r| (0..3).map(|c| axes[r][c] * p[c]).sum::<f64>() as f32);
    }
    if mirror {
        faces = faces.into_iter().map(|[a, b, c]| [a, c, b]).collect();
    }
    let clip = skeletal::baked_clip(path, vertices, info.frames, faces)?;
    Ok((clip, stats, info))
}

#[cfg(test)]
mod tests;
