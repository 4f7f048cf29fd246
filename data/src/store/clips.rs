//! How one import source becomes store clips: read it (every take of a file with takes), weld, filter, cut into
//! windows, normalise (D1)–(D3) and sample FPS tokens (docs/method.md §2.5); what goes wrong becomes the reason
//! of a rejection.

use std::path::Path;

use crate::caption;
use crate::clip::{Clip, object_uid};
use crate::error::{DataError, Result};
use crate::formats::skeletal::{ReadOptions, SkinStats, TakeSel};
use crate::formats::{self, Format, dymesh_bin::MISSING_CAPTION};
use crate::fps::farthest_point_sampling;
use crate::preprocess;

use super::jobs::{Job, Outcome};
use super::{ImportOptions, SPLIT_SEED, Split, StoredClip};

/// The reason text of a rejection: `field: reason`, prefixed by the file when it is not the source itself.
pub(super) fn reason(e: &DataError, source: &str) -> String {
    if e.path == source {
        format!("{}: {}", e.field, e.reason)
    } else {
        e.to_string()
    }
}

/// The reason text of a rejected take: `field: reason`, followed by the file in parentheses when it is neither
/// the source nor the take (an animation file beside the mesh), so that the field always comes first.
fn take_reason(e: &DataError, source: &str, take_source: &str) -> String {
    if e.path == source || e.path == take_source {
        format!("{}: {}", e.field, e.reason)
    } else {
        format!("{}: {} (in {})", e.field, e.reason, e.path)
    }
}

pub(super) fn process_file(job: &Job, opts: &ImportOptions) -> Outcome {
    let Job::File {
        source,
        path,
        format,
        provenance,
    } = job
    else {
        return Outcome::Rejected("not a file".into());
    };
    let format = match format {
        Ok(f) => *f,
        Err(e) => return Outcome::Rejected(reason(e, source)),
    };
    if let Err(e) = provenance {
        return Outcome::Rejected(reason(e, source));
    }
    // The source's scene, if any (docs/method.md §6.5: a `.scene.obj` beside it, a glTF's still meshes): every
    // window carries it, normalised with it.
    let scene = match scene_of(path) {
        Err(e) => return Outcome::Rejected(reason(&e, source)),
        Ok(s) => s,
    };
    let scene = scene.as_ref();
    if !format.has_takes() {
        return match formats::read_clip(path).and_then(|c| accept(c, source.clone(), opts, scene)) {
            Ok(windows) => Outcome::Clips(windows, Vec::new(), SkinStats::default(), Vec::new()),
            Err(e) => Outcome::Rejected(reason(&e, source)),
        };
    }
    let takes = match formats::list_takes(path) {
        Ok(t) => t.unwrap_or_default(),
        Err(e) => return Outcome::Rejected(reason(&e, source)),
    };
    if takes.is_empty() {
        let poses = formats::one_frame_takes(path).unwrap_or_default();
        return Outcome::Rejected(match poses.is_empty() {
            true => "animations: no animation: a static mesh is not a clip".into(),
            false => format!(
                "animations: only one-frame animations (poses, no motion): {}",
                poses.join(", ")
            ),
        });
    }
    let asset = job
        .provenance()
        .asset
        .unwrap_or_else(|| caption::asset_of_path(&formats::asset_path(path)));
    let object = object_name(path);
    let mut clips = Vec::new();
    let mut failed = Vec::new();
    let mut skin = SkinStats::default();
    for (k, take) in takes.iter().enumerate() {
        let take_source = format!("{source}#{}", take.name);
        let read = formats::read_take(
            path,
            &ReadOptions {
                take: TakeSel::Index(k),
                max_frames: opts.max_frames,
            },
        );
        let result = read.and_then(|t| {
            let mut clip = t.clip;
            clip.id = format!("{object}_offset{k}_0-{}", clip.frames - 1);
            // A glTF may carry its own caption (any4d's writer stores the clip's); other clips are captioned
            // from their asset and take names.
            let own = matches!(format, Format::Gltf | Format::Glb) && clip.caption != MISSING_CAPTION;
            if !own {
                clip.caption = caption::caption(&asset, &take.name);
            }
            Ok((accept(clip, take_source.clone(), opts, scene)?, t.stats))
        });
        match result {
            Ok((w, stats)) => {
                clips.extend(w);
                skin.add(&stats);
            }
            Err(e) => failed.push((take_source.clone(), take_reason(&e, source, &take_source))),
        }
    }
    if clips.is_empty() {
        let why: Vec<String> = failed
            .iter()
            .take(3)
            .map(|(s, r)| format!("{}: {r}", s.rsplit_once('#').map_or(s.as_str(), |(_, take)| take)))
            .collect();
        let more = failed.len().saturating_sub(3);
        let more = if more > 0 {
            format!("; {more} more")
        } else {
            String::new()
        };
        return Outcome::Rejected(format!(
            "takes: none of {} became a clip ({}{more})",
            failed.len(),
            why.join("; ")
        ));
    }
    // Listing the poses is a notice only: a file whose takes read is not rejected for failing to list them.
    let poses = formats::one_frame_takes(path)
        .unwrap_or_default()
        .into_iter()
        .map(|name| format!("{source}#{name}"))
        .collect();
    Outcome::Clips(clips, failed, skin, poses)
}

