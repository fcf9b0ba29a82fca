//! Seeded random streams for simulations.
//!
//! Each random quantity of a run (one link direction's jitter, its losses, a vehicle's noise...)
//! draws from its own stream, numbered by the caller: stream `n` of seed `s` is the same on every
//! machine and in every version of this crate, and does not depend on how much the other
//! streams drew. The generator is xoshiro256++ (Blackman and Vigna), its state filled by
//! SplitMix64 from the seed and the stream number; it is fast and statistically sound, not
//! cryptographic.

/// One reproducible stream of random numbers.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rng {
    state: [u64; 4],
}

fn splitmix64(x: &mut u64) -> u64 {
    *x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *x;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

impl Rng {
    /// Stream `stream` of the run seeded with `seed`.
    pub fn new(seed: u64, stream: u64) -> Rng {
        let mut x = seed ^ splitmix64(&mut stream.wrapping_mul(0xd1b5_4a32_d192_ed03));
        let state = [
            splitmix64(&mut x),
            splitmix64(&mut x),
            splitmix64(&mut x),
            splitmix64(&mut x),
        ];
        // SplitMix64 outputs are a bijection of distinct inputs: never all zero.
        Rng { state }
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let s = &mut self.state;
        let result = s[0].wrapping_add(s[3]).rotate_left(23).wrapping_add(s[0]);
        let t = s[1] << 17;
        s[2] ^= s[0];
        s[3] ^= s[1];
        s[1] ^= s[2];
        s[0] ^= s[3];
        s[2] ^= t;
        s[3] = s[3].rotate_left(45);
        result
    }

    /// The next 32 random bits (the high half of [`Rng::next_u64`]).
    pub fn next_u32(&mut self) -> u32 {
        (self.next_u64() >> 32) as u32
    }

    /// Uniform in [0, 1), 53 bits of precision.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// True with probability `p` (clamped to [0, 1]).
    pub fn bernoulli(&mut self, p: f64) -> bool {
        self.uniform() < p
    }

    /// Standard normal (mean 0, standard deviation 1), by the Box-Muller transform.
    pub fn standard_normal(&mut self) -> f64 {
        // 1 - uniform() is in (0, 1]: the logarithm is finite.
        let r = (-2.0 * (1.0 - self.uniform()).ln()).sqrt();
        r * (std::f64::consts::TAU * self.uniform()).cos()
    }

    /// Laplace with mean 0 and standard deviation 1 (scale 1/sqrt 2), by inversion.
    pub fn standard_laplace(&mut self) -> f64 {
        let u = self.uniform() - 0.5;
        let scale = std::f64::consts::FRAC_1_SQRT_2;
        -scale * u.signum() * (1.0 - 2.0 * u.abs()).ln()
    }

    /// Uniform with mean 0 and standard deviation 1 (on [-sqrt 3, sqrt 3)).
    pub fn standard_uniform(&mut self) -> f64 {
        (2.0 * self.uniform() - 1.0) * 3f64.sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn moments(mut draw: impl FnMut() -> f64, n: usize) -> (f64, f64) {
        let (mut sum, mut sq) = (0.0, 0.0);
        for _ in 0..n {
            let x = draw();
            assert!(x.is_finite());
            sum += x;
            sq += x * x;
        }
        let mean = sum / n as f64;
        (mean, (sq / n as f64 - mean * mean).sqrt())
    }

    #[test]
    fn streams_are_fixed_by_seed_and_number() {
        // Golden values: a change here changes every simulated run.
        let mut a = Rng::new(1, 0);
        let first: Vec<u64> = (0..3).map(|_| a.next_u64()).collect();
        let mut again = Rng::new(1, 0);
        assert_eq!(first, (0..3).map(|_| again.next_u64()).collect::<Vec<_>>());
        assert_eq!(first, GOLDEN);
        assert_ne!(Rng::new(1, 1), Rng::new(1, 0));
        assert_ne!(Rng::new(2, 0), Rng::new(1, 0));
        assert_ne!(Rng::new(0, 0).next_u64(), Rng::new(0, 1).next_u64());
    }

    const GOLDEN: [u64; 3] = [
        5_226_295_891_941_712_017,
        5_547_022_123_706_608_281,
        18_144_476_329_041_699_521,
    ];

    #[test]
    fn xoshiro256plusplus_reference_outputs() {
        // From state {1, 2, 3, 4}: rotl(1 + 4, 23) + 1, then the reference implementation's
        // second output.
        let mut rng = Rng {
            state: [1, 2, 3, 4],
        };
        assert_eq!(rng.next_u64(), 41_943_041);
        assert_eq!(rng.next_u64(), 58_720_359);
    }

    #[test]
    fn distributions_have_their_moments() {
        let n = 200_000;
        let tolerance = 4.0 / (n as f64).sqrt();
        let mut rng = Rng::new(42, 3);
        let (m, s) = moments(|| rng.uniform(), n);
        assert!((m - 0.5).abs() < tolerance && (s - (1.0f64 / 12.0).sqrt()).abs() < tolerance);
        for draw in [
            Rng::standard_normal as fn(&mut Rng) -> f64,
            Rng::standard_laplace,
            Rng::standard_uniform,
        ] {
            let (m, s) = moments(|| draw(&mut rng), n);
            assert!(m.abs() < 2.0 * tolerance, "mean {m}");
            assert!((s - 1.0).abs() < 4.0 * tolerance, "std {s}");
        }
        let hits = (0..n).filter(|_| rng.bernoulli(0.273)).count() as f64 / n as f64;
        assert!((hits - 0.273).abs() < tolerance, "{hits}");
    }
}
