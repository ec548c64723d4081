//! [`VoxelStore`]: the CPU path's volume, kept in the volume's own scalar
//! type, and shared with the host instead of copied where the host lends
//! it.
//!
//! The rays read voxels as f32. Every type a volume may hold — u8, i16,
//! u16 — converts to f32 **exactly**, so keeping its values as they are and
//! converting each read in registers gives the same samples, bit for bit,
//! as an f32 copy would: the same image. What changes is the memory: a CT
//! (i16) takes half the bytes, an 8-bit MRI or label map a quarter. The
//! hand-over writes half or a quarter of the fresh pages (the first touch
//! of new memory is most of its cost), the macro cells and the visible
//! cells read half as many bytes, and a sample's voxel rows share cache
//! lines more often.
//!
//! A volume the host lends (`RenderVolume::Shared`, a [`SharedVolume`]) is
//! not copied at all: the store keeps the host's values (a reference
//! count), so the hand-over writes no page and the volume is in memory
//! once. The values never change while shared; an update hands over a new
//! volume, which the store shares in turn.
//!
//! f32 volumes stay f32, their NaN voxels stored as 0 (what the rays would
//! read for them anyway); a shared f32 volume holding a NaN is therefore
//! copied, not shared (a scan of the region handed over decides).
//! Indices are voxel indices, x fastest.

use crate::macrocell::IndexBox;
use rayon::prelude::*;
use voxflex_core::render::RenderVolume;
use voxflex_core::shared_volume::SharedVolume;
use voxflex_core::volume::{Sample, ScalarType, VolumeView, VoxelData, VoxelSlice};

/// The volume's values in their scalar type (x fastest), NaN-free.
#[derive(Clone, Debug)]
pub struct VoxelStore {
    values: Values,
}

/// Where a [`VoxelStore`]'s values live.
#[derive(Clone, Debug)]
enum Values {
    /// The store's own copy.
    Own(VoxelData),
    /// The host's values, lent (NaN-free).
    Shared(SharedVolume),
}

impl Default for VoxelStore {
    fn default() -> Self {
        Self {
            values: Values::Own(VoxelData::F32(Vec::new())),
        }
    }
}

impl VoxelStore {
    /// `len` zeros of type `ty`, owned.
    pub fn zeroed(ty: ScalarType, len: usize) -> Self {
        let data = match ty {
            ScalarType::U8 => VoxelData::U8(vec![0; len]),
            ScalarType::I16 => VoxelData::I16(vec![0; len]),
            ScalarType::U16 => VoxelData::U16(vec![0; len]),
            ScalarType::F32 => VoxelData::F32(vec![0.0; len]),
        };
        Self {
            values: Values::Own(data),
        }
    }

    /// True when `volume`, of `len` values, can update the store in place
    /// (only its dirty region changed): a copied volume (or a device
    /// buffer, read back as f32) updates a store of its own type and size,
    /// a shared volume one of its type and size, shared or not. Otherwise
    /// the store starts over.
    pub fn updatable_by(&self, volume: &RenderVolume<'_>, len: usize) -> bool {
        let s = self.as_slice();
        let fits = |ty: ScalarType| s.scalar_type() == ty && s.len() == len;
        match (volume, &self.values) {
            (RenderVolume::Cpu(view), Values::Own(_)) => fits(view.data.scalar_type()),
            (RenderVolume::Gpu { .. }, Values::Own(_)) => fits(ScalarType::F32),
            (RenderVolume::Shared(shared), _) => fits(shared.view().data.scalar_type()),
            (RenderVolume::Cpu(_) | RenderVolume::Gpu { .. }, Values::Shared(_)) => false,
        }
    }

    /// The values.
    pub fn as_slice(&self) -> VoxelSlice<'_> {
        match &self.values {
            Values::Own(data) => data.as_slice(),
            Values::Shared(shared) => shared.view().data,
        }
    }

    /// The values as f32 when the store holds its own f32 (what a
    /// read-back from a device buffer fills).
    pub fn f32_mut(&mut self) -> Option<&mut [f32]> {
        match &mut self.values {
            Values::Own(VoxelData::F32(v)) => Some(v),
            _ => None,
        }
    }

    /// Bytes the store itself holds (0 while it shares the host's).
    pub fn bytes(&self) -> usize {
        match &self.values {
            Values::Own(data) => {
                let s = data.as_slice();
                s.len() * s.scalar_type().size_bytes()
            }
            Values::Shared(_) => 0,
        }
    }

    /// True while the store reads the host's values.
    pub fn is_shared(&self) -> bool {
        matches!(self.values, Values::Shared(_))
    }

    /// Copies the voxels of `region` of `view` into the store (NaN as 0),
    /// first making it an owned store of `view`'s type and size (zeros) if
    /// it is not.
    pub fn copy_region(&mut self, view: &VolumeView<'_>, region: IndexBox) {
        if !self.updatable_by(&RenderVolume::Cpu(*view), view.data.len()) {
            *self = Self::zeroed(view.data.scalar_type(), view.data.len());
        }
        let Values::Own(data) = &mut self.values else {
            unreachable!("made owned above");
        };
        let dims = view.grid.dims;
        match (view.data, data) {
            (VoxelSlice::U8(s), VoxelData::U8(o)) => copy(s, dims, region, o),
            (VoxelSlice::I16(s), VoxelData::I16(o)) => copy(s, dims, region, o),
            (VoxelSlice::U16(s), VoxelData::U16(o)) => copy(s, dims, region, o),
            (VoxelSlice::F32(s), VoxelData::F32(o)) => copy(s, dims, region, o),
            _ => unreachable!("the store was made the view's type above"),
        }
    }

    /// Takes `shared`, of which `region` changed (the whole grid when the
    /// store starts over): shares it, or copies it when it holds a NaN
    /// (stored as 0). Only `region` can hold a new NaN when the store
    /// already shares the previous volume; an owned store may have turned
    /// a NaN elsewhere into 0, so then the whole volume is scanned.
    pub fn share(&mut self, shared: &SharedVolume, region: IndexBox) {
        let view = shared.view();
        let all = IndexBox::all(view.grid.dims);
        let shared_before = self.is_shared();
        if has_nan(&view, if shared_before { region } else { all }) {
            // Leaving the host's values: copy all of them.
            self.copy_region(&view, if shared_before { all } else { region });
        } else {
            self.values = Values::Shared(shared.clone());
        }
    }
}

