//! The order in which training examples are visited: a fresh seeded permutation per epoch, and a cursor into
//! it. The whole state is (seed, epoch, cursor), so a checkpoint resumes mid-epoch exactly.

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

#[cfg(test)]
mod tests {
    use super::*;

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
