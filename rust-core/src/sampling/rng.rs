//! A small deterministic generator for tables built from samples and for tests.

/// SplitMix64: small, deterministic uniforms in [0, 1).
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    pub fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Three uniforms: the `rnd` of one BRDF sample.
    pub fn three(&mut self) -> [f64; 3] {
        [self.next_f64(), self.next_f64(), self.next_f64()]
    }
}
