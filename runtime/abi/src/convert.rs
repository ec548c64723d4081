//! Conversions between voxflex-core types and their `#[repr(C)]` mirrors.

use crate::ffi::*;
use voxflex_core::deformation::{DirtyRegion, FrameInfo, RestPoints};
use voxflex_core::glam::DVec3;
use voxflex_core::gpu::{BufferBinding, BufferId, GpuLimits};
use voxflex_core::grid::Grid;
use voxflex_core::volume::{ScalarType, VolumeView, VoxelSlice};

impl From<Grid> for GridDesc {
    fn from(g: Grid) -> Self {
        Self {
            dims: g.dims.map(|d| d as u64),
            spacing: g.spacing.to_array(),
            origin: g.origin.to_array(),
        }
    }
}

impl GridDesc {
    /// The grid, refusing dims that do not fit this machine's `usize`.
    pub fn to_grid(&self) -> Result<Grid, String> {
        let mut dims = [0usize; 3];
        for (d, &v) in dims.iter_mut().zip(&self.dims) {
            *d = usize::try_from(v).map_err(|_| format!("grid dimension {v} is too large"))?;
        }
        Ok(Grid::new(
            dims,
            DVec3::from_array(self.spacing),
            DVec3::from_array(self.origin),
        ))
    }
}

impl VolumeDesc {
    /// Describes a borrowed volume (valid while `view` is).
    pub fn from_view(view: &VolumeView<'_>) -> Self {
        let data = view.data;
        Self {
            grid: view.grid.into(),
            scalar_type: data.scalar_type() as u32,
            reserved: 0,
            data: data.as_bytes().as_ptr().cast(),
            len: data.len() as u64,
        }
    }

    /// The borrowed volume.
    ///
    /// # Safety
    /// `data` must point to `len` values of `scalar_type`, alive for `'a`.
    pub unsafe fn to_view<'a>(&self) -> Result<VolumeView<'a>, String> {
        let grid = self.grid.to_grid()?;
        let len = usize::try_from(self.len).map_err(|_| "volume too large".to_owned())?;
        if len != grid.len() {
            return Err(format!(
                "volume holds {len} values but its grid {:?} needs {}",
                grid.dims,
                grid.len()
            ));
        }
        let st = ScalarType::from_code(self.scalar_type)
            .ok_or_else(|| format!("unknown scalar type code {}", self.scalar_type))?;
        if len > 0 && self.data.is_null() {
            return Err("volume data pointer is null".into());
        }
        // SAFETY: guaranteed by the caller; types match the tag.
        let data = unsafe {
            match st {
                ScalarType::U8 => VoxelSlice::U8(slice(self.data.cast(), len)),
                ScalarType::I16 => VoxelSlice::I16(slice(self.data.cast(), len)),
                ScalarType::U16 => VoxelSlice::U16(slice(self.data.cast(), len)),
                ScalarType::F32 => VoxelSlice::F32(slice(self.data.cast(), len)),
            }
        };
        Ok(VolumeView { grid, data })
    }
}

/// # Safety
/// `ptr` valid for `len` reads of `T` for `'a` (may dangle when `len == 0`).
unsafe fn slice<'a, T>(ptr: *const T, len: usize) -> &'a [T] {
    if len == 0 {
        &[]
    } else {
        // SAFETY: guaranteed by the caller.
        unsafe { std::slice::from_raw_parts(ptr, len) }
    }
}

impl RestPointsDesc {
    /// Describes rest points (valid while `rest` is).
    pub fn from_rest(rest: &RestPoints<'_>) -> Self {
        match rest {
            RestPoints::Lattice(g) => Self {
                tag: REST_POINTS_LATTICE,
                reserved: 0,
                grid: (*g).into(),
                points: std::ptr::null(),
                len: g.len() as u64,
            },
            RestPoints::Points(p) => Self {
                tag: REST_POINTS_LIST,
                reserved: 0,
                grid: Grid::new([0; 3], DVec3::ONE, DVec3::ZERO).into(),
                points: p.as_ptr(),
                len: p.len() as u64,
            },
        }
    }

