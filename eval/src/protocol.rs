//! The evaluation protocol of docs/method.md §6.1: a manifest of fixed validation clips, nested keyframe sets per K_x
//! (or every-r / Bernoulli-p placements, docs/method.md §8 X4) and noise seeds, shared by every method and saved as
//! JSON. The items are read from a dataset store's validation split ([`StoreSource`]); 31-frame items join two
//! clips that share a frame (docs/method.md §2.7).

use std::path::Path;

use any4d_data::Clip;
use any4d_data::io::write_atomic;
use any4d_data::keyframes::Placement;
use any4d_data::rng::{GOLDEN_GAMMA, Rng, rng, splitmix64};
use any4d_data::store::{Split, Status, Store, StoredClip, read_index};
use serde::{Deserialize, Serialize};

/// Manifest format version written by [`Manifest::save`]; [`Manifest::load`] rejects any other.
pub const MANIFEST_VERSION: u32 = 1;
/// The manifest seed of docs/method.md §6.1.
pub const MANIFEST_SEED: u64 = 42;
/// Stream label for the clip draw, so it never shares draws with the keyframe draws (streams 1 + position).
const CLIP_STREAM: u64 = 0;

use crate::error::{EvalError, Result};

/// A clip of the dataset store: its index there and its id.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ClipRef {
    /// Index in the dataset store (`Store::get(index)`).
    pub index: usize,
    /// Clip id (AAM form `<uid>_offset<k>_<start>-<end>` when known).
    pub id: String,
}

/// One evaluation item: a 16-frame clip, or two clips sharing their boundary frame (31 frames, docs/method.md §2.7).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ManifestClip {
    /// The clip, or the first clip of a long-horizon pair.
    pub clip: ClipRef,
    /// The second clip of a long-horizon pair (its frame 0 is the first clip's last frame).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub next: Option<ClipRef>,
    /// Keyframe sets, zero-based frame indices, sorted. For `Placement::Random`, entry k is the set for K_x = k
    /// and each set contains the previous one; other placements have one set.
    pub keyframes: Vec<Vec<usize>>,
}

/// The fixed protocol: which clips, which keyframes, which noise seeds (docs/method.md §6.1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// [`MANIFEST_VERSION`].
    pub version: u32,
    /// Seed of the clip and keyframe draws (42).
    pub seed: u64,
    /// Frames per evaluation item: 16 (short horizon) or 31 (two windows sharing frame 15).
    pub frames: usize,
    /// How the keyframe sets were drawn.
    pub placement: Placement,
    /// Base noise seeds; generation for item i with base s uses [`noise_seed`]`(s, i)`.
    pub seeds: Vec<u64>,
    /// The dataset the clips come from (a directory or description).
    pub data: String,
    /// The split the clips were drawn from (`validation`).
    pub split: String,
    /// The evaluation items, in draw order.
    pub clips: Vec<ManifestClip>,
}

/// What to draw in [`Manifest::build`].
#[derive(Debug, Clone, PartialEq)]
pub struct ManifestOptions {
    /// Number of items (100 in docs/method.md §6.1); fewer candidates is an error.
    pub n_clips: usize,
    /// Draw seed (42).
    pub seed: u64,
    /// Frames per item (16 or 31).
    pub frames: usize,
    /// Keyframe placement.
    pub placement: Placement,
    /// Base noise seeds (`[42]`; docs/method.md §8 X8: `[42, 43, 44, 45, 46]`).
    pub seeds: Vec<u64>,
    /// Dataset description stored in the manifest.
    pub data: String,
    /// Split name stored in the manifest.
    pub split: String,
}

impl ManifestOptions {
    /// The short-horizon protocol of P-Table 1: 100 clips, 16 frames, K_x = 0..3 nested, seed 42, noise seed 42.
    pub fn table1(data: impl Into<String>) -> Self {
        Self {
            n_clips: 100,
            seed: MANIFEST_SEED,
            frames: 16,
            placement: Placement::PAPER,
            seeds: vec![MANIFEST_SEED],
            data: data.into(),
            split: "validation".into(),
        }
    }

    /// The long-horizon protocol of P-Table 2: 100 pairs, 31 frames, keyframes {0, 15, 30}.
    pub fn table2(data: impl Into<String>) -> Self {
        Self {
            frames: 31,
            placement: Placement::Stride { stride: 15 },
            ..Self::table1(data)
        }
    }
}

/// A candidate evaluation item before keyframes are drawn.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Candidate {
    pub clip: ClipRef,
    pub next: Option<ClipRef>,
}

