//! The embedded procedural dataset (`any4d data synth`): shape families × motion families with
//! random parameters, vertex counts spread over the §2.2 filter range, and captions built from what happens.
//!
//! Clips are in world units (metres, y up, standing on y = 0), not normalised. Every clip depends only on
//! (seed, index): stream `index` of [`crate::rng::rng`]. Captions use viewer-relative directions: +x is "to the
//! right", +y "upward", +z "toward the viewer" (the camera of [`crate::render`] looks from the front-right-top).

mod motions;
pub mod rigged;
pub mod scenes;
mod shapes;

use rayon::prelude::*;

use crate::clip::Clip;
use crate::error::{DataError, Result};
use crate::limits::{CLIP_VERTICES, FRAMES, MAX_SYNTH_CLIPS, MAX_SYNTH_VERTICES};
use crate::rng::{Rng, rng};

type V3 = [f32; 3];

/// What the rest mesh is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ShapeFamily {
    /// A noisy, lumpy sphere.
    Blob,
    /// An upright fluted tube with an elliptic, tapering cross-section.
    Tube,
    /// A two-legged figure (torso, head, arms, legs), skinned to leg and arm bones.
    Humanoid,
    /// A four-legged animal (body, neck, head, tail, legs), skinned to leg bones.
    Quadruped,
    /// A flat cloth sheet (the only open surface).
    Sheet,
    /// A worm lying on the ground, gently sinuous.
    Worm,
    /// A coiled spring standing upright.
    Helix,
}

impl ShapeFamily {
    pub const ALL: [ShapeFamily; 7] = [
        ShapeFamily::Blob,
        ShapeFamily::Tube,
        ShapeFamily::Humanoid,
        ShapeFamily::Quadruped,
        ShapeFamily::Sheet,
        ShapeFamily::Worm,
        ShapeFamily::Helix,
    ];

    /// Name used in clip ids.
    pub fn name(self) -> &'static str {
        match self {
            ShapeFamily::Blob => "blob",
            ShapeFamily::Tube => "tube",
            ShapeFamily::Humanoid => "humanoid",
            ShapeFamily::Quadruped => "quadruped",
            ShapeFamily::Sheet => "sheet",
            ShapeFamily::Worm => "worm",
            ShapeFamily::Helix => "helix",
        }
    }

    /// The family named `name` (as in clip ids), if any.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|f| f.name() == name)
    }

    /// Noun used in captions.
    fn noun(self) -> &'static str {
        match self {
            ShapeFamily::Blob => "blob",
            ShapeFamily::Tube => "tube",
            ShapeFamily::Humanoid => "humanoid",
            ShapeFamily::Quadruped => "quadruped",
            ShapeFamily::Sheet => "cloth sheet",
            ShapeFamily::Worm => "worm",
            ShapeFamily::Helix => "spring",
        }
    }
}

/// How the mesh moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MotionFamily {
    /// Bend along the main axis towards one side and back (lying shapes curl both ends).
    Bend,
    /// Twist about the main axis and back.
    Twist,
    /// A travelling wave along the main axis.
    Wave,
    /// Walk or run cycle (legs swing) for legged shapes; a pulsing crawl for the others.
    Walk,
    /// One to three hops, squashing at take-off and landing, in place or travelling.
    Jump,
    /// Volume-preserving squash and stretch: vertical, or along the length of a worm or sheet.
    Squash,
    /// Rigid spin about the vertical axis while sliding.
    Rigid,
}

impl MotionFamily {
    pub const ALL: [MotionFamily; 7] = [
        MotionFamily::Bend,
        MotionFamily::Twist,
        MotionFamily::Wave,
        MotionFamily::Walk,
        MotionFamily::Jump,
        MotionFamily::Squash,
        MotionFamily::Rigid,
    ];

