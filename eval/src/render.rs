//! Result pictures (docs/method.md §6): a PNG strip per clip with the ground truth above and the prediction below, one
//! column per frame, keyframe columns framed and labelled. Frames are drawn by the data crate's rasteriser from one
//! fixed orthographic three-quarter view framed on both sequences, so motion and errors are visible at one scale.

use std::path::Path;

use any4d_data::Clip;
use any4d_data::render::{Camera, View, rasterize_frame};
use image::imageops::replace;

use crate::plot::{BLACK, Canvas, WHITE, text_width};

use crate::error::{EvalError, Result};

/// Keyframe frame colour (orange).
const KEY_COLOUR: [u8; 3] = [230, 120, 0];

/// Layout of a strip.
#[derive(Debug, Clone, PartialEq)]
pub struct StripOptions {
    /// Pixel size of one frame cell.
    pub cell: u32,
    /// Width of the label column on the left.
    pub label_width: u32,
    /// Label of the prediction row.
    pub prediction_label: String,
}

impl Default for StripOptions {
    fn default() -> Self {
        Self {
            cell: 96,
            label_width: 56,
            prediction_label: "PRED".into(),
        }
    }
}

/// The strip as a canvas: a header row of frame numbers, the ground truth, then the prediction; keyframe columns
/// framed in orange with a `K`. Errors when the two sequences do not share frame and vertex counts.
pub fn strip_canvas(gt: &Clip, pred: &Clip, keyframes: &[usize], opts: &StripOptions) -> Result<Canvas> {
    if gt.frames != pred.frames || gt.n_vertices != pred.n_vertices {
        return Err(EvalError::invalid(
            &gt.id,
            "prediction",
            format!(
                "{} frames × {} vertices, ground truth has {} × {}",
                pred.frames, pred.n_vertices, gt.frames, gt.n_vertices
            ),
        ));
    }
    if let Some(k) = keyframes.iter().find(|&&k| k >= gt.frames) {
        return Err(EvalError::invalid(
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
    let both: Vec<[f32; 3]> = gt.vertices.iter().chain(&pred.vertices).copied().collect();
    let view = View::fit(&both, Camera::FrontRightTop);
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
        for (row, clip) in [gt, pred].into_iter().enumerate() {
            let tile = rasterize_frame(clip.frame(f), &clip.faces, &view, cell).map_err(|e| e.at(&clip.id))?;
            replace(&mut c.img, &tile, x, i64::from(header + cell * row as u32));
        }
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
pub fn write_strip(gt: &Clip, pred: &Clip, keyframes: &[usize], opts: &StripOptions, path: &Path) -> Result<()> {
    strip_canvas(gt, pred, keyframes, opts)?.save_png(path)
}

/// A file format for exported predictions (docs/method.md §6.3: per-frame meshes for the external Blender/VBench
/// pipeline).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExportFormat {
    /// DyMesh pickle `.bin`.
    Bin,
    /// A folder of per-frame `.obj` files.
    ObjSeq,
    /// Binary glTF with one morph target per frame.
    Glb,
}

impl ExportFormat {
    /// Every format.
    pub const ALL: [ExportFormat; 3] = [ExportFormat::Bin, ExportFormat::ObjSeq, ExportFormat::Glb];

    /// The path of `stem` in this format inside `dir`.
    pub fn path(self, dir: &Path, stem: &str) -> std::path::PathBuf {
        match self {
            ExportFormat::Bin => dir.join(format!("{stem}.bin")),
            ExportFormat::ObjSeq => dir.join(format!("{stem}_obj")),
            ExportFormat::Glb => dir.join(format!("{stem}.glb")),
        }
    }
}

/// Write `clip` (a prediction, in the normalised frame of its ground truth) in each of `formats` under `dir`,
/// with the data crate's writers; returns the written paths.
pub fn export_sequence(
    clip: &Clip,
    dir: &Path,
    stem: &str,
    formats: &[ExportFormat],
) -> Result<Vec<std::path::PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|e| EvalError::io(dir, e))?;
    formats
        .iter()
        .map(|f| {
            // Each format's own writer: a stem such as `impute_until_0.98` must not be read as an extension.
            let path = f.path(dir, stem);
            match f {
                ExportFormat::Bin => any4d_data::formats::dymesh_bin::write_bin(&path, clip)?,
                ExportFormat::ObjSeq => any4d_data::formats::obj::write_obj_seq(&path, clip)?,
                ExportFormat::Glb => {
                    any4d_data::formats::gltf::write_gltf(&path, clip, any4d_data::formats::gltf::DEFAULT_FPS)?
                }
            }
            Ok(path)
        })
        .collect()
}
