//! Table tests: confidence intervals, grouping over seeds, Markdown/CSV shape, parquet round trip, timing medians,
//! and the PNG plot.

use std::collections::BTreeMap;

use any4d_eval::plot::{Canvas, PALETTE, Series, WHITE, line_plot, nice_ticks};
use any4d_eval::tables::short_horizon::LAYOUT as TABLE1;
use any4d_eval::tables::summary::{ClipRecord, TableHeader, csv, markdown, mean_ci95, summarize, write_clip_parquet};
use any4d_eval::tables::timing::{TimingRecord, timing_tables};
use any4d_model::bench::median;
use polars::prelude::{ParquetReader, SerReader};

fn record(method: &str, k: usize, seed: u64, item: usize, rmse: f64) -> ClipRecord {
    let metrics: BTreeMap<String, f64> = [
        ("rmse", rmse),
        ("chamfer", 2.0 * rmse),
        ("dtw", 0.5 * rmse),
        ("mae_elem", 0.8 * rmse),
        ("jerk_ratio", 1.0),
        ("jerk", 0.3),
        ("jerk_gt", 0.3),
        ("energy_ratio", 0.9),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    ClipRecord {
        method: method.into(),
        placement: "random".into(),
        k_extra: k,
        seed,
        item,
        clip_id: format!("c{item}"),
        metrics,
    }
}

fn header() -> TableHeader {
    TableHeader {
        data: "synthetic store (validation)".into(),
        manifest: "out/manifest.json".into(),
        text_encoder: "scratch".into(),
        checkpoints: [("keyframe_rf".to_string(), "runs/rf-1/checkpoints/step_100".to_string())]
            .into_iter()
            .collect(),
        device: String::new(),
        notes: Vec::new(),
    }
}

#[test]
fn ci_uses_student_t_with_n_minus_one_dof() {
    let e = mean_ci95(&[1.0, 2.0, 3.0]);
    assert_eq!(e.mean, 2.0);
    // sd = 1, t(0.975, 2) = 4.303, half-width = 4.303 / √3.
    assert!((e.ci95.unwrap() - 4.303 / 3f64.sqrt()).abs() < 1e-9);
    assert_eq!(mean_ci95(&[5.0]).ci95, None);
    let many: Vec<f64> = (0..100).map(|i| (i % 2) as f64).collect();
    let e = mean_ci95(&many);
    let sd = (25.0f64 / 99.0).sqrt();
    assert!(
        (e.ci95.unwrap() - 1.96 * sd / 10.0).abs() < 1e-9,
        "normal quantile beyond 30 dof"
    );
}

#[test]
fn summary_averages_clips_per_seed_then_seeds() {
    let records = vec![
        record("keyframe_rf", 0, 42, 0, 0.02),
        record("keyframe_rf", 0, 42, 1, 0.04), // seed 42 mean 0.03
        record("keyframe_rf", 0, 43, 0, 0.05),
        record("keyframe_rf", 0, 43, 1, 0.05), // seed 43 mean 0.05
        record("lerp", 0, 42, 0, 0.1),
        record("keyframe_rf", 1, 42, 0, 0.01),
    ];
    let rows = summarize(&records, &TABLE1).unwrap();
    let labels: Vec<(&str, usize)> = rows.iter().map(|r| (r.method.as_str(), r.k_extra)).collect();
    assert_eq!(labels, vec![("keyframe_rf", 0), ("keyframe_rf", 1), ("lerp", 0)]);
    let rmse = rows[0].values[0];
    assert!((rmse.mean - 0.04).abs() < 1e-12 && rmse.n == 2 && rows[0].clips == 2);
    assert!((rmse.ci95.unwrap() - 12.706 * (0.0002f64).sqrt() / 2f64.sqrt()).abs() < 1e-9);

    let md = markdown(&TABLE1, &rows, &header());
    for needle in [
        "scratch",
        "runs/rf-1/checkpoints/step_100",
        "synthetic store",
        "out/manifest.json",
        "RMSE ×100",
        "Student t",
    ] {
        assert!(md.contains(needle), "missing {needle:?} in\n{md}");
    }
    assert!(
        md.contains("| keyframe_rf | random | 0 | 2 | 4.0000 ± "),
        "×100 scaling:\n{md}"
    );
    assert!(
        md.contains("| lerp | random | 0 | 1 | 10.0000 |"),
        "one seed, no interval:\n{md}"
    );

    let text = csv(&TABLE1, &rows, &header());
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 4);
    let cols = lines[0].split(',').count();
    assert!(lines.iter().all(|l| l.split(',').count() == cols), "{text}");
    assert!(lines[1].starts_with("keyframe_rf,random,0,2,2,"), "{}", lines[1]);
    let rmse_mean: f64 = lines[1].split(',').nth(5).unwrap().parse().unwrap();
    assert!((rmse_mean - 4.0).abs() < 1e-9, "×100 in the CSV too: {}", lines[1]);
    assert!(
        lines[3].contains(",none,scratch,"),
        "training-free methods name no checkpoint: {}",
        lines[3]
    );
}

