//! Keyframe selection, the one home of the concept: which frames of a T-frame window are observed
//! (docs/method.md §1.3 masks, §4.5 training, §5.4 SceneMI, §6.1 and §8 X4 evaluation). [`KeyframeStrategy`] draws
//! one mask; [`TrainingKeyframes`] is the RF config's choice of strategy (`rf.kf_sampler`); [`Placement`] is the
//! evaluation protocol's, stored in manifests.
//!
//! **Mask polarity (stated once, tested once): 1 / `true` = frame f is an observed keyframe whose clean latent is
//! given; 0 / `false` = frame f is generated.** This is the `m` of docs/method.md §1.3; the RF input is
//! `m ⊙ clean + (1 − m) ⊙ state` (R3).
//!
//! Every sampler is deterministic given its generator, and [`keyframe_mask_batch`] derives its generator from a
//! seed only, so a manifest can be rebuilt from `(strategy, B, T, seed)`.

use rand::Rng;
use rand::seq::SliceRandom;
use serde::{Deserialize, Serialize};

use crate::error::{DataError, Result};
use crate::rng::{DataRng, rng};

/// Stream label of the keyframe generator (see [`crate::rng::rng`]), so keyframe draws never share a stream with
/// other users of the same seed.
pub const KEYFRAME_STREAM: u64 = 0x6b66;

/// How the keyframe set 𝒦 ⊂ {0..T−1} is chosen.
#[derive(Debug, Clone, PartialEq)]
pub enum KeyframeStrategy {
    /// RF training (docs/method.md §4.5): k ~ Unif{0..=k_max}, then a uniform k-subset of {0..T−1} without replacement;
    /// first and last frames are not forced. The paper uses k_max = 5; k = 0 is the keyframe-free case.
    Random { k_max: usize },
    /// SceneMI's training sampler (docs/method.md §5.4): k ~ Unif{2..=T}, first and last frames always included,
    /// the other k − 2 drawn uniformly from the inner frames (T ≥ 2).
    Scenemi,
    /// The evaluation's placement as a training sampler (docs/method.md §4.10; not in the paper): frames 0 and T−1
    /// always, plus k − 2 inner frames with k ~ Unif{2..=k_max} (T ≥ 2, 2 ≤ k_max ≤ T).
    FirstLastRandom { k_max: usize },
    /// Evaluation (docs/method.md §6.1): {0, T−1} ∪ K_x distinct frames drawn from {1..T−2}. For one generator state
    /// the sets are nested across K_x: the set for K_x is a subset of the set for K_x + 1.
    FirstLastPlus(usize),
    /// Every r-th frame: f ∈ 𝒦 iff f mod r = 0 (r ≥ 1). The last frame is included only when r divides T − 1.
    Uniform(usize),
    /// A fixed set of frame indices (each < T; duplicates allowed and collapse).
    Fixed(Vec<usize>),
    /// Each frame independently observed with probability p ∈ [0, 1].
    Bernoulli(f32),
}

impl KeyframeStrategy {
    /// The training default of docs/method.md §4.5: `Random { k_max: 5 }`.
    pub const PAPER_TRAINING: KeyframeStrategy = KeyframeStrategy::Random { k_max: 5 };

    /// Checks that the strategy can be sampled for windows of `t` frames. Call it when a config is loaded:
    /// [`sample_keyframes`] panics on a strategy that fails this check.
    pub fn check(&self, t: usize) -> Result<()> {
        let err = |reason: String| Err(DataError::new("keyframes", format!("{self:?}"), reason));
        if t == 0 {
            return err("a window needs at least one frame".into());
        }
        match self {
            Self::Random { .. } => Ok(()),
            Self::Scenemi if t < 2 => err(format!("first and last frames need T ≥ 2, got T = {t}")),
            Self::Scenemi => Ok(()),
            Self::FirstLastRandom { k_max } => {
                if t < 2 {
                    return err(format!("first and last frames need T ≥ 2, got T = {t}"));
                }
                if !(2..=t).contains(k_max) {
                    return err(format!(
                        "k_max = {k_max} must count the first and last frames and fit the window: 2 ≤ k_max ≤ T = {t}"
                    ));
                }
                Ok(())
            }
            Self::FirstLastPlus(kx) => {
                if t < 2 {
                    return err(format!("first and last frames need T ≥ 2, got T = {t}"));
                }
                if *kx > t - 2 {
                    return err(format!(
                        "{kx} extra keyframes do not fit in the {} inner frames of T = {t}",
                        t - 2
                    ));
                }
                Ok(())
            }
            Self::Uniform(0) => err("the stride r must be at least 1".into()),
            Self::Uniform(_) => Ok(()),
            Self::Fixed(frames) => match frames.iter().find(|&&f| f >= t) {
                Some(f) => err(format!("frame {f} is outside 0..{t}")),
                None => Ok(()),
            },
            Self::Bernoulli(p) if !(0.0..=1.0).contains(p) => err(format!("probability {p} is outside [0, 1]")),
            Self::Bernoulli(_) => Ok(()),
        }
    }
}