    /// Name used in clip ids.
    pub fn name(self) -> &'static str {
        match self {
            MotionFamily::Bend => "bend",
            MotionFamily::Twist => "twist",
            MotionFamily::Wave => "wave",
            MotionFamily::Walk => "walk",
            MotionFamily::Jump => "jump",
            MotionFamily::Squash => "squash",
            MotionFamily::Rigid => "rigid",
        }
    }
}

/// Which generator makes the clips.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Family {
    /// Shape families deformed by motion families (blobs, tubes, a humanoid, …; [`ShapeFamily`] × [`MotionFamily`]).
    #[default]
    Shapes,
    /// Skinned characters on random skeletons performing actions ([`rigged`]), optionally of one template or action.
    Rigged(RiggedKinds),
}

/// What a rigged run may draw: `None` draws the template (among those that can perform the action, if that is
/// fixed) or the action (among the template's).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RiggedKinds {
    pub template: Option<rigged::Template>,
    pub action: Option<rigged::Action>,
}

impl Family {
    pub const ALL: [Family; 2] = [
        Family::Shapes,
        Family::Rigged(RiggedKinds {
            template: None,
            action: None,
        }),
    ];

    pub fn name(self) -> &'static str {
        match self {
            Family::Shapes => "shapes",
            Family::Rigged(_) => "rigged",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|f| f.name() == name)
    }
}

/// Settings of `any4d data synth`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SynthConfig {
    /// Number of clips.
    pub clips: usize,
    /// Seed; clip `i` uses stream `i` of it.
    pub seed: u64,
    /// Frames per clip T.
    pub frames: usize,
    /// Smallest vertex count (inclusive).
    pub min_vertices: usize,
    /// Largest vertex count (inclusive).
    pub max_vertices: usize,
    /// `Some(family)`: every clip animates one and the same rest mesh of this family (one topology; what the
    /// faithful BD-LSTM trains on); only the motions differ. The mesh depends on the family and the vertex range,
    /// not on the seed ([`ONE_BODY_SEED`]), so synth runs with other seeds add clips of the same mesh to a store.
    pub body: Option<ShapeFamily>,
    /// The generator.
    pub family: Family,
    /// Each clip moves in a procedural scene around it ([`scenes`]; its caption names the furniture).
    pub scenes: bool,
}

/// Seed of the shared rest mesh of [`SynthConfig::body`] (stream: the family's index).
pub const ONE_BODY_SEED: u64 = 0x0B0D_1E55;

impl Default for SynthConfig {
    fn default() -> Self {
        Self {
            clips: 1000,
            seed: 666,
            frames: 16,
            min_vertices: 512,
            max_vertices: 4096,
            body: None,
            family: Family::Shapes,
            scenes: false,
        }
    }
}

impl SynthConfig {
    /// Rejects settings the generator cannot honour or that would exhaust memory: 2 ≤ T ≤ [`FRAMES`],
    /// 256 ≤ min, min + 256 ≤ max ≤ [`MAX_SYNTH_VERTICES`], T · max ≤ [`CLIP_VERTICES`] (current limits),
    /// clips ≤ [`MAX_SYNTH_CLIPS`].
    pub fn validate(&self) -> Result<()> {
        let err = |field: &str, reason: String| Err(DataError::new("synth config", field, reason));
        let (max_frames, max_rows) = (FRAMES.get_usize(), CLIP_VERTICES.get_usize());
        if !(2..=max_frames).contains(&self.frames) {
            return err(
                "frames",
                format!("needs 2..={max_frames} frames, got {}{}", self.frames, FRAMES.hint()),
            );
        }
        if self.clips > MAX_SYNTH_CLIPS {
            return err(
                "clips",
                format!("at most {MAX_SYNTH_CLIPS} per run, got {}", self.clips),
            );
        }
        if self.max_vertices > MAX_SYNTH_VERTICES {
            return err(
                "max_vertices",
                format!("at most {MAX_SYNTH_VERTICES}, got {}", self.max_vertices),
            );
        }
        if self.frames * self.max_vertices > max_rows {
            return err(
                "frames",
                format!(
                    "{} frames × {} vertices is more than {max_rows} vertex rows per clip{}",
                    self.frames,
                    self.max_vertices,
                    CLIP_VERTICES.hint()
                ),
            );
        }
        if self.min_vertices < 256 {
            return err(
                "min_vertices",
                format!("must be at least 256, got {}", self.min_vertices),
            );
        }
        if self.max_vertices < self.min_vertices.saturating_add(256) {
            return err(
                "max_vertices",
                format!(
                    "must exceed min_vertices {} by at least 256, got {}",
                    self.min_vertices, self.max_vertices
                ),
            );
        }
        if let Family::Rigged(kinds) = self.family {
            if self.body.is_some() {
                return err(
                    "body",
                    "one shared rest mesh is a shape-family option; rigged characters each have their own".into(),
                );
            }
            if let (Some(t), Some(a)) = (kinds.template, kinds.action)
                && !t.actions().contains(&a)
            {
                let can: Vec<&str> = t.actions().iter().map(|a| a.name()).collect();
                return err(
                    "action",
                    format!("a {} cannot {}; it can {}", t.name(), a.name(), can.join(", ")),
                );
            }
        }
        Ok(())
    }

