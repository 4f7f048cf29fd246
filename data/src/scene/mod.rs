//! The static scene a clip moves in (docs/method.md §6.5): a triangle mesh in the clip's coordinates, made of closed
//! (watertight) parts — a floor is a slab, a wall a box — so that inside and outside are defined everywhere.
//!
//! [`Scene::new`] checks what a file could get wrong before anything uses it: at least one triangle, finite
//! coordinates, faces that index real vertices, and at most [`MAX_SCENE_TRIANGLES`] triangles (every metric visits
//! every triangle for every vertex of a clip).

use std::path::Path;

use crate::error::{DataError, Result};

pub mod features;
pub mod geometry;

pub use crate::limits::MAX_SCENE_TRIANGLES;

pub use crate::formats::obj::{SCENE_SUFFIX, is_scene_file};

/// The scene file beside the import source `source` (a file or an OBJ folder), when there is one inside its folder.
pub fn scene_beside(source: &Path) -> Option<std::path::PathBuf> {
    let name = source.file_name()?.to_string_lossy().into_owned();
    let stem = match source.is_dir() {
        true => name,
        false => name.split('.').next().unwrap_or_default().to_owned(),
    };
    let dir = source
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let path = dir.join(format!("{stem}{SCENE_SUFFIX}"));
    crate::formats::skeletal::sidecar_inside(dir, &path).then_some(path)
}

/// A static triangle mesh in a clip's coordinates.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    pub vertices: Vec<[f32; 3]>,
    pub faces: Vec<[u32; 3]>,
}

impl Scene {
    /// A scene of `vertices` and `faces` read from `source` (named in errors).
    pub fn new(vertices: Vec<[f32; 3]>, faces: Vec<[u32; 3]>, source: &Path) -> Result<Self> {
        let err = |field: &str, reason: String| Err(DataError::new(source, field, reason));
        if faces.is_empty() {
            return err("faces", "a scene needs at least one triangle".into());
        }
        if faces.len() > MAX_SCENE_TRIANGLES {
            return err(
                "faces",
                format!(
                    "{} triangles, more than the {MAX_SCENE_TRIANGLES} a scene may have",
                    faces.len()
                ),
            );
        }
        if let Some((v, p)) = vertices
            .iter()
            .enumerate()
            .find(|(_, p)| !p.iter().all(|c| c.is_finite()))
        {
            return err("vertices", format!("vertex {v} has a non-finite coordinate {p:?}"));
        }
        if let Some((i, f)) = faces
            .iter()
            .enumerate()
            .find(|(_, f)| f.iter().any(|&v| v as usize >= vertices.len()))
        {
            return err(
                "faces",
                format!("face {i} = {f:?} indexes past the {} vertices", vertices.len()),
            );
        }
        Ok(Scene { vertices, faces })
    }

    /// The scene of a `.gltf` / `.glb`: its still meshes ([`crate::formats::gltf::static_scene`]) checked as any
    /// scene; `None` when it has none.
    pub fn read_gltf(path: &Path) -> Result<Option<Self>> {
        crate::formats::gltf::static_scene(path)?
            .map(|m| Scene::new(m.vertices, m.faces, path))
            .transpose()
    }

    /// A scene from one `.obj` file (its `v` and `f` lines; polygons are split into fans).
    pub fn read_obj(path: &Path) -> Result<Self> {
        let text = crate::formats::read_text_file(path, crate::limits::FILE_BYTES.get())?;
        let (vertices, faces) = crate::formats::obj::parse_obj(&text, path)?;
        Scene::new(vertices, faces, path)
    }

    /// An axis-aligned box from `lo` to `hi` (12 triangles, wound outwards), as a closed scene part.
    pub fn cuboid(lo: [f32; 3], hi: [f32; 3]) -> Self {
        let corner = |i: usize| [[lo, hi][i & 1][0], [lo, hi][(i >> 1) & 1][1], [lo, hi][(i >> 2) & 1][2]];
        let vertices = (0..8).map(corner).collect();
        // Corner i has x from bit 0, y from bit 1, z from bit 2; each face's two triangles wind outwards.
        let faces = vec![
            [0, 2, 3],
            [0, 3, 1], // z = lo
            [4, 5, 7],
            [4, 7, 6], // z = hi
            [0, 1, 5],
            [0, 5, 4], // y = lo
            [2, 6, 7],
            [2, 7, 3], // y = hi
            [0, 4, 6],
            [0, 6, 2], // x = lo
            [1, 3, 7],
            [1, 7, 5], // x = hi
        ];
        Scene { vertices, faces }
    }

    /// The scene in a window's normalised frame (D1)–(D3) (`(x − c) / s`), or `None` when that is not finite.
    pub fn normalized(&self, n: &crate::preprocess::Normalization) -> Option<Scene> {
        let mut vertices = self.vertices.clone();
        n.apply_points(&mut vertices);
        vertices.iter().flatten().all(|x| x.is_finite()).then(|| Scene {
            vertices,
            faces: self.faces.clone(),
        })
    }

    /// Whether the scene's bounding box and that of every frame of `clip` overlap (a scene that does not is most
    /// likely in other coordinates or units than the clip: callers warn).
    pub fn overlaps(&self, clip: &crate::clip::Clip) -> bool {
        use crate::preprocess::bounds;
        let ((a0, a1), (b0, b1)) = (bounds(&self.vertices), bounds(&clip.vertices));
        (0..3).all(|k| a0[k] <= b1[k] && b0[k] <= a1[k])
    }

    /// This scene and `other` as one (their parts side by side).
    pub fn with(mut self, other: &Scene) -> Self {
        let base = self.vertices.len() as u32;
        self.vertices.extend_from_slice(&other.vertices);
        self.faces.extend(other.faces.iter().map(|f| f.map(|v| v + base)));
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn broken_scenes_are_refused_naming_the_field() {
        let p = Path::new("scene.obj");
        let tri = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        assert_eq!(Scene::new(tri.clone(), vec![], p).unwrap_err().field, "faces");
        let mut bad = tri.clone();
        bad[1][2] = f32::NAN;
        assert_eq!(Scene::new(bad, vec![[0, 1, 2]], p).unwrap_err().field, "vertices");
        assert!(
            Scene::new(tri.clone(), vec![[0, 1, 3]], p)
                .unwrap_err()
                .reason
                .contains("indexes past")
        );
        let clip = crate::clip::Clip::new("c", vec![[0.5, 0.5, 0.0]; 6], 2, 3, vec![[0, 1, 2]], "", "t").unwrap();
        let floor = Scene::new(tri.clone(), vec![[0, 1, 2]], p).unwrap();
        assert!(floor.overlaps(&clip));
        let far = Scene::cuboid([10.0, 10.0, 10.0], [11.0, 11.0, 11.0]);
        assert!(!far.overlaps(&clip));
        let many = vec![[0, 1, 2]; MAX_SCENE_TRIANGLES + 1];
        assert!(Scene::new(tri, many, p).unwrap_err().reason.contains("more than"));
        let dir = tempfile::tempdir().unwrap();
        let obj = dir.path().join("s.obj");
        std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        assert_eq!(Scene::read_obj(&obj).unwrap().faces, [[0, 1, 2]]);
        std::fs::write(&obj, "v 0 0 0\n").unwrap();
        assert_eq!(Scene::read_obj(&obj).unwrap_err().field, "faces");
    }
}
