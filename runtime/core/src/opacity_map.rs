//! [`OpacityMap`]: a spatial opacity field over a box of a volume's voxels
//! (the ROI maps of "Spatial opacity maps for direct volume rendering of
//! regions of interest", CEIG 2016), stored as u16 fixed point.
//!
//! Storage decision: u16 fixed point, `o = q / 65535`, 2 bytes per voxel of
//! the map's bounding box. u8 (1/255 steps) is too coarse for the region
//! growing's extinction steps `E_v`, which are often below 1/255 near the
//! seed's intensity, and would stall the growth; f32 would double the memory.
//! The quantisation error (≤ 7.7e-6) is below the CPU/GPU agreement tolerance.

/// Opacity of a voxel box, u16 fixed point (`value / 65535`).
#[derive(Clone, Debug, PartialEq)]
pub struct OpacityMap {
    /// First voxel of the box, **voxel indices** of the volume the map belongs to.
    pub origin: [usize; 3],
    /// Box size, voxels.
    pub dims: [usize; 3],
    /// Opacity of voxels outside the box (`o_min`), fixed point.
    pub outside: u16,
    /// Opacities inside the box, x fastest, fixed point.
    pub values: Vec<u16>,
}

/// Fixed-point scale: `opacity = value / OPACITY_ONE`.
pub const OPACITY_ONE: f32 = 65535.0;

/// Opacity in [0, 1] → fixed point (rounded, clamped).
#[inline]
pub fn to_fixed(o: f32) -> u16 {
    (o.clamp(0.0, 1.0) * OPACITY_ONE).round() as u16
}

/// Fixed point → opacity in [0, 1].
#[inline]
pub fn from_fixed(q: u16) -> f32 {
    q as f32 / OPACITY_ONE
}

impl OpacityMap {
    /// Opacity at volume voxel `(i, j, k)`, in [0, 1].
    #[inline]
    pub fn get(&self, i: usize, j: usize, k: usize) -> f32 {
        let [ox, oy, oz] = self.origin;
        let [nx, ny, nz] = self.dims;
        if i < ox || j < oy || k < oz || i >= ox + nx || j >= oy + ny || k >= oz + nz {
            return from_fixed(self.outside);
        }
        from_fixed(self.values[(i - ox) + nx * ((j - oy) + ny * (k - oz))])
    }

    /// The volume voxel index `(i, j, k)` of the box's value `l` (`values[l]`).
    #[inline]
    pub fn voxel(&self, l: usize) -> [usize; 3] {
        let (x, r) = (l % self.dims[0], l / self.dims[0]);
        [
            self.origin[0] + x,
            self.origin[1] + r % self.dims[1],
            self.origin[2] + r / self.dims[1],
        ]
    }

    /// The fixed-point opacity of every voxel of a volume of `volume_dims`
    /// voxels (x fastest; [`Self::outside`] beyond the box).
    pub fn dense(&self, volume_dims: [usize; 3]) -> Vec<u16> {
        let mut out = vec![self.outside; volume_dims.iter().product()];
        for (l, &q) in self.values.iter().enumerate() {
            let [i, j, k] = self.voxel(l);
            out[i + volume_dims[0] * (j + volume_dims[1] * k)] = q;
        }
        out
    }

    /// Bytes of storage (2 per voxel of the box).
    pub fn bytes(&self) -> usize {
        self.values.len() * std::mem::size_of::<u16>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_point_round_trips_within_half_a_step() {
        for o in [0.0f32, 0.03, 0.5, 0.999, 1.0] {
            assert!((from_fixed(to_fixed(o)) - o).abs() <= 0.5 / OPACITY_ONE + f32::EPSILON);
        }
        assert_eq!(to_fixed(2.0), u16::MAX);
        assert_eq!(to_fixed(-1.0), 0);
    }

    #[test]
    fn outside_the_box_reads_outside() {
        let m = OpacityMap {
            origin: [1, 1, 1],
            dims: [1, 1, 1],
            outside: to_fixed(0.03),
            values: vec![u16::MAX],
        };
        assert_eq!(m.get(1, 1, 1), 1.0);
        assert!((m.get(0, 1, 1) - 0.03).abs() < 1e-4);
        assert_eq!(m.bytes(), 2);
    }
}
