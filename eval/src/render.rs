//! Result pictures (SPEC §6): a PNG strip per clip with the ground truth above and the prediction below, one column
//! per frame, keyframe columns framed and labelled. Meshes are drawn as orthographic wireframes from a fixed
//! three-quarter view, all frames at one scale so motion is visible.

use std::path::Path;

use any4d_data::{Clip, DataError};

use crate::plot::{BLACK, Canvas, WHITE, text_width};

type Result<T, E = DataError> = std::result::Result<T, E>;

/// Keyframe frame colour (orange) and wireframe colours.
const KEY_COLOUR: [u8; 3] = [230, 120, 0];
const GT_COLOUR: [u8; 3] = [60, 60, 60];
const PRED_COLOUR: [u8; 3] = [0, 90, 170];

/// Layout of a strip.
#[derive(Debug, Clone, PartialEq)]
pub struct StripOptions {
    /// Pixel size of one frame cell.
    pub cell: u32,
    /// Width of the label column on the left.
    pub label_width: u32,
    /// Draw at most this many triangle edges per frame (evenly subsampled faces) to keep dense meshes legible.
    pub max_faces: usize,
    /// Label of the prediction row.
    pub prediction_label: String,
}

impl Default for StripOptions {
    fn default() -> Self {
        Self {
            cell: 96,
            label_width: 56,
            max_faces: 1500,
            prediction_label: "PRED".into(),
        }
    }
}

/// Rotate into the fixed view: 30° about the vertical (y) axis, then 20° tilt about x; returns screen (u, v).
fn view(p: [f32; 3]) -> [f32; 2] {
    let (sa, ca) = (30f32.to_radians().sin(), 30f32.to_radians().cos());
    let (sb, cb) = (20f32.to_radians().sin(), 20f32.to_radians().cos());
    let x = ca * p[0] + sa * p[2];
    let z = -sa * p[0] + ca * p[2];
    let y = cb * p[1] - sb * z;
    [x, y]
}

/// Screen bounds of every frame of several sequences: (min u, min v, extent).
fn bounds(seqs: &[&Clip]) -> ([f32; 2], f32) {
    let mut lo = [f32::INFINITY; 2];
    let mut hi = [f32::NEG_INFINITY; 2];
    for c in seqs {
        for p in &c.vertices {
            let s = view(*p);
            for k in 0..2 {
                lo[k] = lo[k].min(s[k]);
                hi[k] = hi[k].max(s[k]);
            }
        }
    }
    let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-6);
    (lo, extent)
}

/// Where and how one frame is drawn: the square cell at (x, y) of side `size`, the shared screen bounds, the
/// wireframe colour and the face budget.
struct Cell {
    x: i64,
    y: i64,
    size: u32,
    bounds: ([f32; 2], f32),
    colour: [u8; 3],
    max_faces: usize,
}

/// Draw frame `f` of `clip` into `cell`.
fn draw_frame(c: &mut Canvas, clip: &Clip, f: usize, cell: &Cell) {
    let Cell {
        x,
        y,
        size,
        bounds: (lo, extent),
        colour,
        max_faces,
    } = *cell;
    let margin = 4.0;
    let scale = (size as f32 - 2.0 * margin) / extent;
    let to_px = |p: [f32; 3]| {
        let s = view(p);
        (
            x + (margin + (s[0] - lo[0]) * scale) as i64,
            y + size as i64 - (margin + (s[1] - lo[1]) * scale) as i64,
        )
    };
    let frame = clip.frame(f);
    if clip.faces.is_empty() {
        for p in frame {
            let (px, py) = to_px(*p);
            c.put(px, py, colour);
        }
        return;
    }
    let step = clip.faces.len().div_ceil(max_faces.max(1));
    for face in clip.faces.iter().step_by(step) {
        let q = face.map(|i| to_px(frame[i as usize]));
        for k in 0..3 {
            let (a, b) = (q[k], q[(k + 1) % 3]);
            c.line(a.0, a.1, b.0, b.1, colour, 1);
        }
    }
}

/// The strip as a canvas: a header row of frame numbers, the ground truth, then the prediction; keyframe columns
/// framed in orange with a `K`. Errors when the two sequences do not share frame and vertex counts.
pub fn strip_canvas(
    gt: &Clip,
    pred: &Clip,
    keyframes: &[usize],
    opts: &StripOptions,
) -> Result<Canvas> {
    if gt.frames != pred.frames || gt.n_vertices != pred.n_vertices {
        return Err(DataError::new(
            &gt.id,
            "prediction",
            format!(
                "{} frames × {} vertices, ground truth has {} × {}",
                pred.frames, pred.n_vertices, gt.frames, gt.n_vertices
            ),
        ));
    }
    if let Some(k) = keyframes.iter().find(|&&k| k >= gt.frames) {
        return Err(DataError::new(
            &gt.id,
            "keyframes",
            format!("frame {k} is outside 0..{}", gt.frames),
        ));
    }
    let cell = opts.cell;
    let header = 16u32;
    let width = opts.label_width + cell * gt.frames as u32;
    let height = header + 2 * cell;
    let mut c = Canvas::new(width, height, WHITE);
    let b = bounds(&[gt, pred]);
    c.text(4, i64::from(header + cell / 2 - 4), "GT", BLACK, 1);
    let label: String = opts
        .prediction_label
        .chars()
        .take((opts.label_width / 6).saturating_sub(1) as usize)
        .collect();
    c.text(4, i64::from(header + cell + cell / 2 - 4), &label, BLACK, 1);
    for f in 0..gt.frames {
        let x = i64::from(opts.label_width + cell * f as u32);
        let num = f.to_string();
        c.text(
            x + i64::from(cell / 2) - i64::from(text_width(&num, 1)) / 2,
            4,
            &num,
            BLACK,
            1,
        );
        let top = Cell {
            x,
            y: i64::from(header),
            size: cell,
            bounds: b,
            colour: GT_COLOUR,
            max_faces: opts.max_faces,
        };
        draw_frame(&mut c, gt, f, &top);
        draw_frame(
            &mut c,
            pred,
            f,
            &Cell {
                y: i64::from(header + cell),
                colour: PRED_COLOUR,
                ..top
            },
        );
        if keyframes.contains(&f) {
            for inset in 0..2 {
                c.rect(
                    x + inset,
                    i64::from(header) + inset,
                    i64::from(cell) - 2 * inset,
                    2 * i64::from(cell) - 2 * inset,
                    KEY_COLOUR,
                );
            }
            c.text(x + 4, i64::from(header) + 4, "K", KEY_COLOUR, 1);
        }
    }
    Ok(c)
}

/// Write the strip of [`strip_canvas`] as PNG.
pub fn write_strip(
    gt: &Clip,
    pred: &Clip,
    keyframes: &[usize],
    opts: &StripOptions,
    path: &Path,
) -> Result<()> {
    strip_canvas(gt, pred, keyframes, opts)?.save_png(path)
}
