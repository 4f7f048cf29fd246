#[test]
fn look() {
    use any4d_data::store::write_synth_with;
    use any4d_data::synth::SynthConfig;
    use any4d_eval::methods::MethodKind;
    use any4d_eval::run::{RunOptions, run_protocol, vertex_methods};
    let root = std::path::Path::new("/tmp/h8/look");
    let _ = std::fs::remove_dir_all(root);
    let store16 = root.join("store16");
    let cfg = SynthConfig { clips: 60, seed: 5, frames: 16, min_vertices: 512, max_vertices: 900 };
    write_synth_with(&cfg, &store16, 16, None).unwrap();
    let mut opts = RunOptions::new(any4d_eval::tables::TableKind::Table1, store16.clone(), root.join("t1"));
    opts.methods = vertex_methods(&[MethodKind::Lerp, MethodKind::StaticNearest]).unwrap();
    opts.clips = 8;
    opts.seeds = vec![42, 43, 44];
    opts.export_items = 1;
    opts.progress = false;
    let r = run_protocol(&opts).unwrap();
    println!("{}", r.markdown);
    let store31 = root.join("store31");
    write_synth_with(&SynthConfig { frames: 31, ..cfg }, &store31, 16, None).unwrap();
    let mut t2 = RunOptions::new(any4d_eval::tables::TableKind::Table2, store31, root.join("t2"));
    t2.methods = vertex_methods(&[MethodKind::Lerp, MethodKind::StaticNearest]).unwrap();
    t2.clips = 8;
    t2.export_items = 1;
    t2.progress = false;
    println!("{}", run_protocol(&t2).unwrap().markdown);
}