/// The object uid of a file with takes: its last two folders and stem, lower-case, `[a-z0-9]` runs joined by
/// `-` (`…/actors/drone/mesh.md5mesh` → `actors-drone-mesh`), so that all takes of one asset share a split and
/// the uid does not depend on where the tree was unpacked.
fn object_name(path: &Path) -> String {
    let comps: Vec<String> = path
        .components()
        .rev()
        .take(3)
        .map(|c| {
            c.as_os_str()
                .to_string_lossy()
                .split('.')
                .next()
                .unwrap_or_default()
                .to_ascii_lowercase()
        })
        .collect();
    let joined = comps.into_iter().rev().collect::<Vec<_>>().join("-");
    let mut out = String::new();
    for c in joined.chars() {
        if c.is_ascii_alphanumeric() {
            out.push(c);
        } else if !out.ends_with('-') && !out.is_empty() {
            out.push('-');
        }
    }
    out.trim_end_matches('-').to_owned()
}

/// Weld, filter and cut one clip into preprocessed windows.
fn accept(
    mut clip: Clip,
    source: String,
    opts: &ImportOptions,
    scene: Option<&crate::scene::Scene>,
) -> Result<Vec<(StoredClip, String)>> {
    clip.source = source;
    let clip = opts.weld.apply(clip)?;
    opts.filter.check(&clip)?;
    let clip = match opts.loop_short && clip.frames < opts.frames {
        true => preprocess::loop_to(&clip, opts.frames).unwrap_or(clip),
        false => clip,
    };
    if clip.frames < opts.frames {
        return Err(DataError::new(
            &clip.source,
            "frames",
            format!(
                "clip {} has {} frames, fewer than the window length {}{}",
                clip.id,
                clip.frames,
                opts.frames,
                if opts.loop_short {
                    " and does not loop (its last frame does not lead back to its first)"
                } else {
                    " (--loop-short plays a looping take as a cycle)"
                }
            ),
        ));
    }
    preprocess_windows(&clip, opts.frames, opts.stride, opts.p, scene)
}

/// Cut `clip` into windows, normalise each by its frame 0 (D1)–(D3) (and `scene`, when the clip has one, with it),
/// run FPS on normalised frame 0 and assign the split of the clip's object (module doc of [`crate::store`]). Returns each window with its object uid, or
/// an error (field `vertices`) when a window does not normalise to finite numbers (finite coordinates near ±3.4e38
/// overflow f32).
pub(super) fn preprocess_windows(
    clip: &Clip,
    frames: usize,
    stride: usize,
    p: usize,
    scene: Option<&crate::scene::Scene>,
) -> Result<Vec<(StoredClip, String)>> {
    // The uid of the whole clip, so every window of one animation shares its split.
    let object = object_uid(&clip.id).to_owned();
    let split = Split::of_object(&object, SPLIT_SEED);
    let mut out = Vec::new();
    for (k, w) in preprocess::windows(clip, frames, stride).iter().enumerate() {
        let (clip, normalization) = preprocess::normalize(w);
        let finite = normalization.center.iter().all(|c| c.is_finite())
            && normalization.scale.is_finite()
            && normalization.scale > 0.0
            && clip.vertices.iter().flatten().all(|x| x.is_finite());
        if !finite {
            return Err(DataError::new(
                &clip.source,
                "vertices",
                format!(
                    "normalising window {k} by its frame 0 (centre {:?}, scale {}) gives non-finite \
                     coordinates: values this large overflow f32; rescale the file",
                    normalization.center, normalization.scale
                ),
            ));
        }
        let scene = match scene.map(|s| s.normalized(&normalization)) {
            Some(None) => {
                return Err(DataError::new(
                    &clip.source,
                    "scene",
                    format!("normalising the scene by window {k}'s frame 0 gives non-finite coordinates"),
                ));
            }
            Some(s) => s,
            None => None,
        };
        let fps = farthest_point_sampling(clip.frame(0), p);
        out.push((
            StoredClip {
                clip,
                fps,
                normalization,
                split,
                scene,
            },
            object.clone(),
        ));
    }
    Ok(out)
}

/// The scene of the import source `source`: the `.scene.obj` beside it ([`crate::scene::scene_beside`]), else, for a glTF file,
/// its still meshes ([`crate::scene::Scene::read_gltf`]); `None` when it has neither.
pub(super) fn scene_of(source: &Path) -> Result<Option<crate::scene::Scene>> {
    if let Some(obj) = crate::scene::scene_beside(source) {
        return crate::scene::Scene::read_obj(&obj).map(Some);
    }
    let ext = source.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("gltf" | "glb") if source.is_file() => crate::scene::Scene::read_gltf(source),
        _ => Ok(None),
    }
}