    /// The source of clip `index` (its key in a store: a run with the same seed and generator replaces it; clips
    /// in scenes are other sources than the same clips without).
    pub fn source(&self, index: usize) -> String {
        let plain = self.plain_source(index);
        match self.scenes {
            true => format!("scene-{plain}"),
            false => plain,
        }
    }

    fn plain_source(&self, index: usize) -> String {
        match self.family {
            Family::Shapes => format!("synth:{}:{index}", self.seed),
            Family::Rigged(RiggedKinds {
                template: None,
                action: None,
            }) => format!("synth-rigged:{}:{index}", self.seed),
            Family::Rigged(k) => format!(
                "synth-rigged-{}-{}:{}:{index}",
                k.template.map_or("any", |t| t.name()),
                k.action.map_or("any", |a| a.name()),
                self.seed
            ),
        }
    }
}

/// Seed of the scenes' streams ([`furnished`]), mixed with the run's seed: a clip is the same with a scene or without.
pub const SCENE_SEED: u64 = 0x5CE7_E5EE;

/// Clip `index` with its scene when `cfg.scenes` is set (its caption then names the furniture; the scene's draws
/// come from stream `index` of `cfg.seed ^ SCENE_SEED`).
pub fn generate_scened(cfg: &SynthConfig, index: usize) -> Result<(Clip, Option<crate::scene::Scene>)> {
    let mut clip = generate_one(cfg, index)?;
    if !cfg.scenes {
        return Ok((clip, None));
    }
    let mut r = rng(cfg.seed ^ SCENE_SEED, index as u64);
    let (scene, phrase) = scenes::furnish(&clip, &mut r);
    clip.caption = format!("{} {phrase}", clip.caption);
    Ok((clip, Some(scene)))
}

/// Clip `index` of the dataset: families, sizes and motion drawn from stream `index` of `cfg.seed`.
pub fn generate_one(cfg: &SynthConfig, index: usize) -> Result<Clip> {
    if let Family::Rigged(kinds) = cfg.family {
        return rigged::generate_one(cfg, kinds, index);
    }
    let mut r = rng(cfg.seed, index as u64);
    let shape = ShapeFamily::ALL[r.random_range(0..ShapeFamily::ALL.len())];
    let motion = MotionFamily::ALL[r.random_range(0..MotionFamily::ALL.len())];
    match cfg.body {
        None => build(cfg, index, shape, motion, &mut r),
        Some(family) => {
            cfg.validate()?;
            let body = shared_body(cfg, family)?;
            animate(cfg, index, family, &body, motion, &mut r)
        }
    }
}

