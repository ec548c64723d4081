//! 8-bit grayscale PNG snapshots of one slice of a volume, through a
//! window/level.
//!
//! One pixel per voxel in [`render_slice`]; [`write_slice_png`] stretches
//! an anisotropic slice to square pixels. Orientation,
//! chosen so that a volume whose voxel axes follow the DICOM/LPS convention
//! (x toward the patient's left, y posterior, z superior — as ITK, DICOM and
//! voxflex's phantoms) is shown upright in the radiological convention:
//!
//! | axis | fixed | image column (left → right) | image row (top → bottom) |
//! |---|---|---|---|
//! | [`SliceAxis::Axial`] | z = index | +x | +y (anterior at the top) |
//! | [`SliceAxis::Coronal`] | y = index | +x | −z (head at the top) |
//! | [`SliceAxis::Sagittal`] | x = index | +y (anterior on the left) | −z (head at the top) |
//!
//! The readers reorder every file's voxels into that LPS grid
//! ([`crate::orientation`]), so files stored in any axis order show
//! this way too.

use super::write_atomically;
use crate::error::IoError;
use crate::volume::{Sample, VolumeView};
use image::ImageEncoder;
use rayon::prelude::*;
use std::path::Path;

pub use voxflex_core::slice_axis::SliceAxis;

/// A display window in the volume's value units (e.g. Hounsfield units):
/// values `≤ level − width/2` are black, `≥ level + width/2` white, linear in
/// between.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Window {
    /// Centre of the window (value shown mid-gray).
    pub level: f32,
    /// Width of the window (value range spanning black to white); > 0.
    pub width: f32,
}

impl Window {
    /// CT brain window (level 40 HU, width 80 HU).
    pub const CT_BRAIN: Window = Window {
        level: 40.0,
        width: 80.0,
    };
    /// CT soft-tissue window (level 40 HU, width 400 HU).
    pub const CT_SOFT_TISSUE: Window = Window {
        level: 40.0,
        width: 400.0,
    };
    /// CT bone window (level 400 HU, width 1800 HU).
    pub const CT_BONE: Window = Window {
        level: 400.0,
        width: 1800.0,
    };

    /// A window with the given level and width.
    pub fn new(level: f32, width: f32) -> Self {
        Self { level, width }
    }

    /// The window mapping `lo` to black and `hi` to white (a zero-width
    /// range gets width 1).
    pub fn from_range(lo: f32, hi: f32) -> Self {
        let width = (hi - lo).abs();
        let width = if width > 0.0 && width.is_finite() {
            width
        } else {
            1.0
        };
        Self {
            level: 0.5 * (lo + hi),
            width,
        }
    }

    /// True when level and width are finite and width is positive.
    pub fn is_valid(&self) -> bool {
        self.level.is_finite() && self.width.is_finite() && self.width > 0.0
    }

    /// The gray value (0–255) of `v`; NaN maps to 0.
    #[inline]
    pub fn map(&self, v: f32) -> u8 {
        let lo = self.level - 0.5 * self.width;
        let t = (v - lo) / self.width * 255.0;
        // `as u8` saturates and maps NaN to 0.
        t.round() as u8
    }
}

/// Why a slice cannot be rendered.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SliceError {
    /// The index is outside the volume along the fixed axis.
    #[error("{axis} slice index {index} is outside the volume (0..{len} along {})", .axis.letter())]
    IndexOutOfRange {
        /// The slice axis.
        axis: SliceAxis,
        /// The index asked for.
        index: usize,
        /// Number of slices along that axis.
        len: usize,
    },
    /// The window's width is not positive or a value is not finite.
    #[error("window level {level} / width {width} is invalid: width must be finite and > 0")]
    InvalidWindow {
        /// Level asked for.
        level: f32,
        /// Width asked for.
        width: f32,
    },
    /// The view's values disagree with its grid.
    #[error("volume has {values} values but its dims {dims:?} need {needed}")]
    SizeMismatch {
        /// Grid dims.
        dims: [usize; 3],
        /// Values present.
        values: usize,
        /// Values needed.
        needed: usize,
    },
}

/// An 8-bit grayscale image, row-major, top row first.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GrayImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `width * height` gray values, row-major, top row first.
    pub pixels: Vec<u8>,
}