/// Draw the keyframe mask of one window of `t` frames; `true` = observed keyframe.
///
/// # Shapes
/// Output `[T]`.
///
/// # Panics
/// If `strategy.check(t)` fails (validate configs with [`KeyframeStrategy::check`] first).
pub fn sample_keyframes(strategy: &KeyframeStrategy, t: usize, rng: &mut impl Rng) -> Vec<bool> {
    if let Err(e) = strategy.check(t) {
        panic!("invalid keyframe strategy: {e}");
    }
    let mut mask = vec![false; t];
    match strategy {
        KeyframeStrategy::Random { k_max } => {
            // docs/method.md §4.5 step 1: k ~ Unif{0..=k_max} (capped at T), step 2: uniform subset without
            // replacement.
            let k = rng.random_range(0..=*k_max).min(t);
            let mut frames: Vec<usize> = (0..t).collect();
            let (chosen, _) = frames.partial_shuffle(rng, k);
            for &f in chosen.iter() {
                mask[f] = true;
            }
        }
        KeyframeStrategy::Scenemi => {
            mask[0] = true;
            mask[t - 1] = true;
            let k = rng.random_range(2..=t);
            let mut inner: Vec<usize> = (1..t - 1).collect();
            let (chosen, _) = inner.partial_shuffle(rng, k - 2);
            for &f in chosen.iter() {
                mask[f] = true;
            }
        }
        KeyframeStrategy::FirstLastRandom { k_max } => {
            mask[0] = true;
            mask[t - 1] = true;
            let k = rng.random_range(2..=*k_max);
            let mut inner: Vec<usize> = (1..t - 1).collect();
            let (chosen, _) = inner.partial_shuffle(rng, k - 2);
            for &f in chosen.iter() {
                mask[f] = true;
            }
        }
        KeyframeStrategy::FirstLastPlus(kx) => {
            mask[0] = true;
            mask[t - 1] = true;
            // A full shuffle of the inner frames consumes the same draws for every K_x, so taking a prefix of it
            // makes the sets nested across K_x (docs/method.md §6.1).
            let mut inner: Vec<usize> = (1..t - 1).collect();
            inner.shuffle(rng);
            for &f in &inner[..*kx] {
                mask[f] = true;
            }
        }
        KeyframeStrategy::Uniform(r) => {
            for f in (0..t).step_by(*r) {
                mask[f] = true;
            }
        }
        KeyframeStrategy::Fixed(frames) => {
            for &f in frames {
                mask[f] = true;
            }
        }
        KeyframeStrategy::Bernoulli(p) => {
            for m in mask.iter_mut() {
                *m = rng.random_bool(f64::from(*p));
            }
        }
    }
    mask
}

/// Masks for a batch of `b` windows of `t` frames, drawn in order from the generator `rng(seed, KEYFRAME_STREAM)`;
/// 1.0 = observed keyframe, 0.0 = generated. Row i is the mask of sample i.
///
/// # Shapes
/// Output `[B * T]`, row-major `[B, T]`.
///
/// # Panics
/// As [`sample_keyframes`].
pub fn keyframe_mask_batch(strategy: &KeyframeStrategy, b: usize, t: usize, seed: u64) -> Vec<f32> {
    let mut r: DataRng = rng(seed, KEYFRAME_STREAM);
    (0..b)
        .flat_map(|_| sample_keyframes(strategy, t, &mut r))
        .map(|m| if m { 1.0 } else { 0.0 })
        .collect()
}