/// The one rest mesh of a [`SynthConfig::body`] dataset.
fn shared_body(cfg: &SynthConfig, family: ShapeFamily) -> Result<shapes::Body> {
    let stream = ShapeFamily::ALL.iter().position(|&f| f == family).unwrap_or(0);
    let mut r = rng(ONE_BODY_SEED, stream as u64);
    let target = r.random_range(cfg.min_vertices..=cfg.max_vertices);
    shapes::build(family, target, cfg.min_vertices, cfg.max_vertices, &mut r)
        .map_err(|e| e.at(format!("synth:body:{}", family.name())))
}

/// Clip `index` with the families forced (its own rest mesh, whatever `cfg.body` says); equals [`generate_one`]
/// when they match the drawn ones and `cfg.body` is `None`.
pub fn generate_with(cfg: &SynthConfig, index: usize, shape: ShapeFamily, motion: MotionFamily) -> Result<Clip> {
    let mut r = rng(cfg.seed, index as u64);
    let _families: (usize, usize) = (
        r.random_range(0..ShapeFamily::ALL.len()),
        r.random_range(0..MotionFamily::ALL.len()),
    );
    build(cfg, index, shape, motion, &mut r)
}

/// All `cfg.clips` clips, in index order, generated in parallel.
pub fn generate(cfg: &SynthConfig) -> Result<Vec<Clip>> {
    cfg.validate()?;
    (0..cfg.clips).into_par_iter().map(|i| generate_one(cfg, i)).collect()
}

/// The families encoded in a synthetic clip id (`synth-<shape>-<motion>-<seed>-<index>_offset0_0-<T−1>`).
pub fn families(clip_id: &str) -> Option<(ShapeFamily, MotionFamily)> {
    let mut parts = clip_id.strip_prefix("synth-")?.split('-');
    let (s, m) = (parts.next()?, parts.next()?);
    let shape = ShapeFamily::ALL.into_iter().find(|f| f.name() == s)?;
    let motion = MotionFamily::ALL.into_iter().find(|f| f.name() == m)?;
    Some((shape, motion))
}

fn build(
    cfg: &SynthConfig,
    index: usize,
    shape: ShapeFamily,
    motion: MotionFamily,
    r: &mut crate::rng::DataRng,
) -> Result<Clip> {
    cfg.validate()?;
    let source = cfg.source(index);
    let target = r.random_range(cfg.min_vertices..=cfg.max_vertices);
    let body = shapes::build(shape, target, cfg.min_vertices, cfg.max_vertices, r).map_err(|e| e.at(&source))?;
    animate(cfg, index, shape, &body, motion, r)
}

/// Clip `index`: `body` posed by a `motion` drawn from `r`, with its id and caption.
fn animate(
    cfg: &SynthConfig,
    index: usize,
    shape: ShapeFamily,
    body: &shapes::Body,
    motion: MotionFamily,
    r: &mut crate::rng::DataRng,
) -> Result<Clip> {
    let source = cfg.source(index);
    let geo = motions::Geometry::of(body);
    let (drawn, phrase) = motions::draw(motion, body, &geo, r);
    let n = body.pos.len();
    let mut vertices = vec![[0.0f32; 3]; cfg.frames * n];
    for (f, frame) in vertices.chunks_exact_mut(n).enumerate() {
        let tau = f as f32 / (cfg.frames - 1) as f32;
        motions::pose(&drawn, body, &geo, tau, frame);
    }
    let id = format!(
        "synth-{}-{}-{}-{index}_offset0_0-{}",
        shape.name(),
        motion.name(),
        cfg.seed,
        cfg.frames - 1
    );
    let mut words = body.words.clone();
    words.push(body.noun);
    let article = if words[0].starts_with(['a', 'e', 'i', 'o', 'u']) {
        "an"
    } else {
        "a"
    };
    let caption = format!("{article} {} {phrase}", words.join(" "));
    Clip::new(id, vertices, cfg.frames, n, body.faces.clone(), caption, source)
}

#[cfg(test)]
mod tests;
