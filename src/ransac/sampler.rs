//! Reproducible minimal samples.
//!
//! Hypotheses are drawn in batches; batch `b` uses the ChaCha8 stream `b` of the generator seeded
//! with the user's seed, so the samples of a batch never depend on which thread scores them or on
//! how many batches ran before.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Draws `batch_len` samples of `sample_size` distinct indices below `n` for batch `batch`.
/// Requires `n >= sample_size`.
pub fn draw_batch(
    seed: u64,
    batch: u64,
    batch_len: usize,
    sample_size: usize,
    n: usize,
) -> Vec<usize> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(batch);
    let mut out = Vec::with_capacity(batch_len * sample_size);
    for _ in 0..batch_len {
        let start = out.len();
        while out.len() < start + sample_size {
            let i = rng.random_range(0..n);
            if !out[start..].contains(&i) {
                out.push(i);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_are_distinct_in_range_and_reproducible() {
        let a = draw_batch(42, 3, 100, 3, 5);
        assert_eq!(a.len(), 300);
        for s in a.chunks(3) {
            assert!(s.iter().all(|&i| i < 5));
            assert!(s[0] != s[1] && s[0] != s[2] && s[1] != s[2]);
        }
        assert_eq!(a, draw_batch(42, 3, 100, 3, 5));
        assert_ne!(a, draw_batch(42, 4, 100, 3, 5));
        assert_ne!(a, draw_batch(43, 3, 100, 3, 5));
    }
}
