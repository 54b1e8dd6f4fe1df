//! Deterministic per-pixel random numbers: the PCG hash (Jarzynski & Olano 2020), which
//! WGSL reproduces bit for bit with u32 arithmetic. Keep in sync with shaders' `pcg_hash`.

/// The PCG-RXS-M-XS 32-bit hash.
#[inline]
pub fn pcg_hash(input: u32) -> u32 {
    let state = input.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277_803_737);
    (word >> 22) ^ word
}

/// A tiny RNG whose state is one u32, advanced by [`pcg_hash`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rng {
    pub state: u32,
}

/// 2^-24: maps the top 24 bits of a hash to [0, 1) exactly in f32.
const INV_2_POW_24: f32 = 1.0 / 16_777_216.0;

impl Rng {
    /// The RNG of one pixel sample: hashes the pixel index, the sample index and the
    /// scene seed together so every (pixel, sample) pair has its own stream.
    pub fn for_pixel(pixel_index: u32, sample: u32, seed: u32) -> Self {
        let s = pcg_hash(seed ^ pcg_hash(sample ^ pcg_hash(pixel_index)));
        Rng { state: s }
    }

    /// Uniform in [0, 1) with 24 bits (exactly representable in f32, so the GPU agrees).
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        self.state = pcg_hash(self.state);
        (self.state >> 8) as f32 * INV_2_POW_24
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_mean_and_range() {
        let mut rng = Rng::for_pixel(12, 3, 7);
        let n = 100_000;
        let mut sum = 0.0f64;
        for _ in 0..n {
            let u = rng.next_f32();
            assert!((0.0..1.0).contains(&u));
            sum += f64::from(u);
        }
        // Standard error of the mean of U(0,1) over 1e5 samples is ~9e-4.
        assert!((sum / f64::from(n) - 0.5).abs() < 5e-3);
    }

    #[test]
    fn pixels_get_different_streams() {
        let a = Rng::for_pixel(0, 0, 0).next_f32();
        let b = Rng::for_pixel(1, 0, 0).next_f32();
        let c = Rng::for_pixel(0, 1, 0).next_f32();
        assert!(a != b && a != c && b != c);
    }
}
