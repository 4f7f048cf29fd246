//! The one seeded random generator of the data crate (ChaCha8: portable, serialisable for checkpoints).

pub use rand::{Rng, RngCore, SeedableRng};
pub type DataRng = rand_chacha::ChaCha8Rng;

/// A generator from a seed and a stream label, so that independent uses of one seed do not share draws.
pub fn rng(seed: u64, stream: u64) -> DataRng {
    let mut r = DataRng::seed_from_u64(seed);
    r.set_stream(stream);
    r
}

/// φ · 2⁶⁴, the increment of SplitMix64's state: adding it walks the sequence, multiplying spreads an index.
pub const GOLDEN_GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// The SplitMix64 finaliser: a bijective mix of 64 bits, so nearby inputs (seed + 1, step + 1) give unrelated
/// outputs. The one seed-derivation function of the workspace (training steps, evaluation noise seeds).
pub fn splitmix64(z: u64) -> u64 {
    let z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    let z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splitmix64_matches_the_reference_sequence() {
        // SplitMix64 seeded with 0: the outputs of Vigna's reference generator (state += γ, then the finaliser).
        let outputs: Vec<u64> = (1..=3u64).map(|i| splitmix64(i.wrapping_mul(GOLDEN_GAMMA))).collect();
        assert_eq!(
            outputs,
            [0xE220_A839_7B1D_CDAF, 0x6E78_9E6A_A1B9_65F4, 0x06C4_5D18_8009_454F]
        );
    }
}