/// True when `region` of `view` holds a NaN (f32 only; one z-plane per
/// task).
fn has_nan(view: &VolumeView<'_>, region: IndexBox) -> bool {
    let VoxelSlice::F32(values) = view.data else {
        return false;
    };
    let dims = view.grid.dims;
    let slab = dims[0] * dims[1];
    (region.lo[2]..=region.hi[2]).into_par_iter().any(|k| {
        (region.lo[1]..=region.hi[1]).any(|j| {
            let row = k * slab + j * dims[0];
            values[row + region.lo[0]..=row + region.hi[0]]
                .iter()
                .any(|v| v.is_nan())
        })
    })
}

/// Copies `region` of `src` into `out` (both the whole grid `dims`, x
/// fastest), one z-plane per task; a NaN becomes 0 (the integer types
/// have none, and their test compiles away).
fn copy<T: Sample>(src: &[T], dims: [usize; 3], region: IndexBox, out: &mut [T]) {
    let slab = dims[0] * dims[1];
    let zero = T::from_f32(0.0);
    out.par_chunks_mut(slab.max(1))
        .enumerate()
        .skip(region.lo[2])
        .take(region.hi[2] + 1 - region.lo[2])
        .for_each(|(k, plane)| {
            for j in region.lo[1]..=region.hi[1] {
                let row = j * dims[0];
                let (from, to) = (k * slab + row + region.lo[0], row + region.lo[0]);
                let n = region.hi[0] + 1 - region.lo[0];
                for (o, &v) in plane[to..to + n].iter_mut().zip(&src[from..from + n]) {
                    *o = if v.to_f32().is_nan() { zero } else { v };
                }
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxflex_core::glam::DVec3;
    use voxflex_core::grid::Grid;

    fn region() -> IndexBox {
        IndexBox {
            lo: [1, 1, 1],
            hi: [2, 2, 1],
        }
    }

    fn inside(grid: &Grid, l: usize) -> bool {
        let [i, j, k] = grid.unlinear(l);
        (1..=2).contains(&i) && (1..=2).contains(&j) && k == 1
    }

    /// A region update writes that region and nothing else, in the
    /// volume's own type.
    #[test]
    fn copy_covers_the_region_only_in_the_source_type() {
        let grid = Grid::new([4, 3, 2], DVec3::ONE, DVec3::ZERO);
        let data: Vec<i16> = (0..24).map(|x| x as i16 - 5).collect();
        let view = VolumeView {
            grid,
            data: VoxelSlice::I16(&data),
        };
        let mut store = VoxelStore {
            values: Values::Own(VoxelData::I16(vec![-1; 24])),
        };
        store.copy_region(&view, region());
        let VoxelSlice::I16(out) = store.as_slice() else {
            panic!("an i16 volume is stored as i16");
        };
        for l in 0..24 {
            assert_eq!(out[l], if inside(&grid, l) { data[l] } else { -1 });
        }
        assert_eq!(store.bytes(), 48);
    }

    /// Another type or size makes a fresh store of the new type; f32 NaN
    /// voxels are stored as 0 and infinities kept.
    #[test]
    fn a_new_type_starts_over_and_nan_becomes_zero() {
        let grid = Grid::new([4, 3, 2], DVec3::ONE, DVec3::ZERO);
        let mut data: Vec<f32> = (0..24).map(|x| x as f32 * 0.5).collect();
        data[grid.linear(1, 1, 1)] = f32::NAN;
        data[grid.linear(2, 1, 1)] = f32::INFINITY;
        let view = VolumeView {
            grid,
            data: VoxelSlice::F32(&data),
        };
        let mut store = VoxelStore::zeroed(ScalarType::U8, 24);
        assert!(!store.updatable_by(&RenderVolume::Cpu(view), 24));
        store.copy_region(&view, region());
        assert!(store.updatable_by(&RenderVolume::Cpu(view), 24));
        let out = store.f32_mut().expect("f32 now");
        assert_eq!(out[grid.linear(1, 1, 1)], 0.0);
        assert_eq!(out[grid.linear(2, 1, 1)], f32::INFINITY);
        for l in 0..24 {
            let want = if inside(&grid, l) && !data[l].is_nan() {
                data[l]
            } else {
                0.0
            };
            assert_eq!(out[l], want, "voxel {l}");
        }
    }
}
