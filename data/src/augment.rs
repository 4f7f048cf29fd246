//! Training-time augmentation of stored clips (docs/method.md §2.9): slower playback, time reversal, larger or
//! smaller motion about frame 0, mirror, anisotropic scale and a random turn about the up axis, drawn per example from the caller's generator and
//! re-normalised by (D1)–(D3). Off unless a config asks for it; the paper presets never do.

use serde::{Deserialize, Serialize};

use crate::preprocess::Normalization;
use crate::rng::Rng;
use crate::store::StoredClip;

/// Largest anisotropic scale factor a config may ask for.
pub const MAX_SCALE: f32 = 10.0;

/// Largest factor a config may scale motion about frame 0 by.
pub const MAX_MOTION: f32 = 4.0;

/// Which augmentations apply, and how strongly. The default does nothing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Augment {
    /// A turn about the up axis (y) drawn uniformly in `[−yaw_degrees, yaw_degrees]`; 0 = off, 180 = any heading.
    pub yaw_degrees: f32,
    /// Probability of mirroring across the x = 0 plane (each face's winding reversed so that it still faces out).
    pub mirror: f32,
    /// Per-axis scale factors, each drawn uniformly in `[scale[0], scale[1]]`; `[1, 1]` = off.
    pub scale: [f32; 2],
    /// Probability of playing the window backwards.
    pub reverse: f32,
    /// Playback speed drawn log-uniformly in `[speed[0], speed[1]]`, at most 1: frame i shows the window at time
    /// `i · speed`, interpolated linearly between stored frames (a window holds no frames past its end, so faster
    /// playback would need the source's next frames); `[1, 1]` = off.
    pub speed: [f32; 2],
    /// Motion about frame 0 scaled by a factor drawn uniformly in `[motion[0], motion[1]]`: every vertex of frame f
    /// moves to x₀ + a (x_f − x₀), frame 0 kept (larger displacements than the store holds when a > 1);
    /// `[1, 1]` = off.
    pub motion: [f32; 2],
}

impl Default for Augment {
    fn default() -> Self {
        Self {
            yaw_degrees: 0.0,
            mirror: 0.0,
            scale: [1.0, 1.0],
            reverse: 0.0,
            speed: [1.0, 1.0],
            motion: [1.0, 1.0],
        }
    }
}

impl Augment {
    /// True when [`Augment::apply`] changes nothing (and draws nothing).
    pub fn is_off(&self) -> bool {
        *self == Self::default()
    }

    /// Refuses values that are not finite, negative or empty ranges, probabilities outside [0, 1], a turn past 180
    /// degrees, scales outside (0, [`MAX_SCALE`]], speeds outside (0, 1] and motion factors outside
    /// (0, [`MAX_MOTION`]]; the error names the key (under
    /// `prefix`, e.g. `vae.augment`).
    pub fn validate(&self, prefix: &str) -> Result<(), String> {
        let bad = |key: &str, why: String| Err(format!("{prefix}.{key}: {why}"));
        let all = [
            self.yaw_degrees,
            self.mirror,
            self.reverse,
            self.scale[0],
            self.scale[1],
            self.speed[0],
            self.speed[1],
            self.motion[0],
            self.motion[1],
        ];
        if all.iter().any(|x| !x.is_finite()) {
            return bad("*", format!("every value must be finite, got {self:?}"));
        }
        if !(0.0..=180.0).contains(&self.yaw_degrees) {
            return bad("yaw_degrees", format!("must be in [0, 180], got {}", self.yaw_degrees));
        }
        for (key, p) in [("mirror", self.mirror), ("reverse", self.reverse)] {
            if !(0.0..=1.0).contains(&p) {
                return bad(key, format!("a probability in [0, 1], got {p}"));
            }
        }
        let range = |key: &str, [lo, hi]: [f32; 2], max: f32| {
            if !(lo > 0.0 && lo <= hi && hi <= max) {
                return bad(key, format!("needs 0 < low ≤ high ≤ {max}, got [{lo}, {hi}]"));
            }
            Ok(())
        };
        range("scale", self.scale, MAX_SCALE)?;
        range("speed", self.speed, 1.0)?;
        range("motion", self.motion, MAX_MOTION)
    }

