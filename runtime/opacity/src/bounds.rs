//! [`VoxelBounds`]: inclusive boxes of voxel indices, and the policy that
//! grows an opacity growth's working box.

/// An inclusive box of **voxel indices** `lo..=hi` along x, y, z (never
/// empty).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct VoxelBounds {
    /// Lowest voxel index along x, y, z.
    pub lo: [usize; 3],
    /// Highest voxel index along x, y, z (inclusive).
    pub hi: [usize; 3],
}

impl VoxelBounds {
    /// The box holding one voxel.
    pub fn point(p: [usize; 3]) -> Self {
        Self { lo: p, hi: p }
    }

    /// Voxels along x, y, z.
    pub fn dims(&self) -> [usize; 3] {
        [0, 1, 2].map(|a| self.hi[a] - self.lo[a] + 1)
    }

    /// Number of voxels.
    pub fn len(&self) -> usize {
        self.dims().iter().product()
    }

    /// Always false: a box holds at least one voxel.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// The smallest box holding both.
    pub fn union(&self, o: &VoxelBounds) -> VoxelBounds {
        VoxelBounds {
            lo: [0, 1, 2].map(|a| self.lo[a].min(o.lo[a])),
            hi: [0, 1, 2].map(|a| self.hi[a].max(o.hi[a])),
        }
    }

    /// True when `o` lies inside this box.
    pub fn contains(&self, o: &VoxelBounds) -> bool {
        (0..3).all(|a| o.lo[a] >= self.lo[a] && o.hi[a] <= self.hi[a])
    }

    /// True when voxel `p` lies inside this box.
    pub fn contains_point(&self, p: [usize; 3]) -> bool {
        (0..3).all(|a| p[a] >= self.lo[a] && p[a] <= self.hi[a])
    }

    /// The box grown by `pad[a]` voxels on both sides along each axis,
    /// clipped to a volume of `dims` voxels.
    pub fn dilate(&self, pad: [usize; 3], dims: [usize; 3]) -> VoxelBounds {
        VoxelBounds {
            lo: [0, 1, 2].map(|a| self.lo[a].saturating_sub(pad[a])),
            hi: [0, 1, 2].map(|a| (self.hi[a] + pad[a]).min(dims[a] - 1)),
        }
    }

    /// Linear index (x fastest) of voxel `p`, relative to this box.
    #[inline]
    pub fn local_linear(&self, p: [usize; 3]) -> usize {
        let d = self.dims();
        (p[0] - self.lo[0]) + d[0] * ((p[1] - self.lo[1]) + d[1] * (p[2] - self.lo[2]))
    }

    /// Voxel index of the linear index `l` relative to this box.
    #[inline]
    pub fn voxel_of(&self, l: usize) -> [usize; 3] {
        let d = self.dims();
        let x = l % d[0];
        let r = l / d[0];
        [self.lo[0] + x, self.lo[1] + r % d[1], self.lo[2] + r / d[1]]
    }
}

/// Smallest margin (voxels) the working box keeps around the region.
pub const MIN_PAD: usize = 8;

/// The working box a growth needs before its next step: every voxel that
/// could change next lies within one voxel of the voxels raised so far
/// (`region`), and the step reads the neighbours of those, so the box must
/// hold `region` grown by 2 (clipped to the volume). Returns `None` when `current` already does; otherwise a new box:
/// `region` grown by `max(MIN_PAD, extent/2)` per axis (geometric growth, so
/// a region growing from one voxel to `n` is copied O(log n) times), or the
/// whole volume once that box would hold more than half of it.
pub fn grown_working_box(
    current: &VoxelBounds,
    region: &VoxelBounds,
    dims: [usize; 3],
) -> Option<VoxelBounds> {
    if current.contains(&region.dilate([2; 3], dims)) {
        return None;
    }
    let grown = initial_working_box(region, dims).union(current);
    // Past half the volume, the next growth would cover (nearly) all of it:
    // take the whole volume now and save one copy of the field.
    let whole = VoxelBounds {
        lo: [0; 3],
        hi: dims.map(|d| d - 1),
    };
    Some(if 2 * grown.len() > whole.len() {
        whole
    } else {
        grown
    })
}

/// A working box around `region`: grown by `max(MIN_PAD, extent/2)` per
/// axis, clipped to the volume.
pub fn initial_working_box(region: &VoxelBounds, dims: [usize; 3]) -> VoxelBounds {
    let e = region.dims();
    region.dilate([0, 1, 2].map(|a| MIN_PAD.max(e[a] / 2)), dims)
}