    /// The rest points.
    ///
    /// # Safety
    /// For a list, `points` must be valid for `len` reads for `'a`.
    pub unsafe fn to_rest<'a>(&self) -> Result<RestPoints<'a>, String> {
        match self.tag {
            REST_POINTS_LATTICE => Ok(RestPoints::Lattice(self.grid.to_grid()?)),
            REST_POINTS_LIST => {
                let len = usize::try_from(self.len).map_err(|_| "too many points".to_owned())?;
                if len > 0 && self.points.is_null() {
                    return Err("rest point pointer is null".into());
                }
                // SAFETY: guaranteed by the caller.
                Ok(RestPoints::Points(unsafe { slice(self.points, len) }))
            }
            t => Err(format!("unknown rest-point tag {t}")),
        }
    }
}

impl From<FrameInfo> for FrameDesc {
    fn from(f: FrameInfo) -> Self {
        Self {
            frame: f.frame,
            frames: f.frames,
            dt_s: f.dt_s,
        }
    }
}

impl From<FrameDesc> for FrameInfo {
    fn from(f: FrameDesc) -> Self {
        Self {
            frame: f.frame,
            frames: f.frames,
            dt_s: f.dt_s,
        }
    }
}

impl From<DirtyRegion> for RegionDesc {
    fn from(r: DirtyRegion) -> Self {
        let (tag, min, max) = match r {
            DirtyRegion::None => (REGION_NONE, [0.0; 3], [0.0; 3]),
            DirtyRegion::All => (REGION_ALL, [0.0; 3], [0.0; 3]),
            DirtyRegion::Box { min, max } => (REGION_BOX, min.to_array(), max.to_array()),
        };
        Self {
            tag,
            reserved: 0,
            min,
            max,
        }
    }
}

impl RegionDesc {
    /// The region; unknown tags and NaN boxes count as "everything moved".
    pub fn to_region(&self) -> DirtyRegion {
        match self.tag {
            REGION_NONE => DirtyRegion::None,
            REGION_BOX => {
                let (min, max) = (DVec3::from_array(self.min), DVec3::from_array(self.max));
                if min.is_finite() && max.is_finite() {
                    DirtyRegion::Box { min, max }
                } else {
                    DirtyRegion::All
                }
            }
            _ => DirtyRegion::All,
        }
    }
}

impl From<GpuLimits> for GpuLimitsDesc {
    fn from(l: GpuLimits) -> Self {
        Self {
            max_storage_buffer_binding_size: l.max_storage_buffer_binding_size,
            max_buffer_size: l.max_buffer_size,
            max_compute_workgroups_per_dimension: l.max_compute_workgroups_per_dimension,
            min_storage_buffer_offset_alignment: l.min_storage_buffer_offset_alignment,
        }
    }
}

impl From<GpuLimitsDesc> for GpuLimits {
    fn from(l: GpuLimitsDesc) -> Self {
        Self {
            max_storage_buffer_binding_size: l.max_storage_buffer_binding_size,
            max_buffer_size: l.max_buffer_size,
            max_compute_workgroups_per_dimension: l.max_compute_workgroups_per_dimension,
            min_storage_buffer_offset_alignment: l.min_storage_buffer_offset_alignment,
        }
    }
}

impl From<BufferBinding> for BindingDesc {
    fn from(b: BufferBinding) -> Self {
        Self {
            binding: b.binding,
            reserved: 0,
            buffer: b.buffer.0,
            offset: b.offset,
            size: b.size,
        }
    }
}

impl From<BindingDesc> for BufferBinding {
    fn from(b: BindingDesc) -> Self {
        Self {
            binding: b.binding,
            buffer: BufferId(b.buffer),
            offset: b.offset,
            size: b.size,
        }
    }
}