    /// Augments one stored clip in place, drawing from `rng` only for the augmentations that are on, and
    /// re-normalises it by its new frame 0. Vertex order, FPS indices, caption and split are kept; the item's
    /// `normalization` still describes the stored clip (an augmented item is for training, never un-normalised).
    pub fn apply<R: Rng>(&self, item: &mut StoredClip, rng: &mut R) {
        if self.is_off() {
            return;
        }
        let clip = &mut item.clip;
        let (t, n) = (clip.frames, clip.n_vertices);
        if self.speed != [1.0, 1.0] {
            let k = log_uniform(rng, self.speed);
            let old = clip.vertices.clone();
            for (i, frame) in clip.vertices.chunks_exact_mut(n).enumerate() {
                let time = i as f32 * k;
                let f0 = (time.floor() as usize).min(t - 1);
                let f1 = (f0 + 1).min(t - 1);
                let w = time - f0 as f32;
                for (v, out) in frame.iter_mut().enumerate() {
                    let (a, b) = (old[f0 * n + v], old[f1 * n + v]);
                    *out = [0, 1, 2].map(|c| a[c] + w * (b[c] - a[c]));
                }
            }
        }
        if self.reverse > 0.0 && rng.random_bool(f64::from(self.reverse)) {
            // In place: reversing every row, then each frame's rows back, reverses the frame order only.
            clip.vertices.reverse();
            clip.vertices.chunks_exact_mut(n).for_each(<[_]>::reverse);
        }
        if self.motion != [1.0, 1.0] {
            let a = rng.random_range(self.motion[0]..=self.motion[1]);
            let (first, rest) = clip.vertices.split_at_mut(n);
            for frame in rest.chunks_exact_mut(n) {
                for (p, x0) in frame.iter_mut().zip(&*first) {
                    *p = [0, 1, 2].map(|c| x0[c] + a * (p[c] - x0[c]));
                }
            }
        }
        let mirror = self.mirror > 0.0 && rng.random_bool(f64::from(self.mirror));
        let s: [f32; 3] = if self.scale == [1.0, 1.0] {
            [1.0; 3]
        } else {
            std::array::from_fn(|_| rng.random_range(self.scale[0]..=self.scale[1]))
        };
        let yaw = if self.yaw_degrees > 0.0 {
            rng.random_range(-self.yaw_degrees..=self.yaw_degrees).to_radians()
        } else {
            0.0
        };
        let (sin, cos) = yaw.sin_cos();
        let sx = if mirror { -s[0] } else { s[0] };
        let place = |p: &mut [f32; 3]| {
            let (x, y, z) = (p[0] * sx, p[1] * s[1], p[2] * s[2]);
            *p = [cos * x + sin * z, y, -sin * x + cos * z];
        };
        clip.vertices.iter_mut().for_each(place);
        if mirror {
            for f in &mut clip.faces {
                f.swap(1, 2);
            }
        }
        let norm = Normalization::from_frame(&clip.vertices[..n]);
        norm.apply(clip);
        // The scene moves with the clip (the same scale, mirror and turn, then the same re-normalisation); it is
        // static, so time reversal and speed leave it as it is.
        if let Some(scene) = &mut item.scene {
            scene.vertices.iter_mut().for_each(place);
            if mirror {
                scene.faces.iter_mut().for_each(|f| f.swap(1, 2));
            }
            norm.apply_points(&mut scene.vertices);
        }
    }
}

