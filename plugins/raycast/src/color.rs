//! Colour spaces.
//!
//! **Decision:** colours are **sRGB at every interface** — transfer-function
//! control points, the background colour and the output image — and
//! **linear inside**: the transfer-function table holds linear RGB, shading
//! and front-to-back compositing add light linearly, and the final pixel is
//! encoded to sRGB once. An unshaded opaque slab of TF colour `c` therefore
//! comes out as exactly `c`. Alpha is never gamma-encoded.

use std::sync::OnceLock;

/// sRGB-encoded component in [0, 1] → linear light (IEC 61966-2-1).
#[inline]
pub fn srgb_to_linear(c: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear component in [0, 1] → sRGB-encoded in [0, 1] (IEC 61966-2-1).
#[inline]
pub fn linear_to_srgb(c: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// Bins of [`Encoder::start`] over [0, 1] (a power of two, so `x · BINS`
/// and `b / BINS` are exact in f32).
const BINS: usize = 1024;

/// The linear → 8-bit sRGB encoding as a table: `thresholds[n]` is the
/// linear value at which the code steps up to `n + 1` (code `c` is the
/// number of thresholds `≤ x`), built once from the exact formula, so the
/// code equals `round(linear_to_srgb(x) · 255)` without a `powf` per pixel.
/// `start[b]` is the code at `b / BINS`: the search starts there and steps
/// over the (at most four, near 0) thresholds between — exact, and a few
/// comparisons instead of a binary search over 255.
struct Encoder {
    thresholds: [f32; 255],
    start: [u8; BINS],
}

fn encoder() -> &'static Encoder {
    static E: OnceLock<Encoder> = OnceLock::new();
    E.get_or_init(|| {
        let mut thresholds = [0f32; 255];
        for (n, slot) in thresholds.iter_mut().enumerate() {
            // Smallest x whose encoding rounds to code n+1: the encoding equals (n + 0.5)/255.
            let target = (n as f64 + 0.5) / 255.0;
            let x = if target <= 0.003_130_8 * 12.92 {
                target / 12.92
            } else {
                ((target + 0.055) / 1.055).powf(2.4)
            };
            *slot = x as f32;
        }
        let start = std::array::from_fn(|b| {
            let x = b as f32 / BINS as f32;
            thresholds.partition_point(|&t| t <= x) as u8
        });
        Encoder { thresholds, start }
    })
}

impl Encoder {
    #[inline]
    fn code(&self, x: f32) -> u8 {
        if x.is_nan() || x <= 0.0 {
            // Negative, zero or NaN: below every threshold.
            return 0;
        }
        if x >= 1.0 {
            return 255;
        }
        let mut n = self.start[(x * BINS as f32) as usize] as usize;
        while n < 255 && self.thresholds[n] <= x {
            n += 1;
        }
        n as u8
    }
}

/// Linear component → 8-bit sRGB code (NaN → 0).
#[inline]
pub fn linear_to_srgb8(x: f32) -> u8 {
    encoder().code(x)
}

/// Component in [0, 1] → 8-bit code, rounded (NaN → 0). Used for alpha.
#[inline]
pub fn unorm8(x: f32) -> u8 {
    (x.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// A pixel accumulated in linear, premultiplied RGBA → straight-alpha sRGB RGBA8.
#[inline]
pub fn encode_pixel(premultiplied: [f32; 4]) -> [u8; 4] {
    let a = premultiplied[3];
    if a <= 0.0 || a.is_nan() {
        return [0, 0, 0, 0];
    }
    let inv = 1.0 / a;
    let e = encoder();
    [
        e.code(premultiplied[0] * inv),
        e.code(premultiplied[1] * inv),
        e.code(premultiplied[2] * inv),
        unorm8(a),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trips() {
        for i in 0..=255u8 {
            let c = i as f32 / 255.0;
            assert_eq!(linear_to_srgb8(srgb_to_linear(c)), i, "code {i}");
            assert!((linear_to_srgb(srgb_to_linear(c)) - c).abs() < 1e-5);
        }
    }

    #[test]
    fn table_encoding_matches_the_formula() {
        for n in 0..=4000 {
            let x = n as f32 / 4000.0;
            let exact = (linear_to_srgb(x) * 255.0).round() as i32;
            assert!((linear_to_srgb8(x) as i32 - exact).abs() <= 1, "x = {x}");
        }
        assert_eq!(linear_to_srgb8(f32::NAN), 0);
        assert_eq!(linear_to_srgb8(2.0), 255);
        assert_eq!(linear_to_srgb8(-1.0), 0);
    }

    /// The table search equals a binary search over the thresholds at
    /// every threshold, one float either side of it, and across [−1, 2].
    #[test]
    fn table_search_equals_the_binary_search() {
        let e = encoder();
        let binary = |x: f32| {
            if x.is_nan() {
                0
            } else {
                e.thresholds.partition_point(|&t| t <= x) as u8
            }
        };
        let mut xs: Vec<f32> = (-1000..=20_000).map(|n| n as f32 / 10_000.0).collect();
        for &t in &e.thresholds {
            xs.extend([t, t.next_down(), t.next_up()]);
        }
        xs.extend([
            0.0,
            -0.0,
            1.0,
            1.0f32.next_down(),
            f32::MIN_POSITIVE,
            f32::NAN,
            f32::INFINITY,
        ]);
        for x in xs {
            assert_eq!(e.code(x), binary(x), "x = {x:e}");
        }
    }

    #[test]
    fn transparent_pixels_encode_to_zero() {
        assert_eq!(encode_pixel([0.3, 0.2, 0.1, 0.0]), [0; 4]);
        assert_eq!(encode_pixel([0.5, 0.5, 0.5, 0.5])[3], 128);
    }
}
