//! Contact sheets of clips: a z-buffered triangle rasteriser with flat Lambert shading and
//! a fixed orthographic camera framed on all frames, so that motion shows as movement between tiles; a clip's static
//! scene, when it has one, drawn in grey around it with the same depth test.

use std::path::Path;

use image::{ImageFormat, Rgb, RgbImage};

use crate::clip::Clip;
use crate::error::{DataError, Result};
use crate::scene::Scene;

type V3 = [f32; 3];

/// Fixed camera directions (orthographic; y is up, +z faces the viewer in the default view).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Camera {
    /// A 3/4 view from the front-right-top: azimuth 30° to the right of +z, elevation 25°.
    #[default]
    FrontRightTop,
    /// From +z, slightly above.
    Front,
    /// From +x, slightly above.
    Right,
    /// From above (+y); screen up is −z.
    Top,
}

impl Camera {
    /// Unit direction from the scene towards the camera.
    fn toward(self) -> V3 {
        let (az, el) = match self {
            Camera::FrontRightTop => (30f32, 25f32),
            Camera::Front => (0.0, 10.0),
            Camera::Right => (90.0, 10.0),
            Camera::Top => (0.0, 90.0),
        };
        let (az, el) = (az.to_radians(), el.to_radians());
        [az.sin() * el.cos(), el.sin(), az.cos() * el.cos()]
    }
}

/// Whether tiles carry their frame number.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FrameLabels {
    /// Frame index (zero-based) in a 3×5 pixel font, top-left.
    #[default]
    Number,
    None,
}

/// Whether a ground shadow is drawn under the mesh.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Ground {
    /// The mesh flattened onto the lowest height reached in the clip, in grey: shows jumps and travel.
    #[default]
    Shadow,
    None,
}

/// How triangles are coloured.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Shading {
    Lambert([u8; 3]),
    Flat([u8; 3]),
}

/// Settings of [`contact_sheet`].
#[derive(Debug, Clone, PartialEq)]
pub struct RenderOptions {
    /// Side of one square tile in pixels.
    pub width_per_frame: u32,
    /// Tiles per row.
    pub columns: usize,
    pub camera: Camera,
    pub labels: FrameLabels,
    pub ground: Ground,
    /// Surface colour at full light.
    pub color: [u8; 3],
    pub background: [u8; 3],
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            width_per_frame: 160,
            columns: 8,
            camera: Camera::FrontRightTop,
            labels: FrameLabels::Number,
            ground: Ground::Shadow,
            color: [235, 160, 90],
            background: [250, 250, 250],
        }
    }
}

/// An orthographic view: screen axes `right`, `up`, depth along `toward`, and the framed square
/// (centre and half side in scene units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    pub right: V3,
    pub up: V3,
    pub toward: V3,
    pub center: [f32; 2],
    pub half: f32,
}

