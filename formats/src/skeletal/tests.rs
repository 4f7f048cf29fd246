//! Tests of the shared skeletal helpers: sidecars, transforms and quaternions, influences, picking takes.

use super::*;

#[test]
fn companions_are_regular_files_inside_their_folder() {
    let dir = tempfile::tempdir().unwrap();
    let elsewhere = tempfile::tempdir().unwrap();
    std::fs::write(elsewhere.path().join("far.md5anim"), "x").unwrap();
    let mesh = dir.path().join("m.md5mesh");
    std::fs::write(&mesh, "x").unwrap();
    std::fs::write(dir.path().join("walk.md5anim"), "x").unwrap();
    std::fs::create_dir(dir.path().join("sub")).unwrap();
    std::fs::write(dir.path().join("sub/run.md5anim"), "x").unwrap();
    let link = |target: &Path, name: &str| std::os::unix::fs::symlink(target, dir.path().join(name)).unwrap();
    link(&elsewhere.path().join("far.md5anim"), "far.md5anim");
    link(Path::new("/dev/zero"), "zero.md5anim");
    link(&dir.path().join("sub/run.md5anim"), "run.md5anim");
    link(&dir.path().join("sub"), "folder.md5anim");
    let found: Vec<String> = companions(&mesh, &["md5anim"], false)
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    // A link inside the folder is followed; links out of it, to a device or to a folder are not.
    assert_eq!(found, ["run.md5anim", "walk.md5anim"]);
}

fn close(a: [f64; 3], b: [f64; 3]) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9)
}

#[test]
fn trs_inverse_and_quaternions_agree() {
    let s = 0.5f64.sqrt();
    let q = [0.0, 0.0, s, s]; // 90° about z
    let m = trs([1.0, 2.0, 3.0], q, [2.0, 2.0, 2.0]);
    assert!(close(apply(&m, [1.0, 0.0, 0.0]), [1.0, 4.0, 3.0]));
    assert!(close(quat_rotate(q, [1.0, 0.0, 0.0]), [0.0, 1.0, 0.0]));
    let inv = inverse(&m).unwrap();
    assert!(close(apply(&inv, apply(&m, [0.3, -0.7, 5.0])), [0.3, -0.7, 5.0]));
    let qq = quat_mul(q, q); // 180° about z
    assert!(close(quat_rotate(qq, [1.0, 0.0, 0.0]), [-1.0, 0.0, 0.0]));
    assert!(inverse(&[[0.0; 4]; 4]).is_none());
}

#[test]
fn globals_chain_parents() {
    let parents = check_parents(Path::new("f"), "joints", &[-1, 0, 1]).unwrap();
    let l = trs([1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], [1.0; 3]);
    let g = globals(&parents, &[l, l, l]);
    assert!(close(apply(&g[2], [0.0; 3]), [3.0, 0.0, 0.0]));
    let e = check_parents(Path::new("f"), "joints", &[-1, 2, 0]).unwrap_err();
    assert!(e.reason.contains("does not precede"), "{e}");
}

#[test]
fn influences_are_counted_renormalised_and_checked() {
    let mut infl: Influences = vec![
        vec![(0, 0.5), (1, 0.5)],
        vec![(0, 0.2), (1, 0.2), (2, 0.2), (3, 0.2), (4, 0.1)], // 5 weights summing to 0.9
        vec![(1, 2.0)],
    ];
    let stats = clean_influences(Path::new("f"), "weights", &mut infl, 5).unwrap();
    assert_eq!((stats.vertices, stats.over_four_weights, stats.renormalised), (3, 1, 2));
    assert!((infl[1].iter().map(|x| x.1).sum::<f64>() - 1.0).abs() < 1e-12);
    assert_eq!(infl[2], vec![(1, 1.0)]);
    let mut missing: Influences = vec![vec![(7, 1.0)]];
    let e = clean_influences(Path::new("f"), "weights", &mut missing, 5).unwrap_err();
    assert!(e.reason.contains("joint 7") && e.reason.contains("5 joints"), "{e}");
    let mut none: Influences = vec![vec![(0, 0.0)]];
    assert!(clean_influences(Path::new("f"), "weights", &mut none, 1).is_err());
}

#[test]
fn picks_takes_by_index_and_name() {
    let t = |n: &str| TakeInfo {
        name: n.into(),
        frames: 10,
        fps: 30.0,
        file: None,
    };
    let takes = [t("idle"), t("walk")];
    let p = Path::new("a.iqm");
    assert_eq!(pick(p, &takes, &TakeSel::parse("walk")).unwrap(), 1);
    assert_eq!(pick(p, &takes, &TakeSel::parse("1")).unwrap(), 1);
    let e = pick(p, &takes, &TakeSel::parse("run")).unwrap_err();
    assert!(e.reason.contains("0: idle, 1: walk"), "{e}");
    let e = pick(p, &[], &TakeSel::First).unwrap_err();
    assert!(e.reason.contains("static mesh is not a clip"), "{e}");
    assert!(
        check_frames(p, "walk", 5000, MAX_FRAMES)
            .unwrap_err()
            .reason
            .contains("maximum")
    );
}
