//! The static scene of a glTF file (docs/method.md §6.5): the meshes that stand still around the animated one.
//!
//! A node's meshes belong to the scene when no animation channel targets the node or one of its ancestors, the node
//! has no skin and is not the clip's mesh node (the first node with a mesh, as [`super::read`] takes it). Every
//! triangle primitive of such a mesh is placed by the node's rest world matrix, with faces in range and at most
//! [`MAX_SCENE_TRIANGLES`] triangles; the data crate's scene type checks the rest.

use std::path::Path;

use gltf::json::accessor::Type;
use gltf::json::mesh::{Mode, Semantic};
use gltf::json::validation::Checked;

use super::StillMeshes;
use super::accessor::{FLOAT, INDICES};
use super::bake::{IDENTITY, Mat, apply, mul};
use super::read::{Reader, rows3};
use super::source;
use super::{Ctx, ExternalBuffers};
use crate::error::Result;
use crate::limits::MAX_SCENE_TRIANGLES;

/// The still meshes of the file in `bytes` as one scene; `None` when there are none.
pub(super) fn static_scene(bytes: &[u8], path: &Path, external: &ExternalBuffers) -> Result<Option<StillMeshes>> {
    let ctx = Ctx { path };
    let doc = source::load(ctx, bytes, external)?;
    let (r, root) = (Reader::of(ctx, &doc), &doc.root);
    let nodes = r.hierarchy()?;
    let mut moved = vec![false; nodes.len()];
    for anim in &root.animations {
        for ch in &anim.channels {
            if let Some(m) = moved.get_mut(ch.target.node.value()) {
                *m = true;
            }
        }
    }
    // A node moves with any moved ancestor; world matrices at rest along the (checked) forest.
    let chain = |i: usize| {
        let mut c = vec![i];
        while let Some(p) = nodes[*c.last().expect("non-empty")].parent {
            c.push(p);
        }
        c
    };
    let clip_node = root.nodes.iter().position(|n| n.mesh.is_some());
    let (mut vertices, mut faces) = (Vec::new(), Vec::new());
    for (i, node) in root.nodes.iter().enumerate() {
        let Some(mesh_index) = node.mesh.map(|m| m.value()) else {
            continue;
        };
        let up = chain(i);
        if Some(i) == clip_node || node.skin.is_some() || up.iter().any(|&k| moved[k]) {
            continue;
        }
        let world: Mat = up.iter().rev().fold(IDENTITY, |m, &k| mul(&m, &nodes[k].matrix));
        let field = format!("meshes[{mesh_index}]");
        let Some(mesh) = root.meshes.get(mesh_index) else {
            return Err(ctx.err(format!("nodes[{i}].mesh"), format!("mesh {mesh_index} does not exist")));
        };
        for prim in mesh
            .primitives
            .iter()
            .filter(|p| p.mode == Checked::Valid(Mode::Triangles))
        {
            let Some(position) = prim.attributes.get(&Checked::Valid(Semantic::Positions)) else {
                continue;
            };
            let points = rows3(&r.floats(position.value(), &format!("{field} POSITION"), Type::Vec3, FLOAT)?);
            let n = points.len();
            let indices = match prim.indices {
                Some(k) => r.u32s(k.value(), &format!("{field} indices"), Type::Scalar, INDICES)?,
                None => (0..n as u32).collect(),
            };
            if faces.len() + indices.len() / 3 > MAX_SCENE_TRIANGLES {
                return Err(ctx.err(
                    &field,
                    format!("the still meshes have more than the {MAX_SCENE_TRIANGLES} triangles a scene may have"),
                ));
            }
            let base = vertices.len() as u32;
            vertices.extend(points.iter().map(|&p| apply(&world, p).map(|x| x as f32)));
            for t in indices.chunks_exact(3) {
                if let Some(&bad) = t.iter().find(|&&v| v as usize >= n) {
                    return Err(ctx.err(format!("{field} indices"), format!("vertex {bad} of {n}")));
                }
                faces.push([base + t[0], base + t[1], base + t[2]]);
            }
        }
    }
    if faces.is_empty() {
        return Ok(None);
    }
    Ok(Some(StillMeshes { vertices, faces }))
}
