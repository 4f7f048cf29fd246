//! The meshes a COLLADA scene instances: positions, polygons split into triangles, and skin weights.

use roxmltree::Node;

use super::{Doc, child, children};
use crate::error::Result;
use crate::skeletal::{IDENTITY, Mat};

/// One instanced mesh.
pub(super) struct Mesh {
    /// The scene node holding the instance.
    pub node: usize,
    pub positions: Vec<[f64; 3]>,
    pub faces: Vec<[u32; 3]>,
    /// The skin's joints (scene node index, inverse bind matrix); empty for a rigid mesh.
    pub joints: Vec<(usize, Mat)>,
    /// Per vertex `(index into joints, or None for the bind shape, weight)`; empty for a rigid mesh.
    pub weights: Weights,
    pub bind_shape: Mat,
}

/// Per vertex `(joint index, or None for the bind shape, weight)`.
type Weights = Vec<Vec<(Option<usize>, f64)>>;

/// Positions and triangles.
type Surface = (Vec<[f64; 3]>, Vec<[u32; 3]>);

/// A row-major 4×4 matrix from 16 values.
pub(super) fn matrix(v: &[f64]) -> Mat {
    std::array::from_fn(|r| std::array::from_fn(|c| v[r * 4 + c]))
}

pub(super) fn meshes(doc: &Doc) -> Result<Vec<Mesh>> {
    let mut out = Vec::new();
    for &(node, inst) in &doc.instances {
        let target = doc.url(inst, "url")?;
        if inst.tag_name().name() == "instance_geometry" {
            let (positions, faces) = mesh(doc, target)?;
            out.push(Mesh {
                node,
                positions,
                faces,
                joints: Vec::new(),
                weights: Vec::new(),
                bind_shape: IDENTITY,
            });
            continue;
        }
        let id = target.attribute("id").unwrap_or_default();
        let skin = child(target, "skin").ok_or_else(|| {
            doc.err(
                format!("controller {id:?}"),
                "not a skin (morph controllers are not read)",
            )
        })?;
        let (positions, faces) = mesh(doc, doc.url(skin, "source")?)?;
        let field = format!("controller {id:?}");
        let bind_shape = match child(skin, "bind_shape_matrix") {
            Some(b) => {
                let v = doc.numbers(b)?;
                if v.len() != 16 {
                    return Err(doc.err(field, format!("bind_shape_matrix has {} values", v.len())));
                }
                matrix(&v)
            }
            None => IDENTITY,
        };
        let joints_el = child(skin, "joints").ok_or_else(|| doc.err(&field, "no <joints>"))?;
        let (mut names, mut ibms) = (Vec::new(), Vec::new());
        for input in children(joints_el, "input") {
            let (floats, words, stride) = doc.source(doc.url(input, "source")?)?;
            match input.attribute("semantic") {
                Some("JOINT") => names = words,
                Some("INV_BIND_MATRIX") if stride == 16 && floats.len() % 16 == 0 => {
                    ibms = floats.chunks_exact(16).map(matrix).collect();
                }
                Some("INV_BIND_MATRIX") => {
                    return Err(doc.err(&field, "inverse bind matrices that are not 16 values each"));
                }
                _ => {}
            }
        }
        if names.len() != ibms.len() {
            return Err(doc.err(
                &field,
                format!("{} joints but {} inverse bind matrices", names.len(), ibms.len()),
            ));
        }
        let mut joints = Vec::with_capacity(names.len());
        for (name, ibm) in names.iter().zip(ibms) {
            let by = |key: usize| doc.nodes.iter().position(|n| [n.sid, n.id, n.name][key] == Some(*name));
            let j = by(0)
                .or_else(|| by(1))
                .or_else(|| by(2))
                .ok_or_else(|| doc.err(&field, format!("joint {name:?} is not a node of the scene")))?;
            joints.push((j, ibm));
        }
        let weights = vertex_weights(doc, skin, &field, positions.len(), joints.len())?;
        out.push(Mesh {
            node,
            positions,
            faces,
            joints,
            weights,
            bind_shape,
        });
    }
    Ok(out)
}

fn ints(doc: &Doc, node: Option<Node>) -> Result<Vec<i64>> {
    let Some(node) = node else { return Ok(Vec::new()) };
    node.text()
        .unwrap_or_default()
        .split_whitespace()
        .map(|t| {
            t.parse::<i64>().map_err(|_| {
                doc.err(
                    format!("<{}>", node.tag_name().name()),
                    format!("{t:?} is not a whole number"),
                )
            })
        })
        .collect()
}

