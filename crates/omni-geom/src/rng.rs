//! The project's one deterministic PRNG (SplitMix64): rendered noise, RANSAC sampling, fault
//! injection and test data all draw from it, so the same seed gives the same numbers on every
//! platform and with every version of every crate.

/// SplitMix64 (Steele, Lea & Flood 2014): 64-bit state, passes BigCrush, trivially seedable.
#[derive(Debug, Clone)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }

    /// A generator for a sub-stream `key` of `seed` (e.g. one image row), decorrelated by hashing.
    pub fn stream(seed: u64, key: u64) -> Self {
        SplitMix64(mix(seed ^ mix(key.wrapping_add(0x9E37_79B9_7F4A_7C15))))
    }

    /// A generator for the pixel at column `x`, row `y` of an image drawn under `seed`. Each
    /// pixel draws from its own stream, so that a draw taking more or fewer values (a Poisson
    /// count, a rejection) changes no other pixel's noise.
    pub fn pixel(seed: u64, x: usize, y: usize) -> Self {
        Self::stream(seed, ((y as u64) << 32) | x as u64)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix(self.0)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform integer in [0, n) for n > 0 (multiply-shift: no modulo bias worth a name).
    pub fn below(&mut self, n: usize) -> usize {
        (((self.next_u64() >> 32) * n as u64) >> 32) as usize
    }

    /// True with probability `p` (never for p ≤ 0).
    pub fn chance(&mut self, p: f64) -> bool {
        p > 0.0 && self.uniform() < p
    }

    /// Standard normal (Box–Muller; one value per call).
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform(); // (0, 1]
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// Poisson with mean `lambda`: exact (Knuth) below 40, normal approximation above, where
    /// the two are indistinguishable at the precision of an image sensor.
    pub fn poisson(&mut self, lambda: f64) -> f64 {
        if !(lambda > 0.0) {
            return 0.0;
        }
        if lambda < 40.0 {
            let limit = (-lambda).exp();
            let mut k = 0.0;
            let mut p = self.uniform();
            while p > limit {
                k += 1.0;
                p *= self.uniform();
            }
            k
        } else {
            (lambda + lambda.sqrt() * self.normal()).round().max(0.0)
        }
    }
}

impl SplitMix64 {
    /// Gamma with shape `k` ≥ 1 and scale 1 (Marsaglia & Tsang 2000).
    pub fn gamma(&mut self, k: f64) -> f64 {
        let d = k.max(1.0) - 1.0 / 3.0;
        let c = 1.0 / (9.0 * d).sqrt();
        loop {
            let x = self.normal();
            let v = (1.0 + c * x).powi(3);
            if v <= 0.0 {
                continue;
            }
            let u = self.uniform();
            if u.ln() < 0.5 * x * x + d - d * v + d * v.ln() {
                return d * v;
            }
        }
    }
}

/// The SplitMix64 output function.
pub fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn below_and_chance_are_uniform() {
        let mut r = SplitMix64::new(3);
        let mut counts = [0usize; 5];
        for _ in 0..50_000 {
            counts[r.below(5)] += 1;
        }
        assert!(counts.iter().all(|&c| (c as f64 / 10_000.0 - 1.0).abs() < 0.05), "{counts:?}");
        let hits = (0..50_000).filter(|_| r.chance(0.3)).count();
        assert!((hits as f64 / 15_000.0 - 1.0).abs() < 0.03, "{hits}");
        assert!(!(0..1000).any(|_| r.chance(0.0)));
    }

    /// Sample mean and variance of `n` draws.
    fn moments(n: usize, mut draw: impl FnMut() -> f64) -> (f64, f64) {
        let (mut s, mut s2) = (0.0, 0.0);
        for _ in 0..n {
            let x = draw();
            s += x;
            s2 += x * x;
        }
        let mean = s / n as f64;
        (mean, s2 / n as f64 - mean * mean)
    }

    #[test]
    fn moments_match_the_distributions() {
        let mut r = SplitMix64::new(7);
        let n = 200_000;
        let (mean, var) = moments(n, || r.normal());
        assert!(mean.abs() < 0.01 && (var - 1.0).abs() < 0.01, "normal: mean {mean}, var {var}");
        for k in [1.0, 11.1] {
            let (mean, var) = moments(n, || r.gamma(k));
            assert!((mean / k - 1.0).abs() < 0.01 && (var / k - 1.0).abs() < 0.03, "gamma {k}: {mean}, {var}");
        }
        for lambda in [3.0, 25.0, 400.0] {
            let (mean, var) = moments(n, || r.poisson(lambda));
            assert!((mean / lambda - 1.0).abs() < 0.01, "mean {mean} for {lambda}");
            assert!((var / lambda - 1.0).abs() < 0.03, "var {var} for {lambda}");
        }
    }
}
