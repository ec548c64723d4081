//! The GPU command service: the one GPU interface every algorithm is written
//! against.
//!
//! core defines it and never implements it over a real API: the host
//! (`voxflex-runtime`) implements it over wgpu, and inside a plugin the ABI
//! SDK implements it over the host's C function table. Buffers are named by
//! opaque [`BufferId`]s, so data passes between plugins and host services
//! without a trip through the CPU.
//!
//! Layout rule (see docs/DESIGN.md, "Backends"): bind only 32-bit scalar
//! structure-of-arrays buffers and never bind more than
//! [`GpuLimits::max_storage_buffer_binding_size`] bytes at once (128 MiB on
//! lavapipe); larger data is split into slabs.

use crate::error::GpuError;

/// Opaque handle of a GPU buffer owned by the host.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct BufferId(pub u64);

/// Opaque handle of a compiled compute pipeline (cached by WGSL hash).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct PipelineId(pub u64);

/// One buffer bound to `@group(0) @binding(binding)` for a dispatch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BufferBinding {
    /// The `@binding(n)` index in group 0.
    pub binding: u32,
    /// The buffer.
    pub buffer: BufferId,
    /// Byte offset into the buffer (a multiple of
    /// [`GpuLimits::min_storage_buffer_offset_alignment`]).
    pub offset: u64,
    /// Bytes bound; `0` binds from `offset` to the end of the buffer.
    pub size: u64,
}

impl BufferBinding {
    /// Binds the whole of `buffer` at `@binding(binding)`.
    pub fn whole(binding: u32, buffer: BufferId) -> Self {
        Self {
            binding,
            buffer,
            offset: 0,
            size: 0,
        }
    }
}

/// The limits of the device behind a [`GpuService`] that algorithms must respect.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GpuLimits {
    /// Largest storage binding, bytes.
    pub max_storage_buffer_binding_size: u64,
    /// Largest buffer, bytes.
    pub max_buffer_size: u64,
    /// Largest workgroup count per dispatch dimension.
    pub max_compute_workgroups_per_dimension: u32,
    /// Required alignment of a storage binding's offset, bytes.
    pub min_storage_buffer_offset_alignment: u32,
}

/// Buffers, WGSL pipelines and dispatches on the host's one GPU device.
///
/// Every buffer is usable as storage, uniform, copy source, copy
/// destination and indirect dispatch arguments. Every pipeline uses one bind group (group 0) whose layout is
/// derived from the shader. Calls are ordered: a read-back sees every
/// earlier write and dispatch.
pub trait GpuService: Send + Sync {
    /// Human-readable adapter description (name, backend, device type).
    fn adapter_description(&self) -> String;
    /// The device limits.
    fn limits(&self) -> GpuLimits;
    /// A new zero-filled buffer of `size_bytes` (multiple of 4).
    fn create_buffer(&self, size_bytes: u64, label: &str) -> Result<BufferId, GpuError>;
    /// Frees a buffer; unknown ids are ignored.
    fn destroy_buffer(&self, id: BufferId);
    /// Size of a buffer in bytes.
    fn buffer_size(&self, id: BufferId) -> Result<u64, GpuError>;
    /// Copies `bytes` into the buffer at `offset` (both multiples of 4).
    fn write_buffer(&self, id: BufferId, offset: u64, bytes: &[u8]) -> Result<(), GpuError>;
    /// Copies `out.len()` bytes from the buffer at `offset` into `out`, waiting
    /// for all earlier work.
    fn read_buffer(&self, id: BufferId, offset: u64, out: &mut [u8]) -> Result<(), GpuError>;
    /// Compiles (or returns the cached pipeline for) a WGSL compute entry point.
    fn compile(&self, wgsl: &str, entry_point: &str) -> Result<PipelineId, GpuError>;
    /// Runs `workgroups` workgroups of a pipeline with the given bindings.
    fn dispatch(
        &self,
        pipeline: PipelineId,
        bindings: &[BufferBinding],
        workgroups: [u32; 3],
    ) -> Result<(), GpuError>;
    /// Runs a pipeline like [`Self::dispatch`], with the workgroup counts
    /// read on the device from three `u32`s of `args` at byte `offset` (a
    /// multiple of 4) when the dispatch executes — so an earlier kernel can
    /// size a later one without a read-back. Counts above
    /// [`GpuLimits::max_compute_workgroups_per_dimension`] are the writer's
    /// error, and the device does not check them (the host runs wgpu
    /// without its indirect-argument validation): fold them as
    /// [`workgroups_1d`] does, and do not read `num_workgroups` in a kernel
    /// dispatched this way (D3D12 does not report it).
    fn dispatch_indirect(
        &self,
        pipeline: PipelineId,
        bindings: &[BufferBinding],
        args: BufferId,
        offset: u64,
    ) -> Result<(), GpuError>;
}

