//! `any4d view` in a real browser: the page written for a ground truth and a prediction opens in headless Chromium
//! (Debian's `chromium`), reports `data-status="ready"` (every panel drew with WebGL, no script error), passes its
//! `#selftest` (the slider moves the frame, and two frames of the moving clip draw different pixels), and its
//! screenshot shows the meshes (non-white pixels inside the panels, coloured ones where the prediction is off) on
//! the grey floor of its scene.
//!
//! Without Chromium the test says so and passes, unless `ANY4D_REQUIRE_BROWSER=1` (set by `.ci/run`, which installs
//! it), where a missing browser fails.

use std::path::{Path, PathBuf};
use std::process::Command;

use any4d_data::formats::write_clip;
use any4d_data::synth::{SynthConfig, generate_one};

mod common;
use common::{any4d, text};

fn chromium() -> Option<PathBuf> {
    let found = ["/usr/bin/chromium", "/usr/bin/chromium-browser"]
        .iter()
        .map(PathBuf::from)
        .find(|p| p.is_file());
    if found.is_none() {
        assert!(
            std::env::var("ANY4D_REQUIRE_BROWSER").as_deref() != Ok("1"),
            "ANY4D_REQUIRE_BROWSER=1 but no Chromium at /usr/bin/chromium (apt-get install chromium)"
        );
        eprintln!("skipped: no Chromium at /usr/bin/chromium (apt-get install chromium to run this test)");
    }
    found
}

/// Headless Chromium with the flags this closed-network machine needs, a fresh profile, software WebGL.
fn browser(exe: &Path, profile: &Path) -> Command {
    let mut c = Command::new(exe);
    c.args([
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--enable-unsafe-swiftshader",
        "--use-angle=swiftshader",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--virtual-time-budget=4000",
        "--window-size=1400,900",
    ]);
    c.arg(format!("--user-data-dir={}", profile.display()));
    c
}

#[test]
fn the_view_page_plays_in_headless_chromium() {
    let Some(exe) = chromium() else { return };
    let dir = tempfile::tempdir().unwrap();
    let cfg = SynthConfig {
        clips: 1,
        seed: 3,
        frames: 16,
        min_vertices: 300,
        max_vertices: 700,
        body: None,
        family: Default::default(),
        scenes: false,
    };
    let gt = generate_one(&cfg, 0).unwrap();
    let mut pred = gt.clone();
    for (i, p) in pred.vertices.iter_mut().enumerate() {
        p[1] += 0.05 * ((i % 7) as f32 / 7.0);
    }
    let (gt_path, pred_path) = (dir.path().join("gt.glb"), dir.path().join("pred.glb"));
    write_clip(&gt_path, &gt).unwrap();
    write_clip(&pred_path, &pred).unwrap();
    // A floor under the clips (which stand on y = 0), drawn in grey in every panel.
    let floor = any4d_data::scene::Scene::cuboid([-3.0, -0.2, -3.0], [3.0, -0.001, 3.0]);
    let mut obj: String = floor
        .vertices
        .iter()
        .map(|v| format!("v {} {} {}\n", v[0], v[1], v[2]))
        .collect();
    floor
        .faces
        .iter()
        .for_each(|f| obj += &format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1));
    let scene = dir.path().join("floor.obj");
    std::fs::write(&scene, obj).unwrap();
    let page = dir.path().join("view.html");
    let out = any4d(&[
        "view",
        &pred_path.display().to_string(),
        "--gt",
        &gt_path.display().to_string(),
        "--keyframes",
        "0,7,15",
        "--scene",
        &scene.display().to_string(),
        "--out",
        &page.display().to_string(),
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    let html = std::fs::read_to_string(&page).unwrap();
    assert!(
        !html.contains("http://") && !html.contains("https://"),
        "the page needs no network"
    );

    let url = format!("file://{}", page.display());
    let dom = browser(&exe, &dir.path().join("profile-a"))
        .arg("--dump-dom")
        .arg(format!("{url}#selftest"))
        .output()
        .unwrap();
    let dom_text = String::from_utf8_lossy(&dom.stdout);
    assert!(
        dom_text.contains("data-status=\"ready\""),
        "page not ready: {}\nstderr: {}",
        dom_text.lines().find(|l| l.contains("<body")).unwrap_or("(no body)"),
        String::from_utf8_lossy(&dom.stderr)
    );
    let body = dom_text.lines().find(|l| l.contains("<body")).unwrap_or("(no body)");
    assert!(
        body.contains("data-selftest=\"pass\""),
        "the slider must move the frame and the pixels: {body}"
    );
    assert!(dom_text.contains("RMSE ×100"), "metrics shown");
    assert!(dom_text.contains("collision frames"), "scene metrics shown");
    assert_eq!(dom_text.matches("class=\"mark\"").count(), 3, "three keyframe marks");

    let shot = dir.path().join("shot.png");
    let status = browser(&exe, &dir.path().join("profile-b"))
        .arg(format!("--screenshot={}", shot.display()))
        .arg(&url)
        .output()
        .unwrap();
    assert!(
        shot.is_file(),
        "no screenshot: {}",
        String::from_utf8_lossy(&status.stderr)
    );
    if let Ok(keep) = std::env::var("ANY4D_VIEW_SHOT") {
        // To look at the page: ANY4D_VIEW_SHOT=/tmp/view.png (and the page beside it).
        std::fs::copy(&shot, &keep).unwrap();
        std::fs::copy(&page, format!("{keep}.html")).unwrap();
    }
    let img = image::open(&shot).unwrap().to_rgb8();
    let (mut drawn, mut coloured) = (0usize, 0usize);
    for p in img.pixels() {
        let [r, g, b] = p.0;
        let grey = r.abs_diff(g) < 12 && g.abs_diff(b) < 12;
        if (r as u32 + g as u32 + b as u32) < 700 && !(r > 235 && g > 235 && b > 235) {
            drawn += 1;
        }
        if !grey {
            coloured += 1;
        }
    }
    assert!(
        drawn > 5_000,
        "only {drawn} non-white pixels: the meshes were not drawn"
    );
    assert!(coloured > 1_000, "only {coloured} coloured pixels: no error colouring");
}
