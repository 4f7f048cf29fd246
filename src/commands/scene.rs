//! `any4d eval scene`: the scene metrics (E8)–(E10) of a clip in a static scene (docs/method.md §6.5).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::Args;

use any4d_data::formats::read_clip;

#[derive(Args, Debug)]
pub struct SceneArgs {
    /// The clip (any format `data import` reads; the first take of a file with takes).
    pub clip: PathBuf,
    /// The scene: an `.obj` of closed (watertight), outward-wound parts, in the clip's coordinates.
    pub scene: PathBuf,
    /// Contact distance of (E10), in normalised units (frame 0's longest half-extent is 1).
    #[arg(long, default_value_t = 0.02)]
    pub contact: f64,
    /// Slide along the ground (x–z) per frame above which a touching vertex skates (E10), normalised units.
    #[arg(long, default_value_t = 0.01)]
    pub slide: f64,
    /// Print the raw values as one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn scene(args: SceneArgs) -> anyhow::Result<ExitCode> {
    use any4d_data::scene::Scene;
    use any4d_eval::scene_metrics::{ContactThresholds, clip_scene_metrics};
    let clip = read_clip(&args.clip).with_context(|| format!("reading the clip {}", args.clip.display()))?;
    let scene = Scene::read_obj(&args.scene).with_context(|| format!("reading the scene {}", args.scene.display()))?;
    if !scene.overlaps(&clip) {
        eprintln!(
            "warning: the scene {} and the clip {} do not overlap (other coordinates or units?)",
            args.scene.display(),
            args.clip.display()
        );
    }
    let thresholds = ContactThresholds {
        contact: args.contact,
        slide: args.slide,
    };
    // Both in the clip's normalised frame (D1)–(D3), where the thresholds are stated.
    let m = clip_scene_metrics(&clip, &scene, thresholds)
        .with_context(|| format!("scoring {} in {}", args.clip.display(), args.scene.display()))?;
    match args.json {
        true => println!("{}", serde_json::to_string_pretty(&m)?),
        false => {
            println!(
                "{} in {}: {} frames × {} vertices, {} scene triangles",
                args.clip.display(),
                args.scene.display(),
                clip.frames,
                clip.n_vertices,
                scene.faces.len()
            );
            for (name, v) in [
                ("collision frames (E8)", m.collision_frames),
                ("collision vertices (E8)", m.collision_vertices),
                ("max penetration (E9)", m.max_penetration),
                ("foot skating (E10)", m.foot_skating),
            ] {
                println!("{name:<26}{v:>12.4}");
            }
        }
    }
    Ok(ExitCode::SUCCESS)
}
