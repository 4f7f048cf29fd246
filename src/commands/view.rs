//! `any4d view`: clip files side by side in one self-contained HTML page (`any4d_eval::view`), scored against a
//! ground truth when one is given.

use std::path::PathBuf;
use std::process::ExitCode;

use any4d_data::formats::read_clip;
use any4d_eval::metrics::{Motion, Scoring, evaluate_clip_with};
use any4d_eval::view::{DEFAULT_FPS, Page, Panel, metric_lines, write_page};
use anyhow::{Context, bail};
use clap::Args;

#[derive(Args, Debug)]
pub struct ViewArgs {
    /// Clip files to show (any readable format), one panel each, in order.
    pub files: Vec<PathBuf>,
    /// Ground truth: shown first; the other clips of its vertex count are coloured by their distance to it and
    /// scored on the non-keyframes (docs/method.md §6.2).
    #[arg(long)]
    pub gt: Option<PathBuf>,
    /// Keyframes, marked on the timeline (and excluded from the scores); default none.
    #[arg(long, value_delimiter = ',')]
    pub keyframes: Vec<usize>,
    /// Caption shown under the title (default: the first clip's).
    #[arg(long)]
    pub caption: Option<String>,
    /// Page title.
    #[arg(long, default_value = "any4d view")]
    pub title: String,
    /// Playback frames per second.
    #[arg(long, default_value_t = DEFAULT_FPS)]
    pub fps: f64,
    /// A static scene (`.obj` of closed parts, in the clips' coordinates), drawn in grey in every panel; each panel
    /// then lists its scene metrics (E8)–(E10) (docs/method.md §6.5).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Output HTML file.
    #[arg(long)]
    pub out: PathBuf,
}

/// The scene of a `--scene` argument, read (before any work that a broken file would waste).
pub fn read_scene(path: Option<&std::path::Path>) -> anyhow::Result<Option<any4d_data::scene::Scene>> {
    path.map(|p| any4d_data::scene::Scene::read_obj(p).with_context(|| format!("reading the scene {}", p.display())))
        .transpose()
}

/// Each panel's clip scored in `scene` ((E8)–(E10), lines appended to its metrics); a warning when the scene does
/// not overlap the first panel's clip.
pub fn score_in_scene(scene: &any4d_data::scene::Scene, panels: &mut [Panel]) -> anyhow::Result<()> {
    use any4d_eval::scene_metrics::{ContactThresholds, clip_scene_metrics};
    if let Some(first) = panels.first()
        && !scene.overlaps(&first.clip)
    {
        eprintln!(
            "warning: the scene does not overlap `{}` (other coordinates or units?)",
            first.label
        );
    }
    for p in panels.iter_mut() {
        let m = clip_scene_metrics(&p.clip, scene, ContactThresholds::default())
            .with_context(|| format!("scoring `{}` in the scene", p.label))?;
        p.metrics.extend(any4d_eval::view::scene_lines(&m));
    }
    Ok(())
}

fn label(path: &std::path::Path) -> String {
    path.file_name()
        .map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned())
}

/// `any4d view FILE… --out view.html`.
pub fn exec(args: ViewArgs) -> anyhow::Result<ExitCode> {
    if args.files.is_empty() && args.gt.is_none() {
        bail!("nothing to show: give clip files (and optionally --gt FILE)");
    }
    let scene = read_scene(args.scene.as_deref())?;
    let mut panels = Vec::new();
    let gt = match &args.gt {
        Some(path) => {
            let clip = read_clip(path).with_context(|| format!("reading the ground truth {}", path.display()))?;
            panels.push(Panel {
                label: format!("ground truth ({})", label(path)),
                clip: clip.clone(),
                metrics: Vec::new(),
            });
            Some(clip)
        }
        None => None,
    };
    for path in &args.files {
        let clip = read_clip(path).with_context(|| format!("reading {}", path.display()))?;
        let metrics = match &gt {
            Some(g) if g.n_vertices == clip.n_vertices && g.frames == clip.frames => {
                // A clip that cannot be scored (too few frames, every frame a keyframe) is still shown.
                let scored = Motion::from_clip(&clip).and_then(|pred| {
                    evaluate_clip_with(pred, Motion::from_clip(g)?, &args.keyframes, &Scoring::default())
                });
                match scored {
                    Ok(m) => metric_lines(&m),
                    Err(e) => {
                        eprintln!("note: {} is shown without scores: {e}", path.display());
                        Vec::new()
                    }
                }
            }
            _ => Vec::new(),
        };
        panels.push(Panel {
            label: label(path),
            clip,
            metrics,
        });
    }
    let caption = args.caption.clone().unwrap_or_else(|| panels[0].clip.caption.clone());
    if let Some(scene) = &scene {
        score_in_scene(scene, &mut panels)?;
    }
    let page = Page {
        title: args.title.clone(),
        caption,
        keyframes: args.keyframes.clone(),
        ground_truth: gt.is_some(),
        panels,
        fps: args.fps,
        scene,
    };
    write_page(&page, &args.out)?;
    println!("wrote {} ({} panels)", args.out.display(), page.panels.len());
    Ok(ExitCode::SUCCESS)
}
