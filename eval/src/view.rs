//! `any4d view`: one self-contained HTML page that plays clips side by side in sync (ground truth and methods), with
//! an orbit camera, play/pause, a frame slider, keyframes marked on the timeline, per-vertex error colouring against
//! the ground truth, and the caption and metrics. The page needs no network: the clips are embedded as base64 f32/u32
//! arrays in a JSON block and drawn by the WebGL viewer in `view.js` (written here, no library).
//!
//! The page reports its state on `<body data-status=…>`: `loading`, then `ready` once every panel has drawn a frame,
//! `no-webgl` when the browser has no WebGL, or `error: …` (a script error); tests read it in headless Chromium.
//! Opened as `page.html#selftest`, the page also pauses, moves its slider to the middle frame and sets
//! `data-selftest` to `pass` when the frame, its label and the drawn pixels all changed (else `fail: …`).

use std::path::Path;

use any4d_data::Clip;
use base64::Engine;
use base64::engine::general_purpose::STANDARD;

use crate::error::{EvalError, Result};

/// The viewer script, inlined into every page.
const VIEWER_JS: &str = include_str!("view.js");

/// Frames per second of playback when a page does not say.
pub const DEFAULT_FPS: f64 = 15.0;

/// One clip shown in its own panel.
#[derive(Debug, Clone, PartialEq)]
pub struct Panel {
    /// Title of the panel (e.g. "ground truth", a method name, a file name).
    pub label: String,
    /// The clip, in any coordinates (every panel shares one camera framed on the first panel).
    pub clip: Clip,
    /// Metric lines shown under the panel: (name, formatted value).
    pub metrics: Vec<(String, String)>,
}

/// A page: panels in order, the first one the ground truth when `ground_truth` is set.
#[derive(Debug, Clone, PartialEq)]
pub struct Page {
    /// Page heading.
    pub title: String,
    /// The caption shown under the heading.
    pub caption: String,
    /// Keyframe indices, marked on the timeline.
    pub keyframes: Vec<usize>,
    /// Panel 0 is the ground truth: the other panels with its vertex count are coloured by their per-vertex
    /// distance to it at every frame.
    pub ground_truth: bool,
    /// The panels; all must have the same number of frames.
    pub panels: Vec<Panel>,
    /// Playback rate.
    pub fps: f64,
    /// A static scene drawn in grey in every panel (docs/method.md §6.5), in the panels' coordinates.
    pub scene: Option<any4d_data::scene::Scene>,
}

/// The metric lines of a panel in a scene: (E8)–(E10) (docs/method.md §6.5).
pub fn scene_lines(m: &crate::scene_metrics::SceneMetrics) -> Vec<(String, String)> {
    vec![
        ("collision frames".into(), format!("{:.3}", m.collision_frames)),
        ("collision vertices".into(), format!("{:.4}", m.collision_vertices)),
        ("max penetration".into(), format!("{:.4}", m.max_penetration)),
        ("foot skating".into(), format!("{:.3}", m.foot_skating)),
    ]
}

/// The metric lines of a panel scored against the ground truth: distances × 100 (docs/method.md §6.2) and the
/// jerk and motion-energy ratios.
pub fn metric_lines(m: &crate::metrics::ClipMetrics) -> Vec<(String, String)> {
    vec![
        ("RMSE ×100".into(), format!("{:.2}", 100.0 * m.rmse)),
        ("Chamfer ×100".into(), format!("{:.2}", 100.0 * m.chamfer)),
        ("DTW ×100".into(), format!("{:.2}", 100.0 * m.dtw)),
        ("jerk / GT".into(), format!("{:.2}", m.jerk_ratio)),
        ("motion / GT".into(), format!("{:.2}", m.energy_ratio)),
    ]
}

fn b64_f32(values: impl Iterator<Item = f32>) -> String {
    let bytes: Vec<u8> = values.flat_map(f32::to_le_bytes).collect();
    STANDARD.encode(bytes)
}

fn b64_u32(values: impl Iterator<Item = u32>) -> String {
    let bytes: Vec<u8> = values.flat_map(u32::to_le_bytes).collect();
    STANDARD.encode(bytes)
}

/// Per-vertex distance of `pred` to `gt` at every frame, `[T · N]` (same frame and vertex counts).
fn distances(pred: &Clip, gt: &Clip) -> Vec<f32> {
    pred.vertices
        .iter()
        .zip(&gt.vertices)
        .map(|(a, b)| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt())
        .collect()
}

/// The 95th percentile of `values` (0 for none): the colour scale's top, so one outlier does not wash it out.
fn p95(values: &[f32]) -> f32 {
    if values.is_empty() {
        return 0.0;
    }
    let mut v: Vec<f32> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return 0.0;
    }
    let k = ((v.len() - 1) as f64 * 0.95).round() as usize;
    let (_, x, _) = v.select_nth_unstable_by(k, f32::total_cmp);
    *x
}

