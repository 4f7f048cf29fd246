//! What `any4d bench acap` measures: ACAP feature extraction (with the topology's factorisations) and the
//! ring-moment reconstruction of every frame of one procedural clip, the work the faithful BD-LSTM does per clip,
//! beside the independent numpy/scipy implementation (`scripts/acap_reference.py --bench`) on the same clip.

use std::time::Instant;

use crate::acap::{AcapTopology, Reconstruction};
use crate::clip::Clip;
use crate::error::{DataError, Result};
use crate::limits::MAX_SYNTH_VERTICES;
use crate::synth::{MotionFamily, ShapeFamily, SynthConfig, generate_with};

/// Best-of-K seconds of the two stages (the reference reports the best of K too).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AcapTiming {
    /// Topology (weights, factorisations) and the features of every frame.
    pub features_s: f64,
    /// Positions of every frame from its features.
    pub reconstruction_s: f64,
}

impl AcapTiming {
    /// Both stages.
    pub fn total_s(&self) -> f64 {
        self.features_s + self.reconstruction_s
    }
}

/// A twisting tube of about `vertices` vertices (within ±128) and `frames` frames: the benchmark clip.
///
/// # Errors
/// Fewer than 384 or more than the generator's limit less 128 vertices, or frames the generator refuses.
pub fn bench_clip(vertices: usize, frames: usize) -> Result<Clip> {
    let most = MAX_SYNTH_VERTICES - 128;
    if !(384..=most).contains(&vertices) {
        return Err(DataError::new(
            "acap bench",
            "--vertices",
            format!("needs 384..={most} vertices, got {vertices}"),
        ));
    }
    let cfg = SynthConfig {
        clips: 1,
        seed: 4,
        frames,
        min_vertices: vertices - 128,
        max_vertices: vertices + 128,
        body: None,
        family: Default::default(),
        scenes: false,
    };
    generate_with(&cfg, 0, ShapeFamily::Tube, MotionFamily::Twist)
}

/// Times features + reconstruction of `clip` `repeat` times (on the current rayon pool) and keeps the fastest run.
pub fn time_acap(clip: &Clip, repeat: usize) -> Result<AcapTiming> {
    let frames: Vec<&[[f32; 3]]> = (0..clip.frames).map(|f| clip.frame(f)).collect();
    let mut best: Option<AcapTiming> = None;
    for _ in 0..repeat.max(1) {
        let t0 = Instant::now();
        let topology = AcapTopology::new(&clip.id, frames[0], &clip.faces)?;
        let features = topology.features(&frames)?;
        let t1 = Instant::now();
        for f in &features {
            topology.reconstruct(f, Reconstruction::RingMoments)?;
        }
        let run = AcapTiming {
            features_s: (t1 - t0).as_secs_f64(),
            reconstruction_s: t1.elapsed().as_secs_f64(),
        };
        if best.is_none_or(|b| run.total_s() < b.total_s()) {
            best = Some(run);
        }
    }
    Ok(best.expect("at least one run"))
}
