use any4d_eval::metrics::*;
use std::time::Instant;
#[test]
fn timing() {
    let (t, n) = (16usize, 4096usize);
    let mut s = 1u64;
    let mut r = || { s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407); ((s >> 40) as f32) / (1u64 << 24) as f32 };
    let g: Vec<[f32;3]> = (0..t*n).map(|_| [r(), r(), r()]).collect();
    let p: Vec<[f32;3]> = g.iter().map(|q| [q[0]+0.01, q[1], q[2]]).collect();
    let (pm, gm) = (Motion::new(&p, t, n).unwrap(), Motion::new(&g, t, n).unwrap());
    let fr: Vec<usize> = (1..15).collect();
    macro_rules! tm { ($name:expr, $e:expr) => {{ let st = Instant::now(); let v = $e; eprintln!("{:<12} {:>8.1} ms", $name, st.elapsed().as_secs_f64()*1e3); v }} }
    tm!("check", check_pair(pm, gm).unwrap());
    tm!("rmse", rmse(pm, gm, &fr).unwrap());
    tm!("chamfer", chamfer(pm, gm, &fr).unwrap());
    tm!("chamfer1", chamfer_sets(pm.frame(1), gm.frame(1)).unwrap());
    tm!("dtw", centroid_dtw(pm, gm, &fr).unwrap());
    tm!("jerk", jerk(pm, 1.0).unwrap());
    tm!("norm", normalise_by_gt(pm, gm).unwrap());
    tm!("evaluate", evaluate_clip(pm, gm, &[0, 15]).unwrap());
}