/// JSON safe inside a `<script>` element: every `<` (which only occurs inside JSON strings) becomes `\u003c`, so
/// no text can close the element or open a comment in it.
fn escape_script(json: &str) -> String {
    json.replace('<', "\\u003c")
}

/// Writes the page as one HTML file. Errors when there is no panel, frame counts differ, a keyframe lies outside
/// the frames, or a coordinate is not finite.
pub fn write_page(page: &Page, path: &Path) -> Result<()> {
    let html = page_html(page)?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| EvalError::io(dir, e))?;
    }
    std::fs::write(path, html).map_err(|e| EvalError::io(path, e))
}

/// The page as HTML text (see [`write_page`]).
pub fn page_html(page: &Page) -> Result<String> {
    let bad = |field: &str, reason: String| Err(EvalError::invalid("view page", field, reason));
    let Some(first) = page.panels.first() else {
        return bad("panels", "nothing to show: no clip was given".into());
    };
    let frames = first.clip.frames;
    if let Some(p) = page.panels.iter().find(|p| p.clip.frames != frames) {
        return bad(
            "frames",
            format!(
                "`{}` has {} frames, `{}` has {frames}: panels play in sync and need the same length",
                p.label, p.clip.frames, first.label
            ),
        );
    }
    if let Some(&k) = page.keyframes.iter().find(|&&k| k >= frames) {
        return bad("keyframes", format!("frame {k} is outside the {frames} frames"));
    }
    if !(page.fps.is_finite() && page.fps > 0.0) {
        return bad("fps", format!("{} is not a positive frame rate", page.fps));
    }
    for p in &page.panels {
        p.clip.validate().map_err(|e| e.at(&p.label))?;
        if p.clip.vertices.iter().flatten().any(|x| !x.is_finite()) {
            return bad(&p.label, "a coordinate is not finite".into());
        }
    }
    let gt = page.ground_truth.then_some(&first.clip);
    let errors: Vec<Option<Vec<f32>>> = page
        .panels
        .iter()
        .enumerate()
        .map(|(i, p)| match gt {
            Some(g) if i > 0 && p.clip.n_vertices == g.n_vertices => Some(distances(&p.clip, g)),
            _ => None,
        })
        .collect();
    let all: Vec<f32> = errors.iter().flatten().flatten().copied().collect();
    let error_scale = p95(&all);
    let panels: Vec<serde_json::Value> = page
        .panels
        .iter()
        .zip(&errors)
        .map(|(p, err)| {
            serde_json::json!({
                "label": p.label,
                "frames": p.clip.frames,
                "vertices": p.clip.n_vertices,
                "positions": b64_f32(p.clip.vertices.iter().flatten().copied()),
                "faces": b64_u32(p.clip.faces.iter().flatten().copied()),
                "errors": err.as_ref().map(|e| b64_f32(e.iter().copied())),
                "metrics": p.metrics,
            })
        })
        .collect();
    if let Some(scene) = &page.scene
        && scene.vertices.iter().flatten().any(|x| !x.is_finite())
    {
        return bad("scene", "a coordinate is not finite".into());
    }
    let scene = page.scene.as_ref().map(|s| {
        serde_json::json!({
            "positions": b64_f32(s.vertices.iter().flatten().copied()),
            "faces": b64_u32(s.faces.iter().flatten().copied()),
        })
    });
    let data = serde_json::json!({
        "title": page.title,
        "caption": page.caption,
        "keyframes": page.keyframes,
        "frames": frames,
        "fps": page.fps,
        "ground_truth": page.ground_truth,
        "error_scale": error_scale,
        "panels": panels,
        "scene": scene,
    });
    let json = serde_json::to_string(&data).map_err(|e| EvalError::invalid("view page", "json", e.to_string()))?;
    Ok(format!(
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>{title}</title>\n<style>{STYLE}</style>\n\
         </head>\n<body data-status=\"loading\">\n<header><h1 id=\"title\"></h1><p id=\"caption\"></p></header>\n\
         <main id=\"panels\"></main>\n<footer id=\"controls\"><button id=\"play\" type=\"button\">Pause</button>\
         <div id=\"track\"><input id=\"slider\" type=\"range\" min=\"0\" value=\"0\" step=\"1\"><div id=\"marks\"></div></div>\
         <span id=\"frame\"></span><span id=\"legend\"></span></footer>\n\
         <script id=\"data\" type=\"application/json\">{data}</script>\n<script>{VIEWER_JS}</script>\n</body></html>\n",
        title = html_escape(&page.title),
        data = escape_script(&json),
    ))
}

fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