/// Renders slice `index` (voxel index along the fixed axis) through `window`,
/// oriented as in the module docs.
pub fn render_slice(
    volume: VolumeView<'_>,
    axis: SliceAxis,
    index: usize,
    window: Window,
) -> Result<GrayImage, SliceError> {
    let g = volume.grid;
    if volume.data.len() != g.len() {
        return Err(SliceError::SizeMismatch {
            dims: g.dims,
            values: volume.data.len(),
            needed: g.len(),
        });
    }
    if !window.is_valid() {
        return Err(SliceError::InvalidWindow {
            level: window.level,
            width: window.width,
        });
    }
    let len = g.dims[axis.fixed_axis()];
    if index >= len {
        return Err(SliceError::IndexOutOfRange { axis, index, len });
    }
    let (width, height) = axis.image_size(&g);
    let mut pixels = vec![0u8; width * height];
    let nz = g.dims[2];
    crate::with_voxels!(volume.data, |s| {
        pixels
            .par_chunks_mut(width.max(1))
            .enumerate()
            .for_each(|(row, out)| {
                for (col, px) in out.iter_mut().enumerate() {
                    let (i, j, k) = match axis {
                        SliceAxis::Axial => (col, row, index),
                        SliceAxis::Coronal => (col, index, nz - 1 - row),
                        SliceAxis::Sagittal => (index, col, nz - 1 - row),
                    };
                    *px = window.map(s[g.linear(i, j, k)].to_f32());
                }
            })
    });
    Ok(GrayImage {
        width,
        height,
        pixels,
    })
}

