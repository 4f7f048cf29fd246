//! The one seeded random generator of the data crate (ChaCha8: portable, serialisable for checkpoints).

pub use rand::{Rng, RngCore, SeedableRng};
pub type DataRng = rand_chacha::ChaCha8Rng;

/// A generator from a seed and a stream label, so that independent uses of one seed do not share draws.
pub fn rng(seed: u64, stream: u64) -> DataRng {
    let mut r = DataRng::seed_from_u64(seed);
    r.set_stream(stream);
    r
}
