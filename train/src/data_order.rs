//! The order in which training examples are visited: a fresh seeded permutation per epoch, and a cursor into
//! it. The whole state is (seed, epoch, cursor), so a checkpoint resumes mid-epoch exactly. A training example is
//! a whole clip; for a clip stored as several windows each visit draws one of them ([`WholeClips`]).
//!
//! On a sharded store the examples come in blocks, one per shard, and an epoch reads them shard by shard, as a
//! streaming reader must (docs/training.md, "Data order on a sharded store"): the shards in a seeded order, each
//! shard's examples in a seeded order, through a shuffle buffer of bounded size that mixes neighbouring shards. A
//! store of one shard is shuffled whole, exactly as before shards existed.

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
    /// Examples per shard, in example order, when there are two shards or more (empty: one shard, shuffled whole).
    /// Absent from checkpoints written before shards: empty.
    #[serde(default)]
    pub blocks: Vec<usize>,
    /// Examples held by the shuffle buffer across shards (0: each shard's examples in its own order only).
    #[serde(default)]
    pub buffer: usize,
    #[serde(skip)]
    perm: Vec<usize>,
}

impl DataOrder {
    /// Starts at epoch 0, position 0. `len` must be positive.
    pub fn new(seed: u64, len: usize) -> Self {
        Self::sharded(seed, &[len], 0)
    }