impl Manifest {
    /// Draw `opts.n_clips` items from `candidates` (a seeded shuffle, draw order kept) and their keyframe sets.
    /// The error names `source` (the dataset) when there are too few candidates or the options are invalid.
    pub fn build(candidates: &[Candidate], opts: &ManifestOptions, source: &str) -> Result<Self> {
        let bad = |field: &str, reason: String| EvalError::invalid(source, field, reason);
        if candidates.len() < opts.n_clips {
            return Err(bad(
                "clips",
                format!(
                    "{} candidate clips in the {} split, the protocol needs {} (ask for at most {} with --clips)",
                    candidates.len(),
                    opts.split,
                    opts.n_clips,
                    candidates.len()
                ),
            ));
        }
        opts.placement.check(opts.frames).map_err(|r| bad("placement", r))?;
        if opts.seeds.is_empty() {
            return Err(bad("seeds", "at least one noise seed is needed".into()));
        }
        let mut order: Vec<usize> = (0..candidates.len()).collect();
        let mut r = rng(opts.seed, CLIP_STREAM);
        // Partial Fisher–Yates: the first n positions are a uniform draw without replacement.
        for i in 0..opts.n_clips {
            let j = r.random_range(i..order.len());
            order.swap(i, j);
        }
        let clips = order[..opts.n_clips]
            .iter()
            .enumerate()
            .map(|(pos, &c)| ManifestClip {
                clip: candidates[c].clip.clone(),
                next: candidates[c].next.clone(),
                keyframes: opts.placement.keyframe_sets(opts.frames, opts.seed, pos as u64),
            })
            .collect();
        Ok(Self {
            version: MANIFEST_VERSION,
            seed: opts.seed,
            frames: opts.frames,
            placement: opts.placement,
            seeds: opts.seeds.clone(),
            data: opts.data.clone(),
            split: opts.split.clone(),
            clips,
        })
    }

    /// Write the manifest as pretty JSON (temp file, then rename).
    pub fn save(&self, path: &Path) -> Result<()> {
        let text =
            serde_json::to_string_pretty(self).map_err(|e| EvalError::invalid(path, "manifest", e.to_string()))?;
        Ok(write_atomic(path, text.as_bytes())?)
    }

    /// Read and validate a manifest; errors name the file, the field (e.g. `clips[3].keyframes[1]`) and the reason.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| EvalError::io(path, e))?;
        let m: Manifest = serde_json::from_str(&text)
            .map_err(|e| EvalError::invalid(path, format!("line {}", e.line()), e.to_string()))?;
        m.validate().map_err(|e| e.at(path))?;
        Ok(m)
    }

    /// Checks version, placement, seeds and every keyframe set (sorted, unique, in range, first and last
    /// frame present, nested with K_x + 2 entries for `Random`).
    pub fn validate(&self) -> Result<()> {
        let bad = |field: String, reason: String| Err(EvalError::invalid("manifest", field, reason));
        if self.version != MANIFEST_VERSION {
            return bad(
                "version".into(),
                format!("is {}, this build reads {MANIFEST_VERSION}", self.version),
            );
        }
        if let Err(r) = self.placement.check(self.frames) {
            return bad("placement".into(), r);
        }
        if self.seeds.is_empty() {
            return bad("seeds".into(), "is empty".into());
        }
        for (i, item) in self.clips.iter().enumerate() {
            let expected_sets = self.placement.sets();
            if item.keyframes.len() != expected_sets {
                return bad(
                    format!("clips[{i}].keyframes"),
                    format!(
                        "holds {} sets, placement {} needs {expected_sets}",
                        item.keyframes.len(),
                        self.placement.label()
                    ),
                );
            }
            for (k, set) in item.keyframes.iter().enumerate() {
                if let Err(r) = check_set(set, self.frames) {
                    return bad(format!("clips[{i}].keyframes[{k}]"), r);
                }
                if let Placement::Random { .. } = self.placement {
                    if set.len() != k + 2 {
                        return bad(
                            format!("clips[{i}].keyframes[{k}]"),
                            format!("has {} frames, K_x = {k} needs {}", set.len(), k + 2),
                        );
                    }
                    if k > 0 && !item.keyframes[k - 1].iter().all(|f| set.contains(f)) {
                        return bad(
                            format!("clips[{i}].keyframes[{k}]"),
                            format!("does not contain the K_x = {} set", k - 1),
                        );
                    }
                }
            }
        }
        Ok(())
    }

    /// The K_x value (extra keyframes beyond first and last) of keyframe set `set` of item `item`.
    pub fn k_extra(&self, item: usize, set: usize) -> usize {
        self.clips[item].keyframes[set].len().saturating_sub(2)
    }
}