/// The pooled jerk column is Σ jerk / Σ ground-truth jerk per seed: a clip whose ground truth barely moves dominates
/// the mean of per-clip ratios but not the pooled ratio; a seed whose ground truth never moves gives NaN.
#[test]
fn pooled_jerk_is_a_ratio_of_sums_per_seed() {
    let with_jerk = |seed, item, jerk: f64, gt: f64| {
        let mut r = record("keyframe_rf", 0, seed, item, 0.1);
        r.metrics.insert("jerk".into(), jerk);
        r.metrics.insert("jerk_gt".into(), gt);
        r.metrics.insert("jerk_ratio".into(), jerk / gt);
        r
    };
    let records = vec![
        with_jerk(42, 0, 1.0, 0.001),
        with_jerk(42, 1, 2.0, 1.0),
        with_jerk(43, 0, 3.0, 1.0),
        with_jerk(43, 1, 3.0, 2.0),
    ];
    let rows = summarize(&records, &TABLE1).unwrap();
    let at = |key: &str| TABLE1.columns.iter().position(|c| c.key == key).expect(key);
    let (mean_of_ratios, pooled) = (rows[0].values[at("jerk_ratio")], rows[0].values[at("jerk_pooled")]);
    assert!(
        (mean_of_ratios.mean - (501.0 + 2.25) / 2.0).abs() < 1e-9,
        "{mean_of_ratios:?}"
    );
    assert!(
        (pooled.mean - (3.0 / 1.001 + 6.0 / 3.0) / 2.0).abs() < 1e-9,
        "{pooled:?}"
    );
    assert!(
        csv(&TABLE1, &rows, &header())
            .lines()
            .next()
            .unwrap()
            .contains(",jerk_pooled_mean,")
    );
    let still = summarize(&[with_jerk(42, 0, 1.0, 0.0)], &TABLE1).unwrap();
    assert!(still[0].values[at("jerk_pooled")].mean.is_nan());
}

#[test]
fn missing_metric_is_named() {
    let mut r = record("lerp", 0, 42, 3, 0.1);
    r.metrics.remove("dtw");
    let e = summarize(&[r], &TABLE1).unwrap_err();
    assert_eq!((e.what(), e.field()), ("c3", "dtw"));
}

#[test]
fn parquet_round_trips_per_clip_records() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("clips.parquet");
    let records = vec![record("lerp", 0, 42, 0, 0.1), record("lerp", 1, 42, 0, 0.07)];
    write_clip_parquet(&records, &path).unwrap();
    let df = ParquetReader::new(std::fs::File::open(&path).unwrap())
        .finish()
        .unwrap();
    assert_eq!(df.height(), 2);
    let rmse = df.column("rmse").unwrap().f64().unwrap().get(1).unwrap();
    assert_eq!(rmse, 0.07);
    assert_eq!(df.column("method").unwrap().str().unwrap().get(0), Some("lerp"));
    assert_eq!(any4d_eval::tables::summary::read_clip_parquet(&path).unwrap(), records);
    let mut bad = records.clone();
    bad[1].metrics.insert("extra".into(), 1.0);
    assert_eq!(write_clip_parquet(&bad, &path).unwrap_err().field(), "metrics");
}

