//! Non-learned completion baselines (docs/method.md §5.2, (L1)): linear interpolation between consecutive keyframes in
//! vertex space, the static nearest keyframe, the same interpolation over latent arrays (`lerp_space =
//! "latent"`; the caller decodes the result), and the keyframe correction (L2) of a decoded completion.

use crate::metrics::{EvalError, Motion, Result, keyframe_set};

/// A non-learned way to fill the frames between keyframes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VertexBaseline {
    /// (L1) linear interpolation between the two keyframes around each frame.
    Linear,
    /// Hold the nearest keyframe (ties go to the earlier one): a frozen-motion reference.
    NearestKeyframe,
}

impl VertexBaseline {
    /// Complete a sequence from its keyframes. Only the keyframe frames of `gt` are read; the output copies them
    /// exactly and fills every other frame. Frames 0 and T − 1 must be keyframes.
    ///
    /// # Shapes
    /// `gt`: `[T, N, 3]`; returns `[T * N]` rows.
    pub fn complete(self, gt: Motion, keyframes: &[usize]) -> Result<Vec<[f32; 3]>> {
        gt.check("ground truth")?;
        let flat: Vec<f32> = gt.vertices().iter().flatten().copied().collect();
        let filled = fill_frames(self.into(), &flat, gt.frames(), 3 * gt.n_vertices(), keyframes)?;
        Ok(filled.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
    }
}

/// How a frame between keyframes a < f < b is filled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Fill {
    Linear,
    Nearest,
}

impl From<VertexBaseline> for Fill {
    fn from(b: VertexBaseline) -> Self {
        match b {
            VertexBaseline::Linear => Fill::Linear,
            VertexBaseline::NearestKeyframe => Fill::Nearest,
        }
    }
}

/// (L1) in latent space: interpolate the keyframe latents `z_a`, `z_b` of each segment; the caller decodes.
/// Only the keyframe frames of `latents` are read. Frames 0 and T − 1 must be keyframes.
///
/// # Shapes
/// `latents`: `[T, P, C]` flattened frame-major (`frame_len = P · C` values per frame); returns the same shape.
pub fn lerp_latents(latents: &[f32], frames: usize, frame_len: usize, keyframes: &[usize]) -> Result<Vec<f32>> {
    if latents.len() != frames * frame_len {
        return Err(EvalError::Parameter {
            name: "latents",
            reason: format!(
                "hold {} values, expected frames × frame length = {frames} × {frame_len}",
                latents.len()
            ),
        });
    }
    if let Some(i) = latents.iter().position(|x| !x.is_finite()) {
        return Err(EvalError::Parameter {
            name: "latents",
            reason: format!(
                "non-finite value {} at frame {}, index {}",
                latents[i],
                i / frame_len,
                i % frame_len
            ),
        });
    }
    fill_frames(Fill::Linear, latents, frames, frame_len, keyframes)
}

/// (L2) keyframe correction: adds to every frame of `prediction` the (L1) interpolation of the keyframe residuals
/// `given − prediction`, so the keyframe frames become `given`'s and the frames between them move by what the
/// decoder got wrong on their neighbours (docs/method.md §5.6). Only the keyframe frames of `given` are read;
/// frames 0 and T − 1 must be keyframes.
///
/// # Shapes
/// `prediction`: `[T * N]` rows; `given`: `[T, N, 3]`.
pub fn correct_by_keyframes(prediction: &mut [[f32; 3]], given: Motion, keyframes: &[usize]) -> Result<()> {
    given.check("keyframes")?;
    let rows = given.frames() * given.n_vertices();
    if prediction.len() != rows {
        return Err(EvalError::Parameter {
            name: "prediction",
            reason: format!(
                "{} rows, expected {} frames × {}",
                prediction.len(),
                given.frames(),
                given.n_vertices()
            ),
        });
    }
    let residual: Vec<f32> = given
        .vertices()
        .iter()
        .zip(prediction.iter())
        .flat_map(|(g, p)| [g[0] - p[0], g[1] - p[1], g[2] - p[2]])
        .collect();
    let spread = lerp_latents(&residual, given.frames(), 3 * given.n_vertices(), keyframes)?;
    for (p, r) in prediction.iter_mut().zip(spread.chunks_exact(3)) {
        for c in 0..3 {
            p[c] += r[c];
        }
    }
    Ok(())
}

/// Fill the non-keyframes of a flat frame-major array from its keyframes.
fn fill_frames(fill: Fill, data: &[f32], frames: usize, frame_len: usize, keyframes: &[usize]) -> Result<Vec<f32>> {
    let keys = keyframe_set(keyframes, frames)?;
    if keys.first() != Some(&0) || keys.last() != Some(&(frames - 1)) {
        return Err(EvalError::Parameter {
            name: "keyframes",
            reason: format!("{keys:?} must include the first and last frames 0 and {}", frames - 1),
        });
    }
    let frame = |f: usize| &data[f * frame_len..(f + 1) * frame_len];
    let mut out = vec![0.0f32; data.len()];
    for &k in &keys {
        out[k * frame_len..(k + 1) * frame_len].copy_from_slice(frame(k));
    }
    for pair in keys.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        for f in a + 1..b {
            let w = (f - a) as f64 / (b - a) as f64;
            let dst = &mut out[f * frame_len..(f + 1) * frame_len];
            let (xa, xb) = (frame(a), frame(b));
            match fill {
                Fill::Linear => {
                    for ((d, &pa), &pb) in dst.iter_mut().zip(xa).zip(xb) {
                        // (L1) x̂_f = x_a + (f − a)/(b − a) · (x_b − x_a)
                        *d = (f64::from(pa) + w * (f64::from(pb) - f64::from(pa))) as f32;
                    }
                }
                Fill::Nearest => dst.copy_from_slice(if f - a <= b - f { xa } else { xb }),
            }
        }
    }
    Ok(out)
}