impl From<&voxflex_core::camera::Camera> for CameraDesc {
    fn from(c: &voxflex_core::camera::Camera) -> Self {
        use voxflex_core::camera::Projection;
        let (projection, projection_parameter) = match c.projection {
            Projection::Orthographic { height_mm } => (PROJECTION_ORTHOGRAPHIC, height_mm),
            Projection::Perspective { fov_y_deg } => (PROJECTION_PERSPECTIVE, fov_y_deg),
        };
        Self {
            target: c.target.to_array(),
            azimuth_deg: c.azimuth_deg,
            elevation_deg: c.elevation_deg,
            distance_mm: c.distance_mm,
            projection,
            width: c.width,
            projection_parameter,
            height: c.height,
            reserved: 0,
        }
    }
}

impl CameraDesc {
    /// The camera, refusing unknown projections and non-finite values.
    pub fn to_camera(&self) -> Result<voxflex_core::camera::Camera, String> {
        use voxflex_core::camera::{Camera, Projection};
        let finite = self.target.iter().all(|v| v.is_finite())
            && [
                self.azimuth_deg,
                self.elevation_deg,
                self.distance_mm,
                self.projection_parameter,
            ]
            .iter()
            .all(|v| v.is_finite());
        if !finite {
            return Err("camera has a non-finite value".into());
        }
        let projection = match self.projection {
            PROJECTION_ORTHOGRAPHIC => Projection::Orthographic {
                height_mm: self.projection_parameter,
            },
            PROJECTION_PERSPECTIVE => Projection::Perspective {
                fov_y_deg: self.projection_parameter,
            },
            p => return Err(format!("unknown projection code {p}")),
        };
        Ok(Camera {
            target: DVec3::from_array(self.target),
            azimuth_deg: self.azimuth_deg,
            elevation_deg: self.elevation_deg,
            distance_mm: self.distance_mm,
            projection,
            width: self.width,
            height: self.height,
        })
    }
}

impl OpacityMapDesc {
    /// Describes a map (valid while `map` is).
    pub fn from_map(map: &voxflex_core::opacity_map::OpacityMap) -> Self {
        Self {
            origin: map.origin.map(|v| v as u64),
            dims: map.dims.map(|v| v as u64),
            outside: map.outside as u32,
            reserved: 0,
            values: map.values.as_ptr(),
            len: map.values.len() as u64,
        }
    }

    /// Copies the map, checking its size.
    ///
    /// # Safety
    /// `values` must be valid for `len` reads.
    pub unsafe fn to_map(&self) -> Result<voxflex_core::opacity_map::OpacityMap, String> {
        let to_usize =
            |v: u64| usize::try_from(v).map_err(|_| format!("opacity map size {v} is too large"));
        let origin = [
            to_usize(self.origin[0])?,
            to_usize(self.origin[1])?,
            to_usize(self.origin[2])?,
        ];
        let dims = [
            to_usize(self.dims[0])?,
            to_usize(self.dims[1])?,
            to_usize(self.dims[2])?,
        ];
        let len = to_usize(self.len)?;
        let expected = dims
            .iter()
            .try_fold(1usize, |a, &b| a.checked_mul(b))
            .ok_or("opacity map dims overflow")?;
        if expected != len {
            return Err(format!(
                "opacity map holds {len} values but its dims {dims:?} need {expected}"
            ));
        }
        if len > 0 && self.values.is_null() {
            return Err("opacity map values pointer is null".into());
        }
        let outside = u16::try_from(self.outside)
            .map_err(|_| "opacity map `outside` is not a u16".to_owned())?;
        // SAFETY: guaranteed by the caller.
        let values = unsafe { slice(self.values, len) }.to_vec();
        Ok(voxflex_core::opacity_map::OpacityMap {
            origin,
            dims,
            outside,
            values,
        })
    }
}

impl From<voxflex_core::render::RenderStats> for RenderStatsDesc {
    fn from(s: voxflex_core::render::RenderStats) -> Self {
        Self {
            rays: s.rays,
            samples: s.samples,
            terminated_early: s.terminated_early,
        }
    }
}

impl From<RenderStatsDesc> for voxflex_core::render::RenderStats {
    fn from(s: RenderStatsDesc) -> Self {
        Self {
            rays: s.rays,
            samples: s.samples,
            terminated_early: s.terminated_early,
        }
    }
}