#[test]
fn timing_table_reports_medians() {
    assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
    assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
    let recs = vec![
        TimingRecord {
            method: "keyframe_rf".into(),
            frames: 16,
            vertices: 512,
            seconds: vec![1.0, 9.0, 2.0],
        },
        TimingRecord {
            method: "keyframe_rf".into(),
            frames: 16,
            vertices: 1024,
            seconds: vec![4.0, 4.0, 4.0],
        },
    ];
    let h = TableHeader {
        device: "flex / cpu".into(),
        ..header()
    };
    let (md, csv) = timing_tables(&recs, &h);
    assert!(md.contains("| keyframe_rf | 16 | 2.000 | 4.000 | 3.000 |"), "{md}");
    assert!(md.contains("flex / cpu"), "{md}");
    assert_eq!(csv.lines().nth(1).unwrap(), "keyframe_rf,16,2,4,3,flex / cpu");
}

#[test]
fn plot_writes_a_png_with_series_colours() {
    assert_eq!(nice_ticks(0.0, 9.0, 5), vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rmse.png");
    let series = vec![
        Series {
            label: "ours".into(),
            points: vec![(0.0, 2.9), (1.0, 2.0), (2.0, 1.86), (3.0, 1.85)],
            errors: Some(vec![0.1; 4]),
        },
        Series {
            label: "baseline".into(),
            points: vec![(0.0, 9.0), (1.0, 8.1), (2.0, 7.2), (3.0, 6.4)],
            errors: None,
        },
    ];
    line_plot("RMSE x100 vs K_x", "K_x", "RMSE x100", &series, &path).unwrap();
    let img = image::open(&path).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (720, 480));
    for colour in [PALETTE[0], PALETTE[1]] {
        assert!(img.pixels().any(|p| p.0 == colour), "series colour {colour:?} drawn");
    }
    let nan = vec![Series {
        label: "bad".into(),
        points: vec![(0.0, f64::NAN)],
        errors: None,
    }];
    assert_eq!(line_plot("t", "x", "y", &nan, &path).unwrap_err().field(), "bad");
}

#[test]
fn font_draws_distinct_glyphs() {
    let draw = |s: &str| {
        let mut c = Canvas::new(12, 8, WHITE);
        c.text(0, 0, s, [0, 0, 0], 1);
        c.img.pixels().filter(|p| p.0 != WHITE).count()
    };
    assert_eq!(draw(" "), 0);
    assert_eq!(draw("1"), 10);
    assert_ne!(draw("8"), draw("0"));
    assert_eq!(draw("a"), draw("A"), "lower case uses the upper-case glyphs");
}