/// The noise seed of item `clip_index` under base seed `base` (docs/method.md §6.1: derived from (42, clip index)).
/// SplitMix64 of the pair, so neighbouring items and seeds get unrelated streams; the same for every K_x.
pub fn noise_seed(base: u64, clip_index: usize) -> u64 {
    splitmix64(base.wrapping_mul(GOLDEN_GAMMA) ^ (clip_index as u64).wrapping_add(0xD1B5_4A32_D192_ED03))
}

fn check_set(set: &[usize], frames: usize) -> std::result::Result<(), String> {
    if set.first() != Some(&0) || set.last() != Some(&(frames - 1)) {
        return Err(format!(
            "{set:?} must start with frame 0 and end with frame {}",
            frames - 1
        ));
    }
    if set.windows(2).any(|w| w[0] >= w[1]) {
        return Err(format!("{set:?} is not strictly increasing"));
    }
    Ok(())
}

/// Long-horizon candidates (docs/method.md §2.7): pairs of clips of one animation (same id up to the `_<start>-<end>`
/// tail) where the second starts 15 frames after the first, so they share the first clip's last frame.
/// Ids that do not follow the AAM form `<uid>_offset<k>_<start>-<end>` are skipped.
pub fn long_horizon_pairs(clips: &[ClipRef]) -> Vec<Candidate> {
    let parsed: Vec<Option<(&str, usize)>> = clips.iter().map(|c| split_start(&c.id)).collect();
    let mut by_key: std::collections::HashMap<(&str, usize), usize> = std::collections::HashMap::new();
    for (i, p) in parsed.iter().enumerate() {
        if let Some(key) = p {
            by_key.insert(*key, i);
        }
    }
    let mut out = Vec::new();
    for (i, p) in parsed.iter().enumerate() {
        if let Some((stem, start)) = p
            && let Some(&j) = by_key.get(&(*stem, start + 15))
        {
            out.push(Candidate {
                clip: clips[i].clone(),
                next: Some(clips[j].clone()),
            });
        }
    }
    out
}

/// `uid_offset0_30-46` → (`uid_offset0`, 30).
fn split_start(id: &str) -> Option<(&str, usize)> {
    let (stem, range) = id.rsplit_once('_')?;
    let (start, _end) = range.split_once('-')?;
    match start.parse() {
        Ok(s) => Some((stem, s)),
        Err(_) => None, // not the AAM form: not a long-horizon candidate
    }
}

/// Which clips of a store an evaluation draws its items from (`eval run --split`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EvalSplit {
    /// The validation split (the paper's protocol).
    #[default]
    Val,
    /// The training split (to measure over-fitting).
    Train,
    /// Every clip with status ok, whatever its split (a held-out store imported from real files is scored whole).
    All,
}

impl EvalSplit {
    /// The name written into manifests and table headers (`validation`, `train`, `all`).
    pub fn name(self) -> &'static str {
        match self {
            EvalSplit::Val => "validation",
            EvalSplit::Train => "train",
            EvalSplit::All => "all",
        }
    }

    /// Whether a clip of `split` (None: the index row has no split) is an evaluation candidate.
    pub fn includes(self, split: Option<Split>) -> bool {
        match self {
            EvalSplit::Val => split == Some(Split::Val),
            EvalSplit::Train => split == Some(Split::Train),
            EvalSplit::All => true,
        }
    }

    /// Parses `val` | `validation` | `train` | `all` (the CLI's value parser).
    pub fn parse(s: &str) -> std::result::Result<Self, String> {
        match s {
            "val" | "validation" => Ok(EvalSplit::Val),
            "train" => Ok(EvalSplit::Train),
            "all" => Ok(EvalSplit::All),
            other => Err(format!("unknown split {other:?}: expected val, train or all")),
        }
    }
}

/// Clips for the protocol: one split of a store (the validation split unless told otherwise).
pub struct StoreSource {
    store: Store,
    val: Vec<ClipRef>,
}

impl StoreSource {
    /// Open a store and list the clips of `split` from `index.parquet` (rows with status ok, in store order).
    pub fn open(dir: &Path, split: EvalSplit) -> Result<Self> {
        let store = Store::open(dir)?;
        let ok: Vec<_> = read_index(dir)?
            .into_iter()
            .filter(|r| r.status == Status::Ok)
            .collect();
        if ok.len() != store.len() {
            return Err(EvalError::invalid(
                dir,
                "index.parquet",
                format!("{} ok rows but clips.bin holds {} clips", ok.len(), store.len()),
            ));
        }
        let val = ok
            .into_iter()
            .enumerate()
            .filter(|(_, r)| split.includes(r.split))
            .map(|(index, r)| ClipRef { index, id: r.id })
            .collect();
        Ok(Self { store, val })
    }