/// How the RF draws the keyframes of a training window: the `rf.kf_sampler` key (docs/method.md §4.5, §8 X3).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrainingKeyframes {
    /// k ~ Unif{0..=k_max}, a uniform k-subset of the T frames (the paper, k_max = 5).
    Random,
    /// SceneMI: k ~ Unif{2..=T}, first and last always included.
    Scenemi,
    /// First and last frames always, k ~ Unif{2..=k_max} in all (docs/method.md §4.10; the evaluation's placement,
    /// not the paper's sampler).
    FirstLast,
}

impl TrainingKeyframes {
    /// The strategy that draws one training mask, with `k_max` for [`TrainingKeyframes::Random`].
    pub fn strategy(self, k_max: usize) -> KeyframeStrategy {
        match self {
            TrainingKeyframes::Random => KeyframeStrategy::Random { k_max },
            TrainingKeyframes::Scenemi => KeyframeStrategy::Scenemi,
            TrainingKeyframes::FirstLast => KeyframeStrategy::FirstLastRandom { k_max },
        }
    }
}

/// Where the keyframes of a test window sit (docs/method.md §6.1, §8 X4). First and last frames are always keyframes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum Placement {
    /// K_x = 0..=k_extra_max extra frames drawn without replacement from {1..T−2}, nested across K_x (ours).
    Random { k_extra_max: usize },
    /// Every r-th frame: {0, r, 2r, …} ∪ {T−1}.
    EveryR { r: usize },
    /// Each interior frame independently with probability p.
    Bernoulli { p: f32 },
    /// Keyframes every `stride` frames, e.g. {0, 15, 30} for the 31-frame rollout (docs/method.md §7).
    Stride { stride: usize },
}

impl Default for Placement {
    fn default() -> Self {
        Placement::PAPER
    }
}

impl Placement {
    /// The paper's short-horizon placement: first and last plus K_x = 0..3 random frames.
    pub const PAPER: Placement = Placement::Random { k_extra_max: 3 };

    /// Short label for tables and file names: `random`, `every_4`, `bernoulli_0.25`, `stride_15`.
    pub fn label(&self) -> String {
        match self {
            Placement::Random { .. } => "random".into(),
            Placement::EveryR { r } => format!("every_{r}"),
            Placement::Bernoulli { p } => format!("bernoulli_{p}"),
            Placement::Stride { stride } => format!("stride_{stride}"),
        }
    }

    /// Parses a label of [`Placement::label`] (`random` is [`Placement::PAPER`]); `Err` says what is expected.
    pub fn parse(text: &str) -> std::result::Result<Self, String> {
        if text == "random" {
            return Ok(Placement::PAPER);
        }
        let number = |rest: &str, what: &str| format!("placement {text}: {what} ({rest:?} is not one)");
        if let Some(r) = text.strip_prefix("every_") {
            return r
                .parse()
                .map(|r| Placement::EveryR { r })
                .map_err(|_| number(r, "r must be a whole number"));
        }
        if let Some(p) = text.strip_prefix("bernoulli_") {
            return p
                .parse()
                .map(|p| Placement::Bernoulli { p })
                .map_err(|_| number(p, "p must be a number in (0, 1)"));
        }
        Err(format!("placement {text}: expected random, every_<r> or bernoulli_<p>"))
    }

    /// Checks that the placement fits windows of `frames` frames; `Err` says why not.
    pub fn check(self, frames: usize) -> std::result::Result<(), String> {
        if frames < 2 {
            return Err(format!("frames = {frames}, at least 2 are needed"));
        }
        match self {
            Placement::Random { k_extra_max } if k_extra_max > frames - 2 => Err(format!(
                "k_extra_max = {k_extra_max} exceeds the {} interior frames",
                frames - 2
            )),
            Placement::EveryR { r: 0 } | Placement::Stride { stride: 0 } => Err("the step must be at least 1".into()),
            Placement::Bernoulli { p } if !(0.0..=1.0).contains(&p) => Err(format!("p = {p} is outside [0, 1]")),
            _ => Ok(()),
        }
    }

    /// Number of keyframe sets per item: one per K_x for `Random`, one otherwise.
    pub fn sets(self) -> usize {
        match self {
            Placement::Random { k_extra_max } => k_extra_max + 1,
            _ => 1,
        }
    }