/// End to end on a small procedural store: `run_protocol` writes the manifest, parquet, summaries, plot and strips.
#[test]
fn run_protocol_writes_table1_and_table2_outputs_on_a_synthetic_store() {
    use any4d_data::store::write_synth_with;
    use any4d_data::synth::SynthConfig;
    use any4d_eval::methods::{MethodKind, vertex_methods};
    use any4d_eval::tables::long_horizon::LongHorizon;
    use any4d_eval::tables::short_horizon::ShortHorizon;
    use any4d_eval::tables::{Items, Protocol, TableOptions, run_protocol};

    let dir = tempfile::tempdir().unwrap();
    let store16 = dir.path().join("store16");
    let cfg = SynthConfig {
        clips: 30,
        seed: 5,
        frames: 16,
        min_vertices: 512,
        max_vertices: 768,
        body: None,
        family: Default::default(),
        scenes: false,
    };
    write_synth_with(&cfg, &store16, 16, None).unwrap();
    let methods = [MethodKind::Lerp, MethodKind::StaticNearest];

    let out = dir.path().join("t1");
    let mut opts = TableOptions::new(store16.clone(), out.clone());
    opts.methods = vertex_methods(&methods).unwrap();
    opts.export_items = 1;
    opts.progress = false;
    let table1 = Protocol::ShortHorizon(ShortHorizon {
        items: Items {
            clips: 3,
            ..Items::default()
        },
        ..ShortHorizon::default()
    });
    let report = run_protocol(&table1, &opts).unwrap();
    assert_eq!(report.rows.len(), 2 * 4, "two methods × K_x 0..3");
    let lerp_rmse: Vec<f64> = report
        .rows
        .iter()
        .filter(|r| r.method == "lerp")
        .map(|r| r.values[0].mean)
        .collect();
    let nearest_rmse: Vec<f64> = report
        .rows
        .iter()
        .filter(|r| r.method == "static_nearest")
        .map(|r| r.values[0].mean)
        .collect();
    assert!(
        lerp_rmse.iter().zip(&nearest_rmse).all(|(l, s)| l <= s),
        "lerp beats holding keyframes: {lerp_rmse:?} {nearest_rmse:?}"
    );
    for f in [
        "manifest.json",
        "clips.parquet",
        "summary.md",
        "summary.csv",
        "rmse_vs_kx.png",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let strips: Vec<_> = std::fs::read_dir(out.join("strips")).unwrap().collect();
    assert_eq!(strips.len(), 2 * 4, "one strip per method and K_x for the first item");
    // One viewer page per K_x of the first item, every method beside the ground truth.
    let mut views: Vec<String> = std::fs::read_dir(out.join("view"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    views.sort();
    assert_eq!(views.len(), 4, "{views:?}");
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(!md.contains("stage-2"), "table 1 has no second stage: {md}");
    let page = std::fs::read_to_string(out.join("view").join(&views[0])).unwrap();
    assert_eq!(page.matches("\"label\":").count(), 3, "ground truth + 2 methods");
    assert!(page.contains("RMSE ×100"));
    let df = ParquetReader::new(std::fs::File::open(out.join("clips.parquet")).unwrap())
        .finish()
        .unwrap();
    assert_eq!(df.height(), 3 * 4 * 2);

    // Re-running on the saved manifest gives the same table.
    let mut again = TableOptions::new(store16, dir.path().join("t1b"));
    again.methods = vertex_methods(&methods).unwrap();
    again.export_items = 0;
    again.progress = false;
    let saved = Protocol::ShortHorizon(ShortHorizon {
        items: Items {
            manifest: Some(out.join("manifest.json")),
            ..Items::default()
        },
        ..ShortHorizon::default()
    });
    assert_eq!(run_protocol(&saved, &again).unwrap().rows, report.rows);

    // Table 2 on a store of 31-frame clips: the rollout path and the seam column.
    let store31 = dir.path().join("store31");
    write_synth_with(&SynthConfig { frames: 31, ..cfg }, &store31, 16, None).unwrap();
    let mut t2 = TableOptions::new(store31, dir.path().join("t2"));
    t2.methods = vertex_methods(&[MethodKind::Lerp]).unwrap();
    t2.export_items = 1;
    t2.progress = false;
    let table2 = Protocol::LongHorizon(LongHorizon {
        items: Items {
            clips: 2,
            ..Items::default()
        },
        ..LongHorizon::default()
    });
    let report = run_protocol(&table2, &t2).unwrap();
    assert_eq!(report.rows.len(), 1);
    assert!(report.markdown.contains("seam jerk / GT"), "{}", report.markdown);
    assert!(
        report
            .markdown
            .contains("stage-2 reference: the ground-truth overlap frame"),
        "the summary names the stage-2 reference: {}",
        report.markdown
    );
    assert!(
        report.rows[0].values.iter().all(|v| v.mean.is_finite()),
        "{:?}",
        report.rows[0]
    );
}

#[test]
fn timing_table_runs_for_a_training_free_method() {
    use any4d_eval::methods::{MethodKind, vertex_methods};
    use any4d_eval::tables::timing::{Timing, timing_clip};
    use any4d_eval::tables::{Protocol, TableOptions, run_protocol};
    let c = timing_clip(512, 16).unwrap();
    assert_eq!((c.n_vertices, c.frames), (512, 16));
    assert!(timing_clip(7, 16).is_err(), "a prime count has no 2-row grid");
    let dir = tempfile::tempdir().unwrap();
    let mut opts = TableOptions::new(dir.path().join("none"), dir.path().join("t4"));
    opts.methods = vertex_methods(&[MethodKind::Lerp]).unwrap();
    opts.progress = false;
    opts.header.device = "cpu (no model)".into();
    let table4 = Protocol::Timing(Timing {
        vertices: vec![512, 1024],
        reps: 3,
        ..Timing::default()
    });
    let report = run_protocol(&table4, &opts).unwrap();
    assert!(
        report.markdown.contains("| lerp | 16 |") && report.markdown.contains("| lerp | 31 |"),
        "{}",
        report.markdown
    );
    assert!(
        report.markdown.contains("Median of 3 timed runs"),
        "{}",
        report.markdown
    );
}

/// A method label with a dot (`impute_until_0.98`) must not be read as a file extension when exporting.
#[test]
fn export_writes_every_format_for_dotted_stems() {
    use any4d_eval::render::{ExportFormat, export_sequence};
    let tmp = tempfile::tempdir().unwrap();
    let tri: Vec<[f32; 3]> = (0..2)
        .flat_map(|f| [[0.0, 0.0, f as f32], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
        .collect();
    let clip = any4d_data::Clip::new("c", tri, 2, 3, vec![[0, 1, 2]], "cap", "test").unwrap();
    let paths = export_sequence(&clip, tmp.path(), "item000_impute_until_0.98_k0", &ExportFormat::ALL).unwrap();
    assert_eq!(paths.len(), 3);
    for p in &paths {
        assert!(p.exists(), "{} was not written", p.display());
        let back = any4d_data::formats::read_clip(p).unwrap();
        assert_eq!(back.vertices, clip.vertices, "{}", p.display());
    }
}

/// `--split`: each split draws its items only from its own clips (ids checked against the index), `all` draws from
/// both, and a split with too few clips is an error naming it.
#[test]
fn the_split_option_draws_items_from_that_split_only() {
    use any4d_data::store::{Split, read_index, write_synth_with};
    use any4d_data::synth::SynthConfig;
    use any4d_eval::protocol::{EvalSplit, Manifest, ManifestOptions, StoreSource};
    use std::collections::HashSet;

    let dir = tempfile::tempdir().unwrap();
    let store = dir.path().join("store");
    let cfg = SynthConfig {
        clips: 40,
        seed: 9,
        frames: 16,
        min_vertices: 512,
        max_vertices: 768,
        body: None,
        family: Default::default(),
        scenes: false,
    };
    write_synth_with(&cfg, &store, 16, None).unwrap();
    let index = read_index(&store).unwrap();
    let ids = |want: Option<Split>| -> HashSet<String> {
        index
            .iter()
            .filter(|r| want.is_none() || r.split == want)
            .map(|r| r.id.clone())
            .collect()
    };
    let (train, val) = (ids(Some(Split::Train)), ids(Some(Split::Val)));
    assert!(!train.is_empty() && !val.is_empty());
    for (split, allowed) in [
        (EvalSplit::Val, val.clone()),
        (EvalSplit::Train, train.clone()),
        (EvalSplit::All, ids(None)),
    ] {
        let source = StoreSource::open(&store, split).unwrap();
        let candidates = source.candidates(16);
        assert_eq!(candidates.len(), allowed.len(), "{split:?}");
        assert!(candidates.iter().all(|c| allowed.contains(&c.clip.id)), "{split:?}");
        let opts = ManifestOptions {
            n_clips: allowed.len().min(5),
            split: split.name().into(),
            ..ManifestOptions::table1("store")
        };
        let m = Manifest::build(&candidates, &opts, "store").unwrap();
        assert!(m.clips.iter().all(|c| allowed.contains(&c.clip.id)));
        let too_many = ManifestOptions {
            n_clips: allowed.len() + 1,
            ..opts
        };
        let err = Manifest::build(&candidates, &too_many, "store")
            .unwrap_err()
            .to_string();
        assert!(err.contains(split.name()), "{err}");
    }
    assert_eq!(EvalSplit::parse("val"), Ok(EvalSplit::Val));
    assert_eq!(EvalSplit::parse("all"), Ok(EvalSplit::All));
    assert!(EvalSplit::parse("test").unwrap_err().contains("val, train or all"));
}

/// A method that records the captions it is given (and returns its input).
struct CaptionLog(std::sync::Mutex<Vec<String>>);

impl any4d_eval::methods::Method for CaptionLog {
    fn kind(&self) -> any4d_eval::methods::MethodKind {
        any4d_eval::methods::MethodKind::KeyframeRf
    }

    fn complete(
        &self,
        clip: &any4d_data::Clip,
        _keyframes: &[usize],
        caption: &str,
        _seed: u64,
    ) -> Result<Vec<[f32; 3]>, any4d_eval::metrics::EvalError> {
        self.0.lock().unwrap().push(caption.to_string());
        Ok(clip.vertices.clone())
    }
}

/// `eval run --captions none`: every method gets the empty caption (the unconditional input) instead of the clip's,
/// and the table header says so; by default each clip's own caption arrives.
#[test]
fn the_caption_ablation_withholds_every_caption_and_says_so() {
    use std::sync::Arc;

    use any4d_data::store::write_synth_with;
    use any4d_data::synth::SynthConfig;
    use any4d_eval::methods::Method;
    use any4d_eval::tables::short_horizon::ShortHorizon;
    use any4d_eval::tables::{CaptionMode, Items, Protocol, TableOptions, run_protocol};

    /// Shares one log between the table (which owns its methods) and the test.
    struct Shared(Arc<CaptionLog>);
    impl Method for Shared {
        fn kind(&self) -> any4d_eval::methods::MethodKind {
            self.0.kind()
        }
        fn complete(
            &self,
            clip: &any4d_data::Clip,
            keyframes: &[usize],
            caption: &str,
            seed: u64,
        ) -> Result<Vec<[f32; 3]>, any4d_eval::metrics::EvalError> {
            self.0.complete(clip, keyframes, caption, seed)
        }
    }

    let dir = tempfile::tempdir().unwrap();
    let store = dir.path().join("store");
    let cfg = SynthConfig {
        clips: 20,
        seed: 3,
        frames: 16,
        min_vertices: 512,
        max_vertices: 768,
        body: None,
        family: Default::default(),
        scenes: false,
    };
    write_synth_with(&cfg, &store, 16, None).unwrap();
    let table1 = Protocol::ShortHorizon(ShortHorizon {
        items: Items {
            clips: 2,
            ..Items::default()
        },
        ..ShortHorizon::default()
    });
    for mode in [CaptionMode::Clip, CaptionMode::Empty] {
        let log = Arc::new(CaptionLog(std::sync::Mutex::new(Vec::new())));
        let mut opts = TableOptions::new(store.clone(), dir.path().join(format!("{mode:?}")));
        opts.methods = vec![Box::new(Shared(Arc::clone(&log)))];
        opts.export_items = 0;
        opts.progress = false;
        opts.captions = mode;
        let report = run_protocol(&table1, &opts).unwrap();
        let seen = log.0.lock().unwrap().clone();
        assert_eq!(seen.len(), 2 * 4, "{mode:?}: one call per clip and K_x");
        match mode {
            CaptionMode::Clip => {
                assert!(seen.iter().all(|c| !c.is_empty()), "{seen:?}");
                assert!(!report.markdown.contains("withheld"));
            }
            CaptionMode::Empty => {
                assert!(seen.iter().all(String::is_empty), "{seen:?}");
                assert!(
                    report.markdown.contains("every caption withheld"),
                    "{}",
                    report.markdown
                );
            }
        }
    }
}