impl View {
    /// A view from `camera` framing every finite point of `points` (8 % margin). No finite point: unit square.
    pub fn fit(points: &[V3], camera: Camera) -> Self {
        let toward = camera.toward();
        let helper = if toward[1].abs() > 0.99 {
            [0.0, 0.0, -1.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let right = unit(cross(helper, toward));
        let up = cross(toward, right);
        let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
        for p in points.iter().filter(|p| p.iter().all(|c| c.is_finite())) {
            let s = [dot(*p, right), dot(*p, up)];
            for k in 0..2 {
                lo[k] = lo[k].min(s[k]);
                hi[k] = hi[k].max(s[k]);
            }
        }
        if lo[0] > hi[0] {
            return Self {
                right,
                up,
                toward,
                center: [0.0; 2],
                half: 1.0,
            };
        }
        let half = ((hi[0] - lo[0]).max(hi[1] - lo[1]) / 2.0 * 1.08).max(1e-6);
        Self {
            right,
            up,
            toward,
            center: [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0],
            half,
        }
    }
}

/// Render one frame into a `size × size` image, white background, default colour.
///
/// Triangles with a non-finite corner are skipped (a broken prediction shows holes, not a crash). Errors (path
/// "render", field "faces") if a face indexes past `vertices`.
///
/// # Shapes
/// - `vertices`: `[N]` rows of xyz; `faces`: `[M]` triangles
pub fn rasterize_frame(vertices: &[V3], faces: &[[u32; 3]], view: &View, size: u32) -> Result<RgbImage> {
    let opts = RenderOptions {
        background: [255, 255, 255],
        ..RenderOptions::default()
    };
    let mut img = RgbImage::from_pixel(size, size, Rgb(opts.background));
    let part = Part {
        vertices,
        faces,
        shading: Shading::Lambert(opts.color),
    };
    draw_frame(&mut img, (0, 0), size, &[part], view)?;
    Ok(img)
}

/// A grid of all frames of `clip` (row-major, `opts.columns` per row), framed on the bounding box of all frames.
/// Errors if the clip is invalid ([`Clip::validate`]).
pub fn contact_sheet(clip: &Clip, opts: &RenderOptions) -> Result<RgbImage> {
    contact_sheet_in(clip, None, opts)
}

/// [`contact_sheet`] with `scene` (in the clip's coordinates) drawn in grey in every tile, then the clip over it: a
/// wall or ceiling between the camera and the clip never hides it (the viewer's pages show true occlusion). The
/// framing stays the clip's, and the scene's floor replaces the ground shadow.
pub fn contact_sheet_in(clip: &Clip, scene: Option<&Scene>, opts: &RenderOptions) -> Result<RgbImage> {
    clip.validate()?;
    let w = opts.width_per_frame.max(8);
    let cols = opts.columns.clamp(1, clip.frames);
    let rows = clip.frames.div_ceil(cols);
    let mut img = RgbImage::from_pixel(w * cols as u32, w * rows as u32, Rgb(opts.background));
    let view = View::fit(&clip.vertices, opts.camera);
    let ground = clip
        .vertices
        .iter()
        .map(|p| p[1])
        .filter(|y| y.is_finite())
        .fold(f32::INFINITY, f32::min);
    for f in 0..clip.frames {
        let origin = ((f % cols) as u32 * w, (f / cols) as u32 * w);
        if opts.ground == Ground::Shadow && scene.is_none() {
            let flat: Vec<V3> = clip.frame(f).iter().map(|p| [p[0], ground, p[2]]).collect();
            let shadow = Part {
                vertices: &flat,
                faces: &clip.faces,
                shading: Shading::Flat([215, 215, 215]),
            };
            draw_frame(&mut img, origin, w, &[shadow], &view).map_err(|e| e.at(&clip.source))?;
        }
        if let Some(scene) = scene {
            let part = Part {
                vertices: &scene.vertices,
                faces: &scene.faces,
                shading: Shading::Lambert(SCENE_COLOUR),
            };
            draw_frame(&mut img, origin, w, &[part], &view)?;
        }
        let part = Part {
            vertices: clip.frame(f),
            faces: &clip.faces,
            shading: Shading::Lambert(opts.color),
        };
        draw_frame(&mut img, origin, w, &[part], &view).map_err(|e| e.at(&clip.source))?;
        // Tile border.
        for i in 0..w {
            for (x, y) in [(i, 0), (0, i), (i, w - 1), (w - 1, i)] {
                img.put_pixel(origin.0 + x, origin.1 + y, Rgb([200, 200, 200]));
            }
        }
        if opts.labels == FrameLabels::Number {
            draw_number(&mut img, origin.0 + 3, origin.1 + 3, f, (w / 80).max(1));
        }
    }
    Ok(img)
}

/// Render [`contact_sheet_in`] and write it as PNG to `path`; errors name the path.
pub fn render_contact_sheet(
    clip: &Clip,
    scene: Option<&Scene>,
    path: impl AsRef<Path>,
    opts: &RenderOptions,
) -> Result<()> {
    let path = path.as_ref();
    let img = contact_sheet_in(clip, scene, opts)?;
    img.save_with_format(path, ImageFormat::Png)
        .map_err(|e| DataError::new(path, "png", e.to_string()))
}

/// Grey of a scene's surfaces at full light.
const SCENE_COLOUR: [u8; 3] = [175, 178, 185];

/// One triangle mesh of a tile and how it is shaded.
struct Part<'a> {
    vertices: &'a [V3],
    faces: &'a [[u32; 3]],
    shading: Shading,
}

/// Z-buffered flat-Lambert rasterisation of `parts` (one depth buffer for all) into the `size`-pixel square tile at
/// `origin`, over what the tile already shows.
fn draw_frame(img: &mut RgbImage, origin: (u32, u32), size: u32, parts: &[Part<'_>], view: &View) -> Result<()> {
    for Part { vertices, faces, .. } in parts {
        if let Some((i, f)) = faces
            .iter()
            .enumerate()
            .find(|(_, f)| f.iter().any(|&v| v as usize >= vertices.len()))
        {
            return Err(DataError::new(
                "render",
                "faces",
                format!("face {i} = {f:?} indexes past the {} vertices", vertices.len()),
            ));
        }
    }
    let light = unit([
        view.toward[0] + 0.6 * view.up[0] - 0.4 * view.right[0],
        view.toward[1] + 0.6 * view.up[1] - 0.4 * view.right[1],
        view.toward[2] + 0.6 * view.up[2] - 0.4 * view.right[2],
    ]);
    let px = size as f32 / 2.0;
    let project = |p: V3| {
        let sx = (dot(p, view.right) - view.center[0]) / view.half;
        let sy = (dot(p, view.up) - view.center[1]) / view.half;
        [px + sx * px, px - sy * px, dot(p, view.toward)]
    };
    let mut depth = vec![f32::NEG_INFINITY; (size * size) as usize];
    for &Part {
        vertices,
        faces,
        shading,
    } in parts
    {
        let screen: Vec<V3> = vertices.iter().map(|&p| project(p)).collect();
        for f in faces {
            let (a, b, c) = (screen[f[0] as usize], screen[f[1] as usize], screen[f[2] as usize]);
            if !a.iter().chain(&b).chain(&c).all(|v| v.is_finite()) {
                continue;
            }
            let area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
            if area.abs() < 1e-9 {
                continue;
            }
            let (wa, wb, wc) = (
                vertices[f[0] as usize],
                vertices[f[1] as usize],
                vertices[f[2] as usize],
            );
            let n = unit(cross(sub(wb, wa), sub(wc, wa)));
            let rgb = match shading {
                // Two-sided Lambert plus ambient.
                Shading::Lambert(color) => {
                    let shade = 0.28 + 0.72 * dot(n, light).abs();
                    Rgb(color.map(|ch| (ch as f32 * shade).round().clamp(0.0, 255.0) as u8))
                }
                Shading::Flat(color) => Rgb(color),
            };
            let x0 = a[0].min(b[0]).min(c[0]).floor().max(0.0) as u32;
            let x1 = (a[0].max(b[0]).max(c[0]).ceil().min(size as f32 - 1.0)).max(-1.0) as i64;
            let y0 = a[1].min(b[1]).min(c[1]).floor().max(0.0) as u32;
            let y1 = (a[1].max(b[1]).max(c[1]).ceil().min(size as f32 - 1.0)).max(-1.0) as i64;
            for y in y0 as i64..=y1 {
                for x in x0 as i64..=x1 {
                    let (qx, qy) = (x as f32 + 0.5, y as f32 + 0.5);
                    let edge = |p: V3, q: V3| ((q[0] - p[0]) * (qy - p[1]) - (q[1] - p[1]) * (qx - p[0])) / area;
                    let (l0, l1, l2) = (edge(b, c), edge(c, a), edge(a, b));
                    if l0 < 0.0 || l1 < 0.0 || l2 < 0.0 {
                        continue;
                    }
                    let z = l0 * a[2] + l1 * b[2] + l2 * c[2];
                    let k = (y as u32 * size + x as u32) as usize;
                    if z > depth[k] {
                        depth[k] = z;
                        img.put_pixel(origin.0 + x as u32, origin.1 + y as u32, rgb);
                    }
                }
            }
        }
    }
    Ok(())
}

/// 3×5 digit glyphs, one bit per pixel, rows top to bottom, 3 bits per row (MSB left).
const DIGITS: [[u8; 5]; 10] = [
    [7, 5, 5, 5, 7],
    [2, 6, 2, 2, 7],
    [7, 1, 7, 4, 7],
    [7, 1, 7, 1, 7],
    [5, 5, 7, 1, 1],
    [7, 4, 7, 1, 7],
    [7, 4, 7, 5, 7],
    [7, 1, 1, 1, 1],
    [7, 5, 7, 5, 7],
    [7, 5, 7, 1, 7],
];

fn draw_number(img: &mut RgbImage, x: u32, y: u32, value: usize, scale: u32) {
    for (i, ch) in value.to_string().bytes().enumerate() {
        let glyph = DIGITS[(ch - b'0') as usize];
        for (row, bits) in glyph.iter().enumerate() {
            for col in 0..3u32 {
                if bits >> (2 - col) & 1 == 1 {
                    for dy in 0..scale {
                        for dx in 0..scale {
                            let (px, py) = (x + (i as u32 * 4 + col) * scale + dx, y + row as u32 * scale + dy);
                            if px < img.width() && py < img.height() {
                                img.put_pixel(px, py, Rgb([40, 40, 40]));
                            }
                        }
                    }
                }
            }
        }
    }
}

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: V3, b: V3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn unit(a: V3) -> V3 {
    let n = dot(a, a).sqrt().max(1e-12);
    [a[0] / n, a[1] / n, a[2] / n]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad_clip() -> Clip {
        // A unit square moving right by 1 between two frames.
        let sq = |dx: f32| {
            vec![
                [dx, 0.0, 0.0],
                [dx + 1.0, 0.0, 0.0],
                [dx + 1.0, 1.0, 0.0],
                [dx, 1.0, 0.0],
            ]
        };
        let v = [sq(0.0), sq(1.0)].concat();
        Clip::new("q", v, 2, 4, vec![[0, 1, 2], [0, 2, 3]], "", "q.bin").unwrap()
    }

    #[test]
    fn contact_sheet_has_the_grid_size_and_is_not_blank() {
        let clip = quad_clip();
        let opts = RenderOptions {
            width_per_frame: 64,
            columns: 8,
            ..RenderOptions::default()
        };
        let img = contact_sheet(&clip, &opts).unwrap();
        assert_eq!(
            img.dimensions(),
            (128, 64),
            "two frames, columns clamp to the frame count"
        );
        let bg = Rgb(opts.background);
        let painted = |x0: u32| (x0 + 1..x0 + 63).flat_map(|x| (1..63).map(move |y| (x, y)));
        let count = |x0: u32| painted(x0).filter(|&(x, y)| img.get_pixel(x, y) != &bg).count();
        assert!(count(0) > 100 && count(64) > 100, "{} {}", count(0), count(64));
        // Framing covers both frames: the square sits left in tile 0 and right in tile 1.
        let mean_x = |x0: u32| {
            let px: Vec<u32> = painted(x0)
                .filter(|&(x, y)| y > 15 && img.get_pixel(x, y) != &bg && img.get_pixel(x, y).0[0] > 100)
                .map(|(x, _)| x - x0)
                .collect();
            px.iter().sum::<u32>() as f32 / px.len() as f32
        };
        assert!(mean_x(0) + 10.0 < mean_x(64), "{} vs {}", mean_x(0), mean_x(64));
    }

    #[test]
    fn rasterizer_depth_test_keeps_the_nearer_triangle() {
        // Two overlapping squares facing the front camera; the nearer one (z = 1) is drawn first, then the far one.
        let v = vec![
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 1.0],
            [0.0, 1.0, 0.0],
        ];
        // The far square is tilted so it shades differently from the near one.
        let mut v2 = v.clone();
        v2[5][2] = -0.5;
        let view = View::fit(&v2, Camera::Front);
        let near_only = rasterize_frame(&v2, &[[0, 1, 2]], &view, 32).unwrap();
        let both = rasterize_frame(&v2, &[[0, 1, 2], [3, 4, 5]], &view, 32).unwrap();
        let centre_of_near = (20, 20);
        assert_eq!(
            near_only.get_pixel(centre_of_near.0, centre_of_near.1),
            both.get_pixel(20, 20)
        );
        assert_ne!(both.get_pixel(20, 20), &Rgb([255, 255, 255]));
        let e = rasterize_frame(&v, &[[0, 1, 8]], &view, 32).unwrap_err();
        assert_eq!(e.field, "faces");
    }

    #[test]
    fn a_scene_is_drawn_around_the_clip_and_never_over_it() {
        // A wall behind the moving square (z = −1) and one in front of it (z = 2), larger than the framed region:
        // every tile's background turns grey, while the square keeps its colour over both.
        let clip = quad_clip();
        let wall = Scene::new(
            vec![
                [-5.0, -5.0, -1.0],
                [5.0, -5.0, -1.0],
                [5.0, 5.0, -1.0],
                [-5.0, 5.0, -1.0],
                [-5.0, -5.0, 2.0],
                [5.0, -5.0, 2.0],
                [5.0, 5.0, 2.0],
            ],
            vec![[0, 1, 2], [0, 2, 3], [4, 5, 6]],
            Path::new("wall.obj"),
        )
        .unwrap();
        let opts = RenderOptions {
            width_per_frame: 64,
            camera: Camera::Front,
            labels: FrameLabels::None,
            ..RenderOptions::default()
        };
        let bare = contact_sheet(&clip, &opts).unwrap();
        let walled = contact_sheet_in(&clip, Some(&wall), &opts).unwrap();
        let bg = Rgb(opts.background);
        let corner = (5, 60);
        assert_eq!(bare.get_pixel(corner.0, corner.1), &bg);
        let grey = walled.get_pixel(corner.0, corner.1);
        assert!(
            grey != &bg && grey.0[0].abs_diff(grey.0[2]) < 30,
            "scene grey, got {grey:?}"
        );
        // The square's pixels (orange, red well above blue) are the same with the wall behind it.
        let orange = |img: &RgbImage| {
            img.enumerate_pixels()
                .filter(|(_, _, p)| u16::from(p.0[0]) > u16::from(p.0[2]) + 60)
                .map(|(x, y, _)| (x, y))
                .collect::<Vec<_>>()
        };
        assert!(!orange(&bare).is_empty());
        assert_eq!(orange(&bare), orange(&walled), "the square is drawn over its scene");
        let broken = Scene {
            vertices: vec![[0.0; 3]; 3],
            faces: vec![[0, 1, 7]],
        };
        assert_eq!(
            contact_sheet_in(&clip, Some(&broken), &opts).unwrap_err().field,
            "faces"
        );
    }

    #[test]
    fn png_is_written_and_bad_path_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sheet.png");
        render_contact_sheet(&quad_clip(), None, &path, &RenderOptions::default()).unwrap();
        let back = image::open(&path).unwrap();
        assert_eq!((back.width(), back.height()), (320, 160));
        let bad = dir.path().join("missing").join("x.png");
        let e = render_contact_sheet(&quad_clip(), None, &bad, &RenderOptions::default()).unwrap_err();
        assert!(e.path.contains("missing"), "{e}");
    }
}
