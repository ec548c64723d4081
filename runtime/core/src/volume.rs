//! [`Volume`]: voxel values on a [`Grid`], in one of the scalar types medical
//! images use (u8, i16, u16, f32).

use crate::grid::Grid;

/// The scalar type of a volume's voxels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum ScalarType {
    /// Unsigned 8-bit (MRI, label maps).
    U8 = 0,
    /// Signed 16-bit (CT in Hounsfield units).
    I16 = 1,
    /// Unsigned 16-bit (MRI).
    U16 = 2,
    /// 32-bit float (derived fields, resampled output).
    F32 = 3,
}

impl ScalarType {
    /// Bytes per voxel.
    pub fn size_bytes(self) -> usize {
        match self {
            ScalarType::U8 => 1,
            ScalarType::I16 | ScalarType::U16 => 2,
            ScalarType::F32 => 4,
        }
    }

    /// Lower-case name (`u8`, `i16`, `u16`, `f32`).
    pub fn name(self) -> &'static str {
        match self {
            ScalarType::U8 => "u8",
            ScalarType::I16 => "i16",
            ScalarType::U16 => "u16",
            ScalarType::F32 => "f32",
        }
    }

    /// The type with this `#[repr(u32)]` code, if any.
    pub fn from_code(code: u32) -> Option<Self> {
        match code {
            0 => Some(Self::U8),
            1 => Some(Self::I16),
            2 => Some(Self::U16),
            3 => Some(Self::F32),
            _ => None,
        }
    }
}

/// A voxel scalar that converts losslessly (or, for f32, exactly) to `f32`.
pub trait Sample: Copy + Send + Sync + 'static {
    /// The scalar type tag.
    const TYPE: ScalarType;
    /// The value as `f32`.
    fn to_f32(self) -> f32;
    /// The nearest representable value to `v`, saturating at the type's range.
    fn from_f32(v: f32) -> Self;
}

impl Sample for u8 {
    const TYPE: ScalarType = ScalarType::U8;
    #[inline]
    fn to_f32(self) -> f32 {
        self as f32
    }
    #[inline]
    fn from_f32(v: f32) -> Self {
        v.round() as u8
    }
}
impl Sample for i16 {
    const TYPE: ScalarType = ScalarType::I16;
    #[inline]
    fn to_f32(self) -> f32 {
        self as f32
    }
    #[inline]
    fn from_f32(v: f32) -> Self {
        v.round() as i16
    }
}
impl Sample for u16 {
    const TYPE: ScalarType = ScalarType::U16;
    #[inline]
    fn to_f32(self) -> f32 {
        self as f32
    }
    #[inline]
    fn from_f32(v: f32) -> Self {
        v.round() as u16
    }
}
impl Sample for f32 {
    const TYPE: ScalarType = ScalarType::F32;
    #[inline]
    fn to_f32(self) -> f32 {
        self
    }
    #[inline]
    fn from_f32(v: f32) -> Self {
        v
    }
}

/// Owned voxel values, x fastest.
#[derive(Clone, Debug, PartialEq)]
pub enum VoxelData {
    /// Unsigned 8-bit values.
    U8(Vec<u8>),
    /// Signed 16-bit values.
    I16(Vec<i16>),
    /// Unsigned 16-bit values.
    U16(Vec<u16>),
    /// 32-bit float values.
    F32(Vec<f32>),
}