    /// Evaluation candidates: single clips of the split when the store's clips are long enough for `frames`,
    /// otherwise pairs of clips sharing their boundary frame (docs/method.md §2.7).
    pub fn candidates(&self, frames: usize) -> Vec<Candidate> {
        if self.store.frames() >= frames {
            self.val
                .iter()
                .map(|c| Candidate {
                    clip: c.clone(),
                    next: None,
                })
                .collect()
        } else {
            long_horizon_pairs(&self.val)
        }
    }

    /// Whether the store's records carry scenes (docs/method.md §6.5).
    pub fn has_scenes(&self) -> bool {
        self.store.has_scenes()
    }

    /// The stored scene of a single-window item, in that window's normalised frame (the frame of [`Self::item`]'s
    /// ground truth); `None` for a pair of windows or a clip without a scene.
    pub fn item_scene(&self, item: &ManifestClip) -> Result<Option<any4d_data::scene::Scene>> {
        match item.next {
            Some(_) => Ok(None),
            None => Ok(self.store.get(item.clip.index)?.scene),
        }
    }

    /// The ground truth of a manifest item and its prompts (one per 16-frame clip), normalised by its frame 0.
    pub fn item(&self, item: &ManifestClip, frames: usize) -> Result<(Clip, Vec<String>)> {
        let first = self.store.get(item.clip.index)?;
        check_id(&first.clip, &item.clip, self.store.dir())?;
        match &item.next {
            None => {
                let c = first_frames(&first.clip, frames)?;
                let caption = c.caption.clone();
                Ok((c, vec![caption]))
            }
            Some(next) => {
                let second = self.store.get(next.index)?;
                check_id(&second.clip, next, self.store.dir())?;
                let captions = vec![first.clip.caption.clone(), second.clip.caption.clone()];
                let joined = join_shared_frame(&first, &second, self.store.dir())?;
                Ok((any4d_data::preprocess::normalize(&joined).0, captions))
            }
        }
    }
}

fn check_id(clip: &Clip, want: &ClipRef, dir: &Path) -> Result<()> {
    if clip.id != want.id {
        return Err(EvalError::invalid(
            dir,
            format!("clip {}", want.index),
            format!("is {:?}, the manifest names {:?}", clip.id, want.id),
        ));
    }
    Ok(())
}

fn first_frames(clip: &Clip, frames: usize) -> Result<Clip> {
    if clip.frames < frames {
        return Err(EvalError::invalid(
            &clip.id,
            "frames",
            format!("{} frames, the protocol needs {frames}", clip.frames),
        ));
    }
    Clip::new(
        &clip.id,
        clip.vertices[..frames * clip.n_vertices].to_vec(),
        frames,
        clip.n_vertices,
        clip.faces.clone(),
        &clip.caption,
        &clip.source,
    )
    .map_err(EvalError::from)
}

/// Two consecutive windows sharing a frame → one sequence without the duplicate (docs/method.md §2.7), in absolute
/// coordinates (each stored window is normalised by its own frame 0; the stored (c, s) undo that).
fn join_shared_frame(a: &StoredClip, b: &StoredClip, dir: &Path) -> Result<Clip> {
    let (mut a_abs, mut b_abs) = (a.clip.clone(), b.clip.clone());
    a.normalization.invert(&mut a_abs);
    b.normalization.invert(&mut b_abs);
    let pair = format!("{} + {}", a_abs.id, b_abs.id);
    if a_abs.n_vertices != b_abs.n_vertices || a_abs.faces != b_abs.faces {
        return Err(EvalError::invalid(
            dir,
            pair,
            "the pair does not share one mesh (vertex count or faces differ)",
        ));
    }
    let n = a_abs.n_vertices;
    let worst = a_abs
        .frame(a_abs.frames - 1)
        .iter()
        .zip(b_abs.frame(0))
        .map(|(p, q)| (0..3).map(|k| (p[k] - q[k]).abs()).fold(0.0f32, f32::max))
        .fold(0.0f32, f32::max);
    if worst > 1e-4 * a.normalization.scale.max(f32::MIN_POSITIVE) {
        return Err(EvalError::invalid(
            dir,
            pair,
            format!("last frame of the first and frame 0 of the second differ by {worst}: not a shared frame"),
        ));
    }
    let mut vertices = a_abs.vertices.clone();
    vertices.extend_from_slice(&b_abs.vertices[n..]);
    Clip::new(
        &a_abs.id,
        vertices,
        a_abs.frames + b_abs.frames - 1,
        n,
        a_abs.faces.clone(),
        &a_abs.caption,
        &a_abs.source,
    )
    .map_err(EvalError::from)
}