/// Writes slice `index` of `volume` as an 8-bit grayscale PNG through
/// `window` (see the module docs for orientation), in square pixels: on an
/// anisotropic grid the coarser axis is stretched (bilinear) so the image
/// has the slice's proportions in millimetres. Atomic: see
/// [`write_atomically`].
///
/// An index outside the volume or an invalid window is an
/// [`IoError::InvalidRequest`] naming the file.
pub fn write_slice_png(
    path: &Path,
    volume: VolumeView<'_>,
    axis: SliceAxis,
    index: usize,
    window: Window,
) -> Result<(), IoError> {
    let img = render_slice(volume, axis, index, window).map_err(|e| IoError::InvalidRequest {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    write_gray_png(path, &square_pixels(img, axis.pixel_mm(&volume.grid)))
}

/// Largest side (pixels) [`square_pixels`] stretches an image to.
const MAX_STRETCHED_SIDE: f64 = 8192.0;

/// `img`, whose pixels are `pixel_mm` (width, height) millimetres, resized
/// so its pixels are square (the finer size), within
/// [`MAX_STRETCHED_SIDE`]; unchanged when they already are.
fn square_pixels(img: GrayImage, (w_mm, h_mm): (f64, f64)) -> GrayImage {
    let fine = w_mm.min(h_mm);
    if !fine.is_finite() || fine <= 0.0 || (w_mm - h_mm).abs() <= 1e-9 * fine {
        return img;
    }
    let (mut w, mut h) = (
        img.width as f64 * w_mm / fine,
        img.height as f64 * h_mm / fine,
    );
    let shrink = (MAX_STRETCHED_SIDE / w.max(h)).min(1.0);
    (w, h) = ((w * shrink).round().max(1.0), (h * shrink).round().max(1.0));
    let buffer = image::GrayImage::from_raw(img.width as u32, img.height as u32, img.pixels)
        .expect("a rendered slice holds width × height pixels");
    let out = image::imageops::resize(
        &buffer,
        w as u32,
        h as u32,
        image::imageops::FilterType::Triangle,
    );
    GrayImage {
        width: out.width() as usize,
        height: out.height() as usize,
        pixels: out.into_raw(),
    }
}

/// Writes a [`GrayImage`] as an 8-bit grayscale PNG, atomically.
pub fn write_gray_png(path: &Path, img: &GrayImage) -> Result<(), IoError> {
    let too_big = || IoError::InvalidRequest {
        path: path.to_path_buf(),
        message: format!("image {} × {} is too large for PNG", img.width, img.height),
    };
    let w = u32::try_from(img.width).map_err(|_| too_big())?;
    let h = u32::try_from(img.height).map_err(|_| too_big())?;
    if img.pixels.len() != img.width * img.height || w == 0 || h == 0 {
        return Err(IoError::InvalidRequest {
            path: path.to_path_buf(),
            message: format!(
                "image {} × {} with {} pixels cannot be written",
                img.width,
                img.height,
                img.pixels.len()
            ),
        });
    }
    write_atomically(path, |out| {
        image::codecs::png::PngEncoder::new(out)
            .write_image(&img.pixels, w, h, image::ExtendedColorType::L8)
            .map_err(std::io::Error::other)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Grid;
    use crate::volume::{Volume, VoxelData};
    use glam::DVec3;

    /// Value = 100 i + 10 j + k, dims 4 × 3 × 2.
    fn vol() -> Volume {
        let g = Grid::new([4, 3, 2], DVec3::ONE, DVec3::ZERO);
        let data = (0..g.len())
            .map(|l| {
                let [i, j, k] = g.unlinear(l);
                (100 * i + 10 * j + k) as i16
            })
            .collect();
        Volume::new(g, VoxelData::I16(data)).unwrap()
    }

    /// Identity window on 0..=255.
    const ID: Window = Window {
        level: 127.5,
        width: 255.0,
    };

    #[test]
    fn orientation() {
        let v = vol();
        let a = render_slice(v.view(), SliceAxis::Axial, 1, ID).unwrap();
        assert_eq!((a.width, a.height), (4, 3));
        // Row 0 = j 0, column = i.
        assert_eq!(&a.pixels[..4], &[1, 101, 201, 255]);
        assert_eq!(a.pixels[4], 11);
        let c = render_slice(v.view(), SliceAxis::Coronal, 2, ID).unwrap();
        assert_eq!((c.width, c.height), (4, 2));
        // Top row is the highest z.
        assert_eq!(&c.pixels[..4], &[21, 121, 221, 255]);
        assert_eq!(c.pixels[4], 20);
        let s = render_slice(v.view(), SliceAxis::Sagittal, 1, ID).unwrap();
        assert_eq!((s.width, s.height), (3, 2));
        assert_eq!(&s.pixels[..3], &[101, 111, 121]);
        assert_eq!(&s.pixels[3..], &[100, 110, 120]);
    }

    #[test]
    fn window_mapping() {
        let w = Window::CT_BRAIN;
        assert_eq!(w.map(0.0), 0);
        assert_eq!(w.map(-1000.0), 0);
        assert_eq!(w.map(40.0), 128);
        assert_eq!(w.map(80.0), 255);
        assert_eq!(w.map(f32::NAN), 0);
        assert_eq!(Window::from_range(10.0, 20.0).map(20.0), 255);
        assert!(Window::from_range(5.0, 5.0).is_valid());
    }

    #[test]
    fn writes_png_and_refuses_bad_requests() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("slice.png");
        let v = vol();
        write_slice_png(&p, v.view(), SliceAxis::Coronal, 0, ID).unwrap();
        let img = image::open(&p).unwrap().into_luma8();
        assert_eq!(img.dimensions(), (4, 2));
        assert_eq!(img.get_pixel(1, 0).0[0], 101);
        assert_eq!(img.get_pixel(0, 1).0[0], 0);

        let msg = write_slice_png(&p, v.view(), SliceAxis::Axial, 2, ID)
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("slice.png") && msg.contains("axial slice index 2"),
            "{msg}"
        );
        assert!(msg.contains("0..2 along z"), "{msg}");
        let msg = write_slice_png(&p, v.view(), SliceAxis::Axial, 0, Window::new(0.0, 0.0))
            .unwrap_err()
            .to_string();
        assert!(msg.contains("width must be finite"), "{msg}");
        // The earlier good file is intact.
        assert_eq!(image::open(&p).unwrap().into_luma8().dimensions(), (4, 2));

        // 3 mm slices under 1 mm pixels: the coronal image is stretched to
        // its proportions in mm, z rows three pixels tall (head at the top:
        // k = 1, value 101 at i = 1).
        let mut thick = vol();
        thick.grid.spacing = DVec3::new(1.0, 1.0, 3.0);
        write_slice_png(&p, thick.view(), SliceAxis::Coronal, 0, ID).unwrap();
        let img = image::open(&p).unwrap().into_luma8();
        assert_eq!(img.dimensions(), (4, 6));
        assert_eq!(img.get_pixel(1, 0).0[0], 101);
        assert_eq!(img.get_pixel(1, 5).0[0], 100);
        assert_eq!("Z".parse::<SliceAxis>(), Ok(SliceAxis::Axial));
        assert!("oblique".parse::<SliceAxis>().is_err());
    }
}
