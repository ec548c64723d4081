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

/// Linear thresholds at which the 8-bit sRGB code steps up: code `n` is the
/// number of thresholds `≤ x`. Built once from the exact formula, so the
/// lookup equals `round(linear_to_srgb(x) · 255)` without a `powf` per pixel.
fn thresholds() -> &'static [f32; 255] {
    static T: OnceLock<[f32; 255]> = OnceLock::new();
    T.get_or_init(|| {
        let mut t = [0f32; 255];
        for (n, slot) in t.iter_mut().enumerate() {
            // Smallest x whose encoding rounds to code n+1: the encoding equals (n + 0.5)/255.
            let target = (n as f64 + 0.5) / 255.0;
            let x = if target <= 0.003_130_8 * 12.92 {
                target / 12.92
            } else {
                ((target + 0.055) / 1.055).powf(2.4)
            };
            *slot = x as f32;
        }
        t
    })
}

/// Linear component → 8-bit sRGB code (NaN → 0).
#[inline]
pub fn linear_to_srgb8(x: f32) -> u8 {
    if x.is_nan() {
        return 0;
    }
    thresholds().partition_point(|&t| t <= x) as u8
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
    [
        linear_to_srgb8(premultiplied[0] * inv),
        linear_to_srgb8(premultiplied[1] * inv),
        linear_to_srgb8(premultiplied[2] * inv),
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

    #[test]
    fn transparent_pixels_encode_to_zero() {
        assert_eq!(encode_pixel([0.3, 0.2, 0.1, 0.0]), [0; 4]);
        assert_eq!(encode_pixel([0.5, 0.5, 0.5, 0.5])[3], 128);
    }
}