    /// [`DataOrder::new`] over examples in blocks of `blocks[k]` examples (shard k's, in example order), read
    /// shard by shard through a shuffle buffer of `buffer` examples. One block is [`DataOrder::new`].
    pub fn sharded(seed: u64, blocks: &[usize], buffer: usize) -> Self {
        let len = blocks.iter().sum();
        assert!(len > 0, "DataOrder needs at least one example");
        let blocks = match blocks.iter().filter(|&&b| b > 0).count() {
            0 | 1 => Vec::new(),
            _ => blocks.to_vec(),
        };
        let mut order = DataOrder {
            seed,
            len,
            epoch: 0,
            cursor: 0,
            buffer: if blocks.is_empty() { 0 } else { buffer },
            blocks,
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

    /// Whether `other` (a fresh order of the current data and config) visits the same examples in the same
    /// blocks with the same buffer, so that this one's position means the same there.
    pub fn same_layout(&self, other: &DataOrder) -> bool {
        (self.len, &self.blocks, self.buffer) == (other.len, &other.blocks, other.buffer)
    }

    fn shuffle(&mut self) {
        // Distinct stream per epoch: the seed picks the generator, the epoch its stream.
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        rng.set_stream(self.epoch);
        if self.blocks.is_empty() {
            self.perm = (0..self.len).collect();
            self.perm.shuffle(&mut rng);
            return;
        }
        let mut starts = Vec::with_capacity(self.blocks.len());
        let mut at = 0;
        for &b in &self.blocks {
            starts.push(at);
            at += b;
        }
        let mut shards: Vec<usize> = (0..self.blocks.len()).collect();
        shards.shuffle(&mut rng);
        let mut perm = Vec::with_capacity(self.len);
        let mut held: Vec<usize> = Vec::with_capacity(self.buffer.min(self.len));
        for k in shards {
            let mut block: Vec<usize> = (starts[k]..starts[k] + self.blocks[k]).collect();
            block.shuffle(&mut rng);
            for e in block {
                if held.len() < self.buffer {
                    held.push(e);
                } else if self.buffer == 0 {
                    perm.push(e);
                } else {
                    // A full buffer: a random held example leaves, the new one takes its place.
                    let j = rng.random_range(0..held.len());
                    perm.push(std::mem::replace(&mut held[j], e));
                }
            }
        }
        held.shuffle(&mut rng);
        perm.extend(held);
        self.perm = perm;
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

    /// Examples per shard in example order (the lengths of the runs of examples whose first window `shard`
    /// places in one shard), for [`DataOrder::sharded`]. A clip's windows share a source, and a source lives in
    /// one shard.
    pub fn blocks<E>(&self, shard: impl Fn(usize) -> Result<usize, E>) -> Result<Vec<usize>, E> {
        let mut blocks: Vec<(usize, usize)> = Vec::new();
        for g in &self.groups {
            let k = shard(g[0])?;
            match blocks.last_mut() {
                Some((last, n)) if *last == k => *n += 1,
                _ => blocks.push((k, 1)),
            }
        }
        Ok(blocks.into_iter().map(|(_, n)| n).collect())
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

    #[test]
    fn one_block_is_the_whole_store_shuffle_of_before() {
        let mut a = DataOrder::new(3, 50);
        let mut b = DataOrder::sharded(3, &[0, 50, 0], 16);
        assert!(b.blocks.is_empty() && b.buffer == 0);
        assert_eq!(a.take(120), b.take(120));
    }

    #[test]
    fn sharded_epochs_are_permutations_that_stream_shard_by_shard() {
        let blocks = [40, 25, 0, 35];
        let buffer = 8;
        let mut order = DataOrder::sharded(11, &blocks, buffer);
        let shard_of = |e: usize| match e {
            0..40 => 0,
            40..65 => 1,
            _ => 3,
        };
        for _ in 0..3 {
            let epoch = order.take(100);
            let mut sorted = epoch.clone();
            sorted.sort_unstable();
            assert_eq!(sorted, (0..100).collect::<Vec<_>>());
            // Streaming: each shard is read as one stretch of the epoch — most of its examples (all but those the
            // buffer holds longer) come out within its size plus the buffer's.
            for k in [0, 1, 3] {
                let at: Vec<usize> = (0..100).filter(|&i| shard_of(epoch[i]) == k).collect();
                let reach = blocks[k] + buffer;
                let most = (0..100usize.saturating_sub(reach))
                    .map(|s| at.iter().filter(|&&i| (s..s + reach).contains(&i)).count())
                    .max()
                    .unwrap_or(at.len());
                assert!(
                    most * 5 >= at.len() * 4,
                    "shard {k}: {most} of {} within {reach} positions",
                    at.len()
                );
            }
        }
        // The buffer mixes: the first batch is not one shard's examples in order.
        let mut fresh = DataOrder::sharded(11, &blocks, buffer);
        let first = fresh.take(8);
        assert!(first.windows(2).any(|w| w[1] != w[0] + 1), "{first:?}");
        // Resumes mid-epoch exactly.
        let mut b = DataOrder::sharded(11, &blocks, buffer);
        b.take(137);
        let saved = serde_json::to_string(&b).unwrap();
        let mut resumed: DataOrder = serde_json::from_str::<DataOrder>(&saved).unwrap().restored();
        let mut straight = DataOrder::sharded(11, &blocks, buffer);
        straight.take(137);
        assert_eq!(resumed.take(150), straight.take(150));
        assert!(resumed.same_layout(&DataOrder::sharded(1, &blocks, buffer)));
        assert!(!resumed.same_layout(&DataOrder::sharded(11, &[40, 60], buffer)));
        assert!(!resumed.same_layout(&DataOrder::sharded(11, &blocks, buffer + 1)));
    }

    #[test]
    fn an_order_saved_before_shards_resumes_as_one_block() {
        let old = r#"{"seed":7,"len":10,"epoch":0,"cursor":3}"#;
        let mut resumed: DataOrder = serde_json::from_str::<DataOrder>(old).unwrap().restored();
        let mut straight = DataOrder::new(7, 10);
        straight.take(3);
        assert_eq!(resumed.take(12), straight.take(12));
    }

    #[test]
    fn blocks_follow_the_shards_of_the_first_windows() {
        let clips = WholeClips::new(vec![vec![0, 1], vec![2], vec![3, 4], vec![5], vec![6]]);
        let by = |w: usize| Ok::<_, ()>(usize::from(w >= 3) + usize::from(w >= 6));
        assert_eq!(clips.blocks(by), Ok(vec![2, 2, 1]));
        assert_eq!(clips.blocks(|_| Ok::<_, ()>(0)), Ok(vec![5]));
    }
}