const STYLE: &str = "body{margin:0;font:14px system-ui,sans-serif;background:#f4f4f2;color:#222}\
header{padding:8px 16px}h1{font-size:18px;margin:4px 0}#caption{margin:0;color:#555;font-style:italic}\
#panels{display:flex;flex-wrap:wrap;gap:8px;padding:0 16px}.panel{background:#fff;border:1px solid #ccc;\
border-radius:4px;padding:4px}.panel h2{font-size:14px;margin:2px 4px}.panel canvas{display:block;cursor:grab}\
.panel table{font-size:12px;margin:2px 4px;border-collapse:collapse}.panel td{padding:0 6px 0 0}\
#controls{display:flex;align-items:center;gap:12px;padding:10px 16px}#track{position:relative;flex:1}\
#slider{width:100%}#marks{position:relative;height:10px}.mark{position:absolute;top:0;width:3px;height:10px;\
background:#e67800;transform:translateX(-1px)}#legend{font-size:12px;color:#555}";

#[cfg(test)]
mod tests {
    use super::*;

    fn clip(frames: usize, shift: f32) -> Clip {
        let n = 4;
        let vertices = (0..frames)
            .flat_map(|f| {
                [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
                    .map(|p: [f32; 3]| [p[0] + shift * f as f32, p[1], p[2]])
            })
            .collect();
        Clip::new("c", vertices, frames, n, vec![[0, 1, 2], [0, 1, 3]], "a cap", "test").unwrap()
    }

    fn page(panels: Vec<Panel>) -> Page {
        Page {
            title: "t <x>".into(),
            caption: "a </script> caption".into(),
            keyframes: vec![0, 2],
            ground_truth: true,
            panels,
            fps: DEFAULT_FPS,
            scene: None,
        }
    }

    fn panel(label: &str, clip: Clip) -> Panel {
        Panel {
            label: label.into(),
            clip,
            metrics: vec![("rmse".into(), "1.0".into())],
        }
    }

    #[test]
    fn the_page_embeds_every_clip_and_escapes_text() {
        let html = page_html(&page(vec![panel("gt", clip(3, 0.0)), panel("ours", clip(3, 0.5))])).unwrap();
        assert!(html.contains("<title>t &lt;x&gt;</title>"));
        assert!(
            !html.contains("a </script> caption"),
            "a caption cannot close the data block"
        );
        let start = html.find("application/json\">").unwrap() + "application/json\">".len();
        let end = start + html[start..].find("</script>").unwrap();
        let data: serde_json::Value = serde_json::from_str(&html[start..end]).unwrap();
        assert_eq!(
            data["caption"], "a </script> caption",
            "escaped, and the same text once parsed"
        );
        assert_eq!(data["panels"].as_array().unwrap().len(), 2);
        assert!(
            data["panels"][0]["errors"].is_null(),
            "the ground truth is not coloured"
        );
        let err = STANDARD.decode(data["panels"][1]["errors"].as_str().unwrap()).unwrap();
        assert_eq!(err.len(), 3 * 4 * 4, "one f32 per frame and vertex");
        // Frame 2 is shifted by 1.0 along x: every vertex is 1.0 away.
        let last = f32::from_le_bytes(err[err.len() - 4..].try_into().unwrap());
        assert!((last - 1.0).abs() < 1e-6, "{last}");
        let pos = STANDARD
            .decode(data["panels"][1]["positions"].as_str().unwrap())
            .unwrap();
        assert_eq!(pos.len(), 3 * 4 * 3 * 4);
        assert!(data["scene"].is_null());
        // A scene travels as its own positions and faces.
        let mut with = page(vec![panel("gt", clip(3, 0.0))]);
        with.scene = Some(any4d_data::scene::Scene::cuboid([-1.0, -0.1, -1.0], [2.0, 0.0, 2.0]));
        let html = page_html(&with).unwrap();
        let start = html.find("application/json\">").unwrap() + "application/json\">".len();
        let end = start + html[start..].find("</script>").unwrap();
        let data: serde_json::Value = serde_json::from_str(&html[start..end]).unwrap();
        let faces = STANDARD.decode(data["scene"]["faces"].as_str().unwrap()).unwrap();
        assert_eq!(faces.len(), 12 * 3 * 4);
    }

    #[test]
    fn pages_that_cannot_play_are_refused() {
        let e = page_html(&page(vec![])).unwrap_err();
        assert!(e.reason().contains("no clip"), "{e}");
        let e = page_html(&page(vec![panel("gt", clip(3, 0.0)), panel("long", clip(4, 0.0))])).unwrap_err();
        assert!(e.reason().contains("same length") && e.reason().contains("long"), "{e}");
        let mut p = page(vec![panel("gt", clip(3, 0.0))]);
        p.keyframes = vec![0, 3];
        assert!(page_html(&p).unwrap_err().reason().contains("frame 3"));
        let mut bad = clip(3, 0.0);
        bad.vertices[5][1] = f32::NAN;
        assert!(page_html(&page(vec![panel("nan", bad)])).is_err());
    }

    #[test]
    fn error_scale_is_the_95th_percentile() {
        let mut v: Vec<f32> = (0..100).map(|i| i as f32).collect();
        v.push(f32::NAN);
        assert_eq!(p95(&v), 94.0);
        assert_eq!(p95(&[]), 0.0);
    }
}
