//! [`FastDiv`]: `u32` division by a fixed divisor with one 64×64→128-bit
//! multiply (Lemire, Kaser & Kurz 2019), exact for every `u32` dividend.
//! The hot loops that turn linear indices back into coordinates (the
//! resampler's tetrahedron decoder, the opacity growth's lattice) use it
//! instead of hardware division. It lives in core because both
//! `voxflex-resample` and `voxflex-opacity` use it.

/// Division by a fixed `u32` (a divisor of 0 is taken as 1).
#[derive(Clone, Copy, Debug)]
pub struct FastDiv {
    m: u64,
    d: u32,
}

impl FastDiv {
    /// A divider by `d` (0 → 1).
    pub fn new(d: u32) -> Self {
        let d = d.max(1);
        Self {
            m: if d == 1 { 0 } else { u64::MAX / d as u64 + 1 },
            d,
        }
    }

    /// `n / d`.
    #[inline(always)]
    pub fn div(&self, n: u32) -> u32 {
        if self.d == 1 {
            n
        } else {
            ((self.m as u128 * n as u128) >> 64) as u32
        }
    }

    /// `(n / d, n % d)`.
    #[inline(always)]
    pub fn div_rem(&self, n: u32) -> (u32, u32) {
        let q = self.div(n);
        (q, n - q * self.d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_for_every_kind_of_dividend() {
        for d in [1u32, 2, 3, 7, 255, 256, 1000, u32::MAX] {
            let f = FastDiv::new(d);
            for n in [0u32, 1, 6, 7, 8, 1 << 31, u32::MAX - 3, u32::MAX] {
                assert_eq!(f.div_rem(n), (n / d, n % d), "{n} / {d}");
            }
        }
        assert_eq!(FastDiv::new(0).div_rem(5), (5, 0));
    }
}