/// `exp(uniform(ln lo, ln hi))`; `lo` when the range is one point.
fn log_uniform<R: Rng>(rng: &mut R, [lo, hi]: [f32; 2]) -> f32 {
    if lo >= hi {
        return lo;
    }
    rng.random_range(lo.ln()..=hi.ln()).exp()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::clip::Clip;
    use crate::preprocess::normalize;
    use crate::rng::rng;
    use crate::store::Split;

    /// A closed tetrahedron moving along +x over 5 frames, stored normalised.
    fn item() -> StoredClip {
        let base = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]];
        let vertices = (0..5)
            .flat_map(|f| base.map(|p: [f32; 3]| [p[0] + 0.3 * f as f32, p[1] + 0.1 * (f * f) as f32, p[2]]))
            .collect();
        let faces = vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        let clip = Clip::new("tet_offset0_0-4", vertices, 5, 4, faces, "a tetrahedron", "x").unwrap();
        let (clip, normalization) = normalize(&clip);
        StoredClip {
            clip,
            fps: vec![0, 3],
            normalization,
            split: Split::Train,
            scene: None,
        }
    }

    fn volume(v: &[[f32; 3]], faces: &[[u32; 3]]) -> f32 {
        faces
            .iter()
            .map(|f| {
                let [a, b, c] = f.map(|i| v[i as usize]);
                (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                    + a[2] * (b[0] * c[1] - b[1] * c[0]))
                    / 6.0
            })
            .sum()
    }

    fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
        (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f32>().sqrt()
    }

    fn close(a: &[[f32; 3]], b: &[[f32; 3]]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(p, q)| dist(*p, *q) < 1e-5)
    }

    #[test]
    fn off_changes_nothing_and_draws_nothing() {
        let (mut a, b) = (item(), item());
        let mut r = rng(1, 0);
        Augment::default().apply(&mut a, &mut r);
        assert_eq!(a, b);
        assert_eq!(r, rng(1, 0));
    }

    /// A scene made of the clip's own frame-0 points stays on them through every spatial augmentation (turn,
    /// mirror, scale and the re-normalisation), whatever the draw; time reversal and speed do not move it.
    #[test]
    fn the_scene_moves_with_its_clip() {
        let aug = Augment {
            yaw_degrees: 180.0,
            mirror: 0.5,
            scale: [0.7, 1.3],
            ..Augment::default()
        };
        for seed in 0..8 {
            let mut a = item();
            let frame0 = a.clip.frame(0).to_vec();
            a.scene = Some(crate::scene::Scene {
                vertices: frame0,
                faces: vec![[0, 1, 2]],
            });
            aug.apply(&mut a, &mut rng(seed, 1));
            let scene = a.scene.as_ref().unwrap();
            for (p, q) in scene.vertices.iter().zip(a.clip.frame(0)) {
                assert!(
                    p.iter().zip(q).all(|(x, y)| (x - y).abs() < 1e-5),
                    "seed {seed}: {p:?} vs {q:?}"
                );
            }
        }
    }

    #[test]
    fn the_same_generator_gives_the_same_example() {
        let aug = Augment {
            yaw_degrees: 180.0,
            mirror: 0.5,
            scale: [0.8, 1.2],
            reverse: 0.5,
            speed: [0.5, 1.0],
            motion: [0.8, 1.5],
        };
        aug.validate("vae.augment").unwrap();
        let (mut a, mut b, mut c) = (item(), item(), item());
        aug.apply(&mut a, &mut rng(7, 3));
        aug.apply(&mut b, &mut rng(7, 3));
        aug.apply(&mut c, &mut rng(8, 3));
        assert_eq!(a, b);
        assert_ne!(a.clip.vertices, c.clip.vertices);
    }

    #[test]
    fn a_turn_about_y_keeps_shape_and_height_and_the_result_is_normalised() {
        let aug = Augment {
            yaw_degrees: 90.0,
            ..Augment::default()
        };
        let (mut a, b) = (item(), item());
        aug.apply(&mut a, &mut rng(2, 0));
        let (va, vb) = (&a.clip.vertices, &b.clip.vertices);
        // One renormalisation factor for every pair of vertices of every frame, and y differences scale by it too.
        let k = dist(va[0], va[6]) / dist(vb[0], vb[6]);
        for (i, j) in [(0, 1), (2, 3), (4, 13), (7, 19)] {
            assert!((dist(va[i], va[j]) - k * dist(vb[i], vb[j])).abs() < 1e-5);
            assert!(((va[i][1] - va[j][1]) - k * (vb[i][1] - vb[j][1])).abs() < 1e-5);
        }
        assert!(
            (k - 1.0).abs() > 1e-3,
            "the turn changed the L∞ extent, so it was renormalised"
        );
        let n = Normalization::from_frame(&va[..4]);
        assert!(n.center.iter().all(|c| c.abs() < 1e-6) && (n.scale - 1.0).abs() < 1e-5);
    }

    #[test]
    fn a_mirror_keeps_the_faces_pointing_out() {
        let aug = Augment {
            mirror: 1.0,
            ..Augment::default()
        };
        let (mut a, b) = (item(), item());
        aug.apply(&mut a, &mut rng(2, 0));
        let (va, vb) = (&a.clip.vertices, &b.clip.vertices);
        assert!(
            (va[1][0] - va[0][0] + (vb[1][0] - vb[0][0])).abs() < 1e-5,
            "x is flipped"
        );
        assert_eq!(a.clip.faces[0], [0, 1, 2]);
        for f in 0..5 {
            let (before, after) = (
                volume(&vb[4 * f..4 * f + 4], &b.clip.faces),
                volume(&va[4 * f..4 * f + 4], &a.clip.faces),
            );
            assert!(before > 0.0 && after > 0.0, "frame {f}: {before} → {after}");
        }
    }

    #[test]
    fn anisotropic_scale_stretches_each_axis_within_its_range() {
        let aug = Augment {
            scale: [0.5, 2.0],
            ..Augment::default()
        };
        let mut seen = Vec::new();
        for s in 0..20 {
            let (mut a, b) = (item(), item());
            aug.apply(&mut a, &mut rng(s, 0));
            let ext = |v: &[[f32; 3]], k: usize| {
                v[..4].iter().map(|p| p[k]).fold(f32::MIN, f32::max)
                    - v[..4].iter().map(|p| p[k]).fold(f32::MAX, f32::min)
            };
            let r: Vec<f32> = (0..3)
                .map(|k| ext(&a.clip.vertices, k) / ext(&b.clip.vertices, k))
                .collect();
            // Ratios between axes are the drawn factors' ratios: within [0.25, 4].
            assert!(
                (0.249..=4.01).contains(&(r[0] / r[1])) && (0.249..=4.01).contains(&(r[2] / r[1])),
                "{r:?}"
            );
            seen.push(r[0] / r[1]);
        }
        assert!(
            seen.iter().any(|&x| x > 1.2) && seen.iter().any(|&x| x < 0.8),
            "{seen:?}"
        );
    }

    #[test]
    fn reversal_plays_the_window_backwards() {
        let aug = Augment {
            reverse: 1.0,
            ..Augment::default()
        };
        let (mut a, b) = (item(), item());
        aug.apply(&mut a, &mut rng(2, 0));
        // Frame i is stored frame 4 − i, renormalised by stored frame 4 (a translation and a scale).
        let s = dist(a.clip.frame(0)[0], a.clip.frame(0)[3]) / dist(b.clip.frame(4)[0], b.clip.frame(4)[3]);
        for i in 0..5 {
            let (p, q) = (a.clip.frame(i), b.clip.frame(4 - i));
            for v in 1..4 {
                assert!((dist(p[0], p[v]) - s * dist(q[0], q[v])).abs() < 1e-5, "frame {i}");
            }
        }
        assert!(a.clip.frame(4)[0][0] < a.clip.frame(0)[0][0], "moves along −x now");
    }

    #[test]
    fn half_speed_interpolates_between_stored_frames() {
        let aug = Augment {
            speed: [0.5, 0.5],
            ..Augment::default()
        };
        let (mut a, b) = (item(), item());
        aug.apply(&mut a, &mut rng(2, 0));
        // Frame 0 is unchanged, so is the normalisation: frame 2 is stored frame 1, frame 1 their midpoint.
        assert!(close(a.clip.frame(0), b.clip.frame(0)));
        assert!(close(a.clip.frame(2), b.clip.frame(1)));
        assert!(close(a.clip.frame(4), b.clip.frame(2)));
        let mid: Vec<[f32; 3]> = b
            .clip
            .frame(0)
            .iter()
            .zip(b.clip.frame(1))
            .map(|(p, q)| [0, 1, 2].map(|k| 0.5 * (p[k] + q[k])))
            .collect();
        assert!(close(a.clip.frame(1), &mid));
    }

    #[test]
    fn motion_scales_every_frame_about_frame_0_after_reversal() {
        let aug = Augment {
            motion: [2.0, 2.0],
            ..Augment::default()
        };
        let (mut a, b) = (item(), item());
        aug.apply(&mut a, &mut rng(2, 0));
        // Frame 0 is unchanged, so is the normalisation: every offset from it doubles.
        assert!(close(a.clip.frame(0), b.clip.frame(0)));
        for f in 1..5 {
            let want: Vec<[f32; 3]> = b
                .clip
                .frame(0)
                .iter()
                .zip(b.clip.frame(f))
                .map(|(p, q)| [0, 1, 2].map(|k| p[k] + 2.0 * (q[k] - p[k])))
                .collect();
            assert!(close(a.clip.frame(f), &want), "frame {f}");
        }
        // After a reversal the motion is scaled about the new frame 0 (stored frame 4), which stays put.
        let both = Augment {
            reverse: 1.0,
            motion: [0.5, 0.5],
            ..Augment::default()
        };
        let (mut r, mut only_reversed) = (item(), item());
        both.apply(&mut r, &mut rng(2, 0));
        Augment {
            reverse: 1.0,
            ..Augment::default()
        }
        .apply(&mut only_reversed, &mut rng(2, 0));
        assert!(close(r.clip.frame(0), only_reversed.clip.frame(0)));
        let p = (
            r.clip.frame(4)[0],
            only_reversed.clip.frame(4)[0],
            only_reversed.clip.frame(0)[0],
        );
        assert!(
            (0..3).all(|k| (p.0[k] - (p.2[k] + 0.5 * (p.1[k] - p.2[k]))).abs() < 1e-5),
            "{p:?}"
        );
    }

    #[test]
    fn empty_negative_and_non_finite_ranges_are_refused_naming_the_key() {
        let cases = [
            (
                Augment {
                    yaw_degrees: -1.0,
                    ..Augment::default()
                },
                "vae.augment.yaw_degrees",
            ),
            (
                Augment {
                    yaw_degrees: 181.0,
                    ..Augment::default()
                },
                "yaw_degrees",
            ),
            (
                Augment {
                    yaw_degrees: f32::NAN,
                    ..Augment::default()
                },
                "finite",
            ),
            (
                Augment {
                    mirror: 1.5,
                    ..Augment::default()
                },
                "mirror",
            ),
            (
                Augment {
                    reverse: -0.1,
                    ..Augment::default()
                },
                "reverse",
            ),
            (
                Augment {
                    scale: [1.2, 0.8],
                    ..Augment::default()
                },
                "scale",
            ),
            (
                Augment {
                    scale: [0.0, 1.0],
                    ..Augment::default()
                },
                "scale",
            ),
            (
                Augment {
                    scale: [-2.0, -1.0],
                    ..Augment::default()
                },
                "scale",
            ),
            (
                Augment {
                    scale: [1.0, f32::INFINITY],
                    ..Augment::default()
                },
                "finite",
            ),
            (
                Augment {
                    speed: [0.5, 2.0],
                    ..Augment::default()
                },
                "speed",
            ),
            (
                Augment {
                    speed: [0.0, 0.5],
                    ..Augment::default()
                },
                "speed",
            ),
            (
                Augment {
                    motion: [1.5, 1.2],
                    ..Augment::default()
                },
                "motion",
            ),
            (
                Augment {
                    motion: [0.0, 1.5],
                    ..Augment::default()
                },
                "motion",
            ),
            (
                Augment {
                    motion: [1.0, 5.0],
                    ..Augment::default()
                },
                "motion",
            ),
        ];
        for (aug, key) in cases {
            let e = aug.validate("vae.augment").unwrap_err();
            assert!(e.contains(key) && e.starts_with("vae.augment."), "{e} (wanted {key})");
        }
    }
}