fn vertex_weights(doc: &Doc, skin: Node, field: &str, n: usize, n_joints: usize) -> Result<Weights> {
    let vw = child(skin, "vertex_weights").ok_or_else(|| doc.err(field, "no <vertex_weights>"))?;
    let (mut joint_at, mut weight_at, mut stride, mut weights) = (None, None, 0, Vec::new());
    for input in children(vw, "input") {
        let offset: usize = input
            .attribute("offset")
            .and_then(|o| o.parse().ok())
            .filter(|&o| o < 16)
            .ok_or_else(|| doc.err(field, "a vertex_weights input without a small offset"))?;
        stride = stride.max(offset + 1);
        match input.attribute("semantic") {
            Some("JOINT") => joint_at = Some(offset),
            Some("WEIGHT") => {
                weight_at = Some(offset);
                weights = doc.source(doc.url(input, "source")?)?.0;
            }
            _ => {}
        }
    }
    let (Some(ja), Some(wa)) = (joint_at, weight_at) else {
        return Err(doc.err(field, "vertex_weights without JOINT and WEIGHT inputs"));
    };
    let vcount = ints(doc, child(vw, "vcount"))?;
    let v = ints(doc, child(vw, "v"))?;
    if vcount.len() != n {
        return Err(doc.err(
            field,
            format!("weights for {} vertices, the mesh has {n}", vcount.len()),
        ));
    }
    let mut out = Vec::with_capacity(n);
    let mut at = 0usize;
    for (vert, &k) in vcount.iter().enumerate() {
        let k = usize::try_from(k).map_err(|_| doc.err(field, format!("vertex {vert} has {k} weights")))?;
        let mut list = Vec::with_capacity(k.min(64));
        for _ in 0..k {
            let (Some(&j), Some(&w)) = (v.get(at + ja), v.get(at + wa)) else {
                return Err(doc.err(field, format!("<v> ends inside vertex {vert}'s weights")));
            };
            at += stride;
            let joint = match j {
                -1 => None,
                j if (0..n_joints as i64).contains(&j) => Some(j as usize),
                j => return Err(doc.err(field, format!("vertex {vert} names joint {j} of {n_joints}"))),
            };
            let w = usize::try_from(w)
                .ok()
                .and_then(|w| weights.get(w))
                .ok_or_else(|| doc.err(field, format!("vertex {vert} names weight {w} of {}", weights.len())))?;
            list.push((joint, *w));
        }
        out.push(list);
    }
    Ok(out)
}

/// Positions and triangles of a `<geometry>`'s `<mesh>`.
fn mesh(doc: &Doc, geometry: Node) -> Result<Surface> {
    let gid = geometry.attribute("id").unwrap_or_default();
    let field = format!("geometry {gid:?}");
    let Some(mesh) = child(geometry, "mesh") else {
        return Err(doc.err(field, "not a <mesh> (splines and B-reps are not read)"));
    };
    let vertices = child(mesh, "vertices").ok_or_else(|| doc.err(&field, "no <vertices>"))?;
    let position = children(vertices, "input")
        .find(|i| i.attribute("semantic") == Some("POSITION"))
        .ok_or_else(|| doc.err(&field, "no POSITION input"))?;
    let (values, _, stride) = doc.source(doc.url(position, "source")?)?;
    if stride < 3 || values.len() % stride != 0 {
        return Err(doc.err(&field, format!("{} position values with stride {stride}", values.len())));
    }
    let positions: Vec<[f64; 3]> = values.chunks_exact(stride).map(|c| [c[0], c[1], c[2]]).collect();
    let n = positions.len();
    let mut faces = Vec::new();
    for prim in mesh.children().filter(Node::is_element) {
        let kind = prim.tag_name().name();
        if !matches!(kind, "triangles" | "polylist" | "polygons" | "tristrips" | "trifans") {
            continue;
        }
        let pf = format!("{field} <{kind}>");
        let mut stride = 0;
        let mut vertex_at = None;
        for input in children(prim, "input") {
            let offset: usize = input
                .attribute("offset")
                .and_then(|o| o.parse().ok())
                .filter(|&o| o < 64)
                .ok_or_else(|| doc.err(&pf, "an input without a small offset"))?;
            stride = stride.max(offset + 1);
            if input.attribute("semantic") == Some("VERTEX") {
                vertex_at = Some(offset);
            }
        }
        let at = vertex_at.ok_or_else(|| doc.err(&pf, "no VERTEX input"))?;
        let corners = |p: Node| -> Result<Vec<u32>> {
            let raw = ints(doc, Some(p))?;
            if raw.len() % stride != 0 {
                return Err(doc.err(&pf, format!("<p> of {} indices, not a multiple of {stride}", raw.len())));
            }
            raw.chunks_exact(stride)
                .map(|c| {
                    u32::try_from(c[at])
                        .ok()
                        .filter(|&i| (i as usize) < n)
                        .ok_or_else(|| doc.err(&pf, format!("vertex {} of {n}", c[at])))
                })
                .collect()
        };
        let fan = |c: &[u32], faces: &mut Vec<[u32; 3]>| {
            faces.extend((1..c.len().saturating_sub(1)).map(|k| [c[0], c[k], c[k + 1]]));
        };
        match kind {
            "triangles" => {
                let c = corners(child(prim, "p").ok_or_else(|| doc.err(&pf, "no <p>"))?)?;
                faces.extend(c.chunks_exact(3).map(|t| [t[0], t[1], t[2]]));
            }
            "polylist" => {
                let c = match child(prim, "p") {
                    Some(p) => corners(p)?,
                    None => Vec::new(),
                };
                let mut start = 0usize;
                for k in ints(doc, child(prim, "vcount"))? {
                    let end = usize::try_from(k)
                        .ok()
                        .and_then(|k| start.checked_add(k))
                        .filter(|&e| e <= c.len())
                        .ok_or_else(|| doc.err(&pf, format!("<vcount> runs past the {} corners of <p>", c.len())))?;
                    fan(&c[start..end], &mut faces);
                    start = end;
                }
            }
            "polygons" | "trifans" => {
                for p in children(prim, "p").chain(children(prim, "ph").filter_map(|ph| child(ph, "p"))) {
                    fan(&corners(p)?, &mut faces);
                }
            }
            _ => {
                for p in children(prim, "p") {
                    let c = corners(p)?;
                    for k in 0..c.len().saturating_sub(2) {
                        faces.push(if k % 2 == 0 {
                            [c[k], c[k + 1], c[k + 2]]
                        } else {
                            [c[k + 1], c[k], c[k + 2]]
                        });
                    }
                }
            }
        }
    }
    Ok((positions, faces))
}