/// Borrowed voxel values, x fastest.
#[derive(Clone, Copy, Debug)]
pub enum VoxelSlice<'a> {
    /// Unsigned 8-bit values.
    U8(&'a [u8]),
    /// Signed 16-bit values.
    I16(&'a [i16]),
    /// Unsigned 16-bit values.
    U16(&'a [u16]),
    /// 32-bit float values.
    F32(&'a [f32]),
}

/// Runs `$body` with `$s` bound to the typed slice inside a [`VoxelSlice`].
#[macro_export]
macro_rules! with_voxels {
    ($slice:expr, |$s:ident| $body:expr) => {
        match $slice {
            $crate::volume::VoxelSlice::U8($s) => $body,
            $crate::volume::VoxelSlice::I16($s) => $body,
            $crate::volume::VoxelSlice::U16($s) => $body,
            $crate::volume::VoxelSlice::F32($s) => $body,
        }
    };
}

impl VoxelData {
    /// Borrow the values.
    pub fn as_slice(&self) -> VoxelSlice<'_> {
        match self {
            VoxelData::U8(v) => VoxelSlice::U8(v),
            VoxelData::I16(v) => VoxelSlice::I16(v),
            VoxelData::U16(v) => VoxelSlice::U16(v),
            VoxelData::F32(v) => VoxelSlice::F32(v),
        }
    }
}

impl<'a> VoxelSlice<'a> {
    /// Number of voxels.
    pub fn len(&self) -> usize {
        with_voxels!(*self, |s| s.len())
    }
    /// True when there is no voxel.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The scalar type.
    pub fn scalar_type(&self) -> ScalarType {
        match self {
            VoxelSlice::U8(_) => ScalarType::U8,
            VoxelSlice::I16(_) => ScalarType::I16,
            VoxelSlice::U16(_) => ScalarType::U16,
            VoxelSlice::F32(_) => ScalarType::F32,
        }
    }
    /// Value of voxel `l` (linear index) as `f32`.
    #[inline]
    pub fn get_f32(&self, l: usize) -> f32 {
        with_voxels!(*self, |s| s[l].to_f32())
    }
    /// Raw bytes of the values (native endianness).
    pub fn as_bytes(&self) -> &'a [u8] {
        match *self {
            VoxelSlice::U8(s) => s,
            VoxelSlice::I16(s) => bytemuck::cast_slice(s),
            VoxelSlice::U16(s) => bytemuck::cast_slice(s),
            VoxelSlice::F32(s) => bytemuck::cast_slice(s),
        }
    }
    /// All values converted to `f32` (allocates).
    pub fn to_f32_vec(&self) -> Vec<f32> {
        with_voxels!(*self, |s| s.iter().map(|v| v.to_f32()).collect())
    }
}

/// A scalar volume: voxel values on a [`Grid`].
#[derive(Clone, Debug, PartialEq)]
pub struct Volume {
    /// Geometry (voxel index ↔ world millimetres).
    pub grid: Grid,
    /// Values, `grid.len()` of them, x fastest.
    pub data: VoxelData,
}

/// A borrowed volume: what crosses into plugins and services.
#[derive(Clone, Copy, Debug)]
pub struct VolumeView<'a> {
    /// Geometry (voxel index ↔ world millimetres).
    pub grid: Grid,
    /// Values, `grid.len()` of them, x fastest.
    pub data: VoxelSlice<'a>,
}

impl Volume {
    /// A volume, checking that `data` holds exactly `grid.len()` values.
    pub fn new(grid: Grid, data: VoxelData) -> Result<Self, crate::error::VolumeError> {
        let n = data.as_slice().len();
        if n != grid.len() {
            return Err(crate::error::VolumeError::SizeMismatch {
                dims: grid.dims,
                expected: grid.len(),
                actual: n,
            });
        }
        Ok(Self { grid, data })
    }

    /// Borrow as a [`VolumeView`].
    pub fn view(&self) -> VolumeView<'_> {
        VolumeView {
            grid: self.grid,
            data: self.data.as_slice(),
        }
    }

    /// The scalar type of the voxels.
    pub fn scalar_type(&self) -> ScalarType {
        self.data.as_slice().scalar_type()
    }

    /// Value of voxel `(i, j, k)` as `f32`.
    pub fn get_f32(&self, i: usize, j: usize, k: usize) -> f32 {
        self.data.as_slice().get_f32(self.grid.linear(i, j, k))
    }

    /// Smallest and largest value (NaN ignored); `(0, 0)` for an empty volume.
    pub fn value_range(&self) -> (f32, f32) {
        self.view().value_range()
    }
}

impl VolumeView<'_> {
    /// Smallest and largest **finite** value (NaN and ±∞ ignored); `(0, 0)`
    /// when no voxel is finite.
    pub fn value_range(&self) -> (f32, f32) {
        finite_range(self.data).unwrap_or((0.0, 0.0))
    }
}

/// Smallest and largest finite value of `data`; `None` when none is finite.
pub fn finite_range(data: VoxelSlice<'_>) -> Option<(f32, f32)> {
    use rayon::prelude::*;
    let (lo, hi) = with_voxels!(data, |s| s
        .par_chunks(1 << 16)
        .map(|c| c
            .iter()
            .map(|v| v.to_f32())
            .filter(|v| v.is_finite())
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(v), hi.max(v))
            }))
        .reduce(
            || (f32::INFINITY, f32::NEG_INFINITY),
            |a, b| (a.0.min(b.0), a.1.max(b.1))
        ));
    (lo <= hi).then_some((lo, hi))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn new_checks_length() {
        let g = Grid::new([2, 2, 2], DVec3::ONE, DVec3::ZERO);
        assert!(Volume::new(g, VoxelData::U8(vec![0; 7])).is_err());
        let v = Volume::new(g, VoxelData::I16((0..8).map(|x| x - 3).collect())).unwrap();
        assert_eq!(v.value_range(), (-3.0, 4.0));
        assert_eq!(v.get_f32(1, 1, 1), 4.0);
    }

    #[test]
    fn value_range_ignores_nan_and_infinities() {
        let g = Grid::new([2, 2, 1], DVec3::ONE, DVec3::ZERO);
        let v = Volume::new(
            g,
            VoxelData::F32(vec![f32::NAN, f32::INFINITY, -3.0, f32::NEG_INFINITY]),
        )
        .unwrap();
        assert_eq!(v.value_range(), (-3.0, -3.0));
        let none = Volume::new(g, VoxelData::F32(vec![f32::NAN; 4])).unwrap();
        assert_eq!(none.value_range(), (0.0, 0.0));
    }
}