    /// The keyframe sets of the item at position `pos` of a manifest drawn with `seed` (sorted frame indices, first
    /// and last forced); each item has its own generator stream, so items are independent, and the `Random` sets
    /// are nested across K_x.
    ///
    /// # Panics
    /// If [`Placement::check`] fails for `frames` (manifests check it first).
    pub fn keyframe_sets(self, frames: usize, seed: u64, pos: u64) -> Vec<Vec<usize>> {
        let item_rng = rng(seed, 1 + pos);
        let draw = |strategy: KeyframeStrategy| {
            // A fresh copy of the item's generator per set: FirstLastPlus sets are then nested across K_x.
            let mask = sample_keyframes(&strategy, frames, &mut item_rng.clone());
            let mut set: Vec<usize> = (0..frames).filter(|&f| mask[f] || f == 0 || f == frames - 1).collect();
            set.dedup();
            set
        };
        match self {
            Placement::Random { k_extra_max } => (0..=k_extra_max)
                .map(|k| draw(KeyframeStrategy::FirstLastPlus(k)))
                .collect(),
            Placement::EveryR { r } => vec![draw(KeyframeStrategy::Uniform(r))],
            Placement::Stride { stride } => vec![draw(KeyframeStrategy::Uniform(stride))],
            Placement::Bernoulli { p } => vec![draw(KeyframeStrategy::Bernoulli(p))],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn count(mask: &[bool]) -> usize {
        mask.iter().filter(|&&m| m).count()
    }

    #[test]
    fn random_draws_k_uniformly_in_0_to_k_max_without_forcing_ends() {
        let mut r = rng(666, 1);
        let mut hist = [0usize; 6];
        let mut ends_free = false;
        for _ in 0..6000 {
            let m = sample_keyframes(&KeyframeStrategy::PAPER_TRAINING, 16, &mut r);
            let k = count(&m);
            assert!(k <= 5, "k = {k} > 5");
            hist[k] += 1;
            ends_free |= k > 0 && !m[0] && !m[15];
        }
        // Each k has probability 1/6 = 1000 of 6000 draws; 4.5 standard deviations is about 130.
        for (k, &n) in hist.iter().enumerate() {
            assert!((870..=1130).contains(&n), "k = {k} drawn {n} times of 6000: {hist:?}");
        }
        assert!(ends_free, "first/last must not be forced in Random");
    }

    #[test]
    fn first_last_random_keeps_the_ends_and_draws_k_uniformly_in_2_to_k_max() {
        let mut r = rng(7, 1);
        let mut hist = [0usize; 6];
        let strategy = KeyframeStrategy::FirstLastRandom { k_max: 5 };
        for _ in 0..4000 {
            let m = sample_keyframes(&strategy, 16, &mut r);
            assert!(m[0] && m[15], "first and last frames must be keyframes: {m:?}");
            hist[count(&m)] += 1;
        }
        assert_eq!(hist[0] + hist[1], 0, "{hist:?}");
        // k = 2..=5 each with probability 1/4 = 1000 of 4000; 4.5 standard deviations is about 123.
        for (k, &n) in hist.iter().enumerate().skip(2) {
            assert!((877..=1123).contains(&n), "k = {k} drawn {n} times of 4000: {hist:?}");
        }
        assert_eq!(TrainingKeyframes::FirstLast.strategy(5), strategy);
        for (k_max, t) in [(1, 16), (17, 16), (2, 1)] {
            let bad = KeyframeStrategy::FirstLastRandom { k_max };
            assert!(bad.check(t).is_err(), "k_max {k_max} with T = {t} must be refused");
        }
    }

    #[test]
    fn random_subsets_cover_every_frame() {
        let mut r = rng(3, 1);
        let mut seen = [0usize; 16];
        for _ in 0..2000 {
            for (f, m) in sample_keyframes(&KeyframeStrategy::Random { k_max: 5 }, 16, &mut r)
                .iter()
                .enumerate()
            {
                seen[f] += usize::from(*m);
            }
        }
        // Expected 2000 · 2.5 / 16 ≈ 312 per frame.
        assert!(seen.iter().all(|&n| (200..=430).contains(&n)), "{seen:?}");
    }

    #[test]
    fn first_last_plus_always_has_ends_and_is_nested() {
        for seed in 0..50 {
            let mut prev: Option<Vec<bool>> = None;
            for kx in 0..=3 {
                let m = sample_keyframes(&KeyframeStrategy::FirstLastPlus(kx), 16, &mut rng(seed, 9));
                assert!(m[0] && m[15], "ends missing for seed {seed}, kx {kx}");
                assert_eq!(count(&m), kx + 2);
                if let Some(p) = &prev {
                    assert!(
                        p.iter().zip(&m).all(|(a, b)| !a || *b),
                        "not nested at seed {seed}, kx {kx}"
                    );
                }
                prev = Some(m);
            }
        }
    }

    #[test]
    fn mask_polarity_is_one_for_observed_frames() {
        let m = keyframe_mask_batch(&KeyframeStrategy::Fixed(vec![0, 7]), 2, 8, 1);
        assert_eq!(m, vec![1., 0., 0., 0., 0., 0., 0., 1., 1., 0., 0., 0., 0., 0., 0., 1.]);
        let u = sample_keyframes(&KeyframeStrategy::Uniform(3), 8, &mut rng(0, 0));
        assert_eq!(u, vec![true, false, false, true, false, false, true, false]);
    }

    #[test]
    fn batches_are_deterministic_by_seed() {
        let s = KeyframeStrategy::Random { k_max: 5 };
        let a = keyframe_mask_batch(&s, 32, 16, 42);
        assert_eq!(a, keyframe_mask_batch(&s, 32, 16, 42));
        assert_ne!(a, keyframe_mask_batch(&s, 32, 16, 43));
        assert_eq!(a.len(), 32 * 16);
        let b = keyframe_mask_batch(&KeyframeStrategy::Bernoulli(0.5), 64, 16, 7);
        let frac = b.iter().sum::<f32>() / b.len() as f32;
        assert!((0.4..0.6).contains(&frac), "{frac}");
    }

    #[test]
    fn scenemi_keeps_the_ends_and_draws_k_from_2_to_t() {
        let mut r = rng(5, 2);
        let mut hist = [0usize; 9];
        for _ in 0..4000 {
            let m = TrainingKeyframes::Scenemi.strategy(5);
            let m = sample_keyframes(&m, 8, &mut r);
            assert!(m[0] && m[7], "{m:?}");
            hist[count(&m)] += 1;
        }
        // k ~ Unif{2..=8}: 7 values, about 571 each of 4000.
        assert_eq!(hist[..2], [0, 0]);
        assert!(hist[2..].iter().all(|&n| (450..=700).contains(&n)), "{hist:?}");
        assert!(KeyframeStrategy::Scenemi.check(1).is_err());
    }

    #[test]
    fn placements_parse_their_labels_and_draw_nested_sets() {
        for p in [
            Placement::PAPER,
            Placement::EveryR { r: 4 },
            Placement::Bernoulli { p: 0.25 },
        ] {
            assert_eq!(Placement::parse(&p.label()), Ok(p));
        }
        assert!(Placement::parse("every_x").unwrap_err().contains("whole number"));
        assert!(Placement::parse("sometimes").unwrap_err().contains("expected random"));
        let sets = Placement::PAPER.keyframe_sets(16, 42, 3);
        assert_eq!(sets.len(), Placement::PAPER.sets());
        for (k, w) in sets.windows(2).enumerate() {
            assert!(w[0].iter().all(|f| w[1].contains(f)), "K_x {k} not nested: {sets:?}");
        }
        assert_eq!(
            Placement::Stride { stride: 15 }.keyframe_sets(31, 42, 0),
            vec![vec![0, 15, 30]]
        );
        assert!(Placement::Random { k_extra_max: 15 }.check(16).is_err());
        assert!(Placement::EveryR { r: 0 }.check(16).is_err());
    }

    #[test]
    fn invalid_strategies_are_reported() {
        assert!(KeyframeStrategy::FirstLastPlus(15).check(16).is_err());
        assert!(KeyframeStrategy::FirstLastPlus(14).check(16).is_ok());
        assert!(KeyframeStrategy::Uniform(0).check(16).is_err());
        let e = KeyframeStrategy::Fixed(vec![16]).check(16).unwrap_err();
        assert!(e.reason.contains("frame 16"), "{e}");
        assert!(KeyframeStrategy::Bernoulli(1.5).check(16).is_err());
    }
}