/// Helpers every GPU algorithm needs, on top of [`GpuService`].
pub trait GpuServiceExt: GpuService {
    /// A buffer holding `data`.
    fn upload<T: bytemuck::Pod>(&self, data: &[T], label: &str) -> Result<BufferId, GpuError> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let id = self.create_buffer((bytes.len() as u64).max(4).next_multiple_of(4), label)?;
        if !bytes.is_empty() {
            self.write_buffer(id, 0, bytes)?;
        }
        Ok(id)
    }

    /// Reads `out.len()` elements from the start of a buffer.
    fn download<T: bytemuck::Pod>(&self, id: BufferId, out: &mut [T]) -> Result<(), GpuError> {
        self.read_buffer(id, 0, bytemuck::cast_slice_mut(out))
    }

    /// Workgroup counts covering `n` invocations of `workgroup_size` threads,
    /// folded into 3-D so no dimension exceeds the device limit.
    fn workgroups_for(&self, n: u64, workgroup_size: u32) -> Result<[u32; 3], GpuError> {
        workgroups_1d(
            n,
            workgroup_size,
            self.limits().max_compute_workgroups_per_dimension,
        )
    }
}

impl<T: GpuService + ?Sized> GpuServiceExt for T {}

/// Workgroup counts covering `n` invocations of `workgroup_size` threads,
/// folded into `[x, y, z]` so no dimension exceeds `max_per_dim`. A kernel
/// recovers its flat invocation index as
/// `gid.x + gid.y * (nwg.x * size) + gid.z * (nwg.x * size * nwg.y)`.
pub fn workgroups_1d(n: u64, workgroup_size: u32, max_per_dim: u32) -> Result<[u32; 3], GpuError> {
    let groups = n.div_ceil(workgroup_size as u64).max(1);
    let max = max_per_dim as u64;
    let x = groups.min(max);
    let rest = groups.div_ceil(x);
    let y = rest.min(max);
    let z = rest.div_ceil(y);
    if z > max {
        return Err(GpuError(format!(
            "{n} invocations need more than {max}³ workgroups of {workgroup_size}; split the work"
        )));
    }
    Ok([x as u32, y as u32, z as u32])
}

/// A [`GpuService`] that forwards to another but reports smaller limits
/// **and enforces them**, as a device with such limits would fail: a
/// storage binding limit (a dispatch that binds more bytes than that, or at
/// an offset off the device's storage alignment, fails) and a workgroup
/// limit per dimension (direct dispatches are checked before they run,
/// indirect ones by reading their counts back after they were queued).
/// Tests use it to exercise, with small data, the slab splitting and the
/// folding into 2-D and 3-D that every GPU algorithm needs on devices with
/// small limits. `inner` is `&dyn GpuService` or `Arc<dyn GpuService>`.
#[doc(hidden)]
pub struct LimitedDevice<G> {
    /// The real service.
    pub inner: G,
    /// The storage binding limit to report, bytes (`None`: the device's).
    pub max_storage_buffer_binding_size: Option<u64>,
    /// The workgroup limit per dimension to report (`None`: the device's).
    pub max_compute_workgroups_per_dimension: Option<u32>,
}

impl<G> LimitedDevice<G> {
    /// `inner` with storage bindings of at most `bytes`.
    pub fn binding(inner: G, bytes: u64) -> Self {
        Self {
            inner,
            max_storage_buffer_binding_size: Some(bytes),
            max_compute_workgroups_per_dimension: None,
        }
    }

    /// `inner` with at most `max` workgroups per dimension.
    pub fn workgroups(inner: G, max: u32) -> Self {
        Self {
            inner,
            max_storage_buffer_binding_size: None,
            max_compute_workgroups_per_dimension: Some(max),
        }
    }
}

