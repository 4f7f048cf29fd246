//! The order in which training examples are visited: a fresh seeded permutation per epoch, and a cursor into
//! it. The whole state is (seed, epoch, cursor), so a checkpoint resumes mid-epoch exactly. A training example is
//! a whole clip; for a clip stored as several windows each visit draws one of them ([`WholeClips`]).

use rand::Rng;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Position in the shuffled stream of example indices `0..len`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct DataOrder {
    /// Seed of every epoch's permutation.
    pub seed: u64,
    /// Number of examples.
    pub len: usize,
    /// Current epoch (0-based).
    pub epoch: u64,
    /// Next position in the current epoch's permutation.
    pub cursor: usize,
    #[serde(skip)]
    perm: Vec<usize>,
}

impl DataOrder {
    /// Starts at epoch 0, position 0. `len` must be positive.
    pub fn new(seed: u64, len: usize) -> Self {
        assert!(len > 0, "DataOrder needs at least one example");
        let mut order = DataOrder {
            seed,
            len,
            epoch: 0,
            cursor: 0,
            perm: Vec::new(),
        };
        order.shuffle();
        order
    }

    /// Rebuilds the permutation after deserialising (the permutation itself is not stored).
    pub fn restored(mut self) -> Self {
        self.shuffle();
        self
    }

    fn shuffle(&mut self) {
        // Distinct stream per epoch: the seed picks the generator, the epoch its stream.
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        rng.set_stream(self.epoch);
        self.perm = (0..self.len).collect();
        self.perm.shuffle(&mut rng);
    }

    /// The next `n` example indices, continuing into the next epoch when this one runs out.
    pub fn take(&mut self, n: usize) -> Vec<usize> {
        let mut out = Vec::with_capacity(n);
        while out.len() < n {
            if self.cursor == self.len {
                self.epoch += 1;
                self.cursor = 0;
                self.shuffle();
            }
            let k = (n - out.len()).min(self.len - self.cursor);
            out.extend_from_slice(&self.perm[self.cursor..self.cursor + k]);
            self.cursor += k;
        }
        out
    }

    /// Examples seen so far, as a fractional epoch count.
    pub fn epochs_done(&self) -> f64 {
        self.epoch as f64 + self.cursor as f64 / self.len as f64
    }
}

/// The training examples of a split as whole clips (docs/method.md §2.6): example e is the group of stored windows
/// cut from one clip, and every visit of e draws one of its windows uniformly, so an epoch sees each clip once,
/// however long it is. A group of one window draws nothing from the RNG: a store of uncut clips trains exactly as
/// if the windows were the examples.
#[derive(Clone, Debug)]
pub struct WholeClips {
    groups: Vec<Vec<usize>>,
    windows: usize,
}

impl WholeClips {
    /// Groups of positions (into the split's list of stored windows), as [`any4d_data::store::Store::whole_clips`]
    /// returns them; empty groups are dropped.
    pub fn new(groups: Vec<Vec<usize>>) -> Self {
        let groups: Vec<Vec<usize>> = groups.into_iter().filter(|g| !g.is_empty()).collect();
        let windows = groups.iter().map(Vec::len).sum();
        WholeClips { groups, windows }
    }

    /// Number of whole clips (the training examples).
    pub fn len(&self) -> usize {
        self.groups.len()
    }

    /// True when there is no clip.
    pub fn is_empty(&self) -> bool {
        self.groups.is_empty()
    }

    /// Number of stored windows over all clips.
    pub fn windows(&self) -> usize {
        self.windows
    }

    /// One window position per example in `examples`, each drawn uniformly from its clip's windows with `rng`.
    /// Panics on an example index out of range (the data order only yields `0..len`).
    pub fn draw(&self, examples: &[usize], rng: &mut ChaCha8Rng) -> Vec<usize> {
        examples
            .iter()
            .map(|&e| match self.groups[e].as_slice() {
                [one] => *one,
                many => many[rng.random_range(0..many.len())],
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whole_clips_draw_each_window_and_leave_single_windows_alone() {
        let clips = WholeClips::new(vec![vec![0], vec![1, 2, 3, 4], vec![], vec![5]]);
        assert_eq!((clips.len(), clips.windows()), (3, 6));
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let before = rng.clone();
        assert_eq!(clips.draw(&[0, 2, 0], &mut rng), [0, 5, 0]);
        assert_eq!(rng, before, "single windows draw nothing");
        let mut seen = [0usize; 6];
        for _ in 0..4000 {
            seen[clips.draw(&[1], &mut rng)[0]] += 1;
        }
        // Uniform over the four windows: 1000 each, sd ≈ 27.
        assert!(seen[1..5].iter().all(|&n| (880..=1120).contains(&n)), "{seen:?}");
        assert_eq!((seen[0], seen[5]), (0, 0));
    }

    #[test]
    fn each_epoch_is_a_permutation_and_resume_continues_the_stream() {
        let mut a = DataOrder::new(7, 10);
        let first: Vec<usize> = a.take(10);
        let mut sorted = first.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..10).collect::<Vec<_>>());
        let second = a.take(10);
        assert_ne!(first, second, "epochs are reshuffled");

        let mut b = DataOrder::new(7, 10);
        b.take(13);
        let saved = serde_json::to_string(&b).unwrap();
        let mut resumed: DataOrder = serde_json::from_str::<DataOrder>(&saved).unwrap().restored();
        let mut straight = DataOrder::new(7, 10);
        straight.take(13);
        assert_eq!(resumed.take(9), straight.take(9));
    }
}
