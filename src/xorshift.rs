//! A small deterministic pseudo-random generator (Marsaglia's xorshift64, shifts 13/7/17) for
//! draws that must repeat exactly from run to run: the body completion's plane hypotheses and
//! the random inputs of tests. Not for anything that needs statistical quality.

/// xorshift64 state; never zero (zero is its fixed point).
#[derive(Debug, Clone)]
pub(crate) struct XorShift64(u64);

impl XorShift64 {
    /// A generator from `seed`, which must not be zero.
    pub(crate) fn new(seed: u64) -> Self {
        debug_assert_ne!(seed, 0, "xorshift64 stays at zero");
        Self(seed)
    }

    /// The next state.
    pub(crate) fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.0 = x;
        x
    }

    /// The next state modulo `n` (> 0).
    pub(crate) fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }

    /// Uniform in [0, 1), from the next state's top 24 bits.
    #[cfg(test)]
    pub(crate) fn unit_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sequence_is_marsaglias_xorshift64() {
        let mut r = XorShift64::new(1);
        // x = 1: x ^= x << 13 → 0x2001; x ^= x >> 7 → 0x2041; x ^= x << 17 → 0x4082_2041.
        assert_eq!(r.next_u64(), 0x4082_2041);
        let mut a = XorShift64::new(0x2545_f491_4f6c_dd1d);
        let mut b = a.clone();
        let first: Vec<u64> = (0..5).map(|_| a.next_u64()).collect();
        assert!(first.iter().all(|&x| x != 0));
        assert_eq!(first, (0..5).map(|_| b.next_u64()).collect::<Vec<_>>());
        assert!((0..1000).all(|_| a.below(7) < 7));
        let units: Vec<f32> = (0..1000).map(|_| a.unit_f32()).collect();
        assert!(units.iter().all(|u| (0.0..1.0).contains(u)));
        let mean = units.iter().sum::<f32>() / units.len() as f32;
        assert!((mean - 0.5).abs() < 0.05, "mean {mean}");
    }
}