impl<G, T> LimitedDevice<G>
where
    G: std::ops::Deref<Target = T>,
    T: GpuService + ?Sized,
{
    /// Fails as a device with the smaller bindings would.
    fn check_bindings(&self, bindings: &[BufferBinding]) -> Result<(), GpuError> {
        let Some(limit) = self.max_storage_buffer_binding_size else {
            return Ok(());
        };
        let align = u64::from(self.inner.limits().min_storage_buffer_offset_alignment);
        for b in bindings {
            let size = match b.size {
                0 => self.inner.buffer_size(b.buffer)?.saturating_sub(b.offset),
                s => s,
            };
            if size > limit || b.offset % align != 0 {
                return Err(GpuError(format!(
                    "@binding({}) binds {size} bytes at offset {} (limit {limit}, alignment {align})",
                    b.binding, b.offset
                )));
            }
        }
        Ok(())
    }

    /// Fails as a device with fewer workgroups per dimension would.
    fn check_workgroups(&self, workgroups: [u32; 3]) -> Result<(), GpuError> {
        match self.max_compute_workgroups_per_dimension {
            Some(max) if workgroups.iter().any(|&n| n > max) => Err(GpuError(format!(
                "workgroups {workgroups:?} exceed the limit of {max} per dimension"
            ))),
            _ => Ok(()),
        }
    }
}

impl<G, T> GpuService for LimitedDevice<G>
where
    G: std::ops::Deref<Target = T> + Send + Sync,
    T: GpuService + ?Sized,
{
    fn adapter_description(&self) -> String {
        self.inner.adapter_description()
    }
    fn limits(&self) -> GpuLimits {
        let l = self.inner.limits();
        GpuLimits {
            max_storage_buffer_binding_size: self
                .max_storage_buffer_binding_size
                .unwrap_or(l.max_storage_buffer_binding_size),
            max_compute_workgroups_per_dimension: self
                .max_compute_workgroups_per_dimension
                .unwrap_or(l.max_compute_workgroups_per_dimension),
            ..l
        }
    }
    fn create_buffer(&self, size_bytes: u64, label: &str) -> Result<BufferId, GpuError> {
        self.inner.create_buffer(size_bytes, label)
    }
    fn destroy_buffer(&self, id: BufferId) {
        self.inner.destroy_buffer(id)
    }
    fn buffer_size(&self, id: BufferId) -> Result<u64, GpuError> {
        self.inner.buffer_size(id)
    }
    fn write_buffer(&self, id: BufferId, offset: u64, bytes: &[u8]) -> Result<(), GpuError> {
        self.inner.write_buffer(id, offset, bytes)
    }
    fn read_buffer(&self, id: BufferId, offset: u64, out: &mut [u8]) -> Result<(), GpuError> {
        self.inner.read_buffer(id, offset, out)
    }
    fn compile(&self, wgsl: &str, entry_point: &str) -> Result<PipelineId, GpuError> {
        self.inner.compile(wgsl, entry_point)
    }
    fn dispatch(
        &self,
        pipeline: PipelineId,
        bindings: &[BufferBinding],
        workgroups: [u32; 3],
    ) -> Result<(), GpuError> {
        self.check_bindings(bindings)?;
        self.check_workgroups(workgroups)?;
        self.inner.dispatch(pipeline, bindings, workgroups)
    }
    fn dispatch_indirect(
        &self,
        pipeline: PipelineId,
        bindings: &[BufferBinding],
        args: BufferId,
        offset: u64,
    ) -> Result<(), GpuError> {
        self.check_bindings(bindings)?;
        self.inner
            .dispatch_indirect(pipeline, bindings, args, offset)?;
        if self.max_compute_workgroups_per_dimension.is_none() {
            return Ok(());
        }
        let mut counts = [0u8; 12];
        self.inner.read_buffer(args, offset, &mut counts)?;
        self.check_workgroups(bytemuck::cast(counts))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn workgroups_fold_into_3d() {
        assert_eq!(workgroups_1d(10, 64, 65535).unwrap(), [1, 1, 1]);
        let wg = workgroups_1d(256u64.pow(3), 256, 65535).unwrap();
        assert!(wg[0] <= 65535 && wg[1] <= 65535);
        assert!(wg[0] as u64 * wg[1] as u64 * wg[2] as u64 * 256 >= 256u64.pow(3));
    }
}
