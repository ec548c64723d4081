//! The `#[repr(C)]` types and `extern "C"` function tables that cross the
//! host ↔ plugin boundary. Nothing else crosses it: no Rust type, no panic,
//! no allocation (the side that allocates frees).
//!
//! Status codes: every fallible entry point returns an `i32` status
//! ([`STATUS_OK`], [`STATUS_ERROR`], [`STATUS_PANIC`]) and, on failure,
//! writes a UTF-8 message into the caller's [`ErrorBuf`].

use std::ffi::c_void;

/// The call succeeded.
pub const STATUS_OK: i32 = 0;
/// The call failed; the [`ErrorBuf`] holds the reason.
pub const STATUS_ERROR: i32 = 1;
/// The callee panicked; the panic was caught and its message is in the [`ErrorBuf`].
pub const STATUS_PANIC: i32 = 2;

/// Magic number at the start of every [`PluginHeader`] (`"VOXFLEX1"`).
pub const PLUGIN_MAGIC: u64 = u64::from_le_bytes(*b"VOXFLEX1");

/// Borrowed UTF-8 text: pointer + length in bytes (not NUL-terminated).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct StrRef {
    /// First byte (may be dangling when `len == 0`).
    pub ptr: *const u8,
    /// Length in bytes.
    pub len: usize,
}

impl StrRef {
    /// Borrows a `&str` (the caller keeps it alive during the call).
    pub fn new(s: &str) -> Self {
        Self {
            ptr: s.as_ptr(),
            len: s.len(),
        }
    }

    /// Borrows a `'static` string for a static declaration.
    pub const fn from_static(s: &'static str) -> Self {
        Self {
            ptr: s.as_ptr(),
            len: s.len(),
        }
    }

    /// The text, replacing invalid UTF-8.
    ///
    /// # Safety
    /// `ptr` must point to `len` readable bytes for the returned lifetime.
    pub unsafe fn to_string_lossy(&self) -> String {
        if self.len == 0 || self.ptr.is_null() {
            return String::new();
        }
        // SAFETY: guaranteed by the caller.
        let bytes = unsafe { std::slice::from_raw_parts(self.ptr, self.len) };
        String::from_utf8_lossy(bytes).into_owned()
    }
}

/// A caller-owned buffer the callee writes an error message into
/// (truncated to `cap` bytes at a UTF-8 boundary).
#[repr(C)]
#[derive(Debug)]
pub struct ErrorBuf {
    /// Caller-allocated storage.
    pub ptr: *mut u8,
    /// Capacity in bytes.
    pub cap: usize,
    /// Bytes written by the callee.
    pub len: usize,
}

impl ErrorBuf {
    /// Writes `msg` (truncated to capacity at a char boundary).
    ///
    /// # Safety
    /// `self.ptr` must be valid for `self.cap` bytes of writes.
    pub unsafe fn write(&mut self, msg: &str) {
        let mut n = msg.len().min(self.cap);
        while n > 0 && !msg.is_char_boundary(n) {
            n -= 1;
        }
        if n > 0 && !self.ptr.is_null() {
            // SAFETY: guaranteed by the caller; n ≤ cap.
            unsafe { std::ptr::copy_nonoverlapping(msg.as_ptr(), self.ptr, n) };
        }
        self.len = n;
    }

    /// Writes all of `text` into the host's output buffer `out` (a plugin
    /// answering with data, not an error): refuses a null buffer, and text
    /// longer than its capacity, naming `what` it is.
    ///
    /// # Safety
    /// `out` is null or a buffer valid for `cap` bytes of writes.
    pub unsafe fn write_whole(out: *mut ErrorBuf, text: &str, what: &str) -> Result<(), String> {
        if out.is_null() {
            return Err("null output buffer".into());
        }
        // SAFETY: checked non-null; the caller passes a buffer of `cap` bytes.
        let out = unsafe { &mut *out };
        if text.len() > out.cap {
            return Err(format!(
                "{what} takes {} bytes, more than the host's {}",
                text.len(),
                out.cap
            ));
        }
        // SAFETY: as above; the text fits.
        unsafe { out.write(text) };
        Ok(())
    }
}

/// What a plugin is.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PluginKind {
    /// A deformation model ([`DeformationVTable`]).
    Deformation = 0,
    /// A renderer (vtable defined by the renderer issue; reserved).
    Renderer = 1,
    /// An actuator model ([`ActuatorVTable`]).
    Actuator = 2,
}

impl PluginKind {
    /// The kind with this code, if any.
    pub fn from_code(code: u32) -> Option<Self> {
        match code {
            0 => Some(Self::Deformation),
            1 => Some(Self::Renderer),
            2 => Some(Self::Actuator),
            _ => None,
        }
    }
}

/// Capability bit: the plugin has a rayon CPU path.
pub const CAPABILITY_CPU: u32 = 1;
/// Capability bit: the plugin has a WGSL GPU path (through the host's GPU service).
pub const CAPABILITY_GPU: u32 = 2;

/// The frozen first thing the host reads from a plugin. Its layout never
/// changes across ABI versions, so the host can always read the version and
/// layout hash and refuse a mismatch before touching anything else.
#[repr(C)]
#[derive(Debug)]
pub struct PluginHeader {
    /// Always [`PLUGIN_MAGIC`].
    pub magic: u64,
    /// [`crate::ABI_VERSION`] the plugin was built against.
    pub abi_version: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// [`crate::LAYOUT_HASH`] the plugin was built against.
    pub layout_hash: u64,
    /// The declaration; read only when version and hash match.
    pub declaration: *const PluginDeclaration,
}

// SAFETY: the header and the declaration it points to are immutable statics.
unsafe impl Sync for PluginHeader {}

/// The type of the one exported symbol, `voxflex_plugin_v1`.
pub type PluginEntry = unsafe extern "C" fn() -> *const PluginHeader;

/// Static description of a plugin.
#[repr(C)]
#[derive(Debug)]
pub struct PluginDeclaration {
    /// Plugin name as scenes refer to it (`plugin = "affine"`).
    pub name: StrRef,
    /// Plugin semver (`CARGO_PKG_VERSION` of its crate).
    pub version: StrRef,
    /// One-line description.
    pub description: StrRef,
    /// What the plugin is: a [`PluginKind`] as u32 (kept as a plain integer so
    /// a foreign value can never be an invalid Rust enum).
    pub kind: u32,
    /// [`CAPABILITY_CPU`] | [`CAPABILITY_GPU`].
    pub capabilities: u32,
    /// The deformation vtable when `kind == Deformation`, else null.
    pub deformation: *const DeformationVTable,
    /// The renderer vtable when `kind == Renderer`, else null.
    pub renderer: *const RendererVTable,
    /// The actuator vtable when `kind == Actuator`, else null.
    pub actuator: *const ActuatorVTable,
    /// Writes the plugin's parameter schema (JSON Schema text, UTF-8) into
    /// `out` (a host buffer of `cap` bytes); 0 on success, else an error
    /// in `err` ([`crate::params_schema`]).
    pub params_schema: unsafe extern "C" fn(out: *mut ErrorBuf, err: *mut ErrorBuf) -> i32,
}

// SAFETY: immutable static data.
unsafe impl Sync for PluginDeclaration {}

/// Geometry of a voxel grid (see `voxflex_core::grid::Grid`): dims, spacing
/// and origin in millimetres.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct GridDesc {
    /// Voxels along x, y, z.
    pub dims: [u64; 3],
    /// Voxel spacing, mm.
    pub spacing: [f64; 3],
    /// Centre of voxel (0,0,0), world mm.
    pub origin: [f64; 3],
}

/// A borrowed volume: grid, scalar type and values (x fastest).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct VolumeDesc {
    /// Geometry.
    pub grid: GridDesc,
    /// `voxflex_core::volume::ScalarType` as u32.
    pub scalar_type: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// First value (native endianness).
    pub data: *const c_void,
    /// Number of values.
    pub len: u64,
}

/// Rest points: [`REST_POINTS_LATTICE`] (every voxel centre of `grid`) or
/// [`REST_POINTS_LIST`] (`len` points `[x, y, z]` in world mm at `points`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct RestPointsDesc {
    /// [`REST_POINTS_LATTICE`] or [`REST_POINTS_LIST`].
    pub tag: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// The lattice (tag = lattice).
    pub grid: GridDesc,
    /// The points (tag = list).
    pub points: *const [f32; 3],
    /// Number of points (tag = list).
    pub len: u64,
}

/// [`RestPointsDesc::tag`]: every voxel centre of a grid.
pub const REST_POINTS_LATTICE: u32 = 0;
/// [`RestPointsDesc::tag`]: an explicit point list.
pub const REST_POINTS_LIST: u32 = 1;

/// One frame's timing (see `voxflex_core::deformation::FrameInfo`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct FrameDesc {
    /// Frame number from 0.
    pub frame: u64,
    /// Frames in the scene.
    pub frames: u64,
    /// Simulated seconds per frame.
    pub dt_s: f64,
}

/// A dirty region: [`REGION_NONE`], [`REGION_ALL`] or [`REGION_BOX`] (world mm).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct RegionDesc {
    /// Which region.
    pub tag: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Box lower corner, mm.
    pub min: [f64; 3],
    /// Box upper corner, mm.
    pub max: [f64; 3],
}

/// [`RegionDesc::tag`]: nothing moved.
pub const REGION_NONE: u32 = 0;
/// [`RegionDesc::tag`]: everything may have moved.
pub const REGION_ALL: u32 = 1;
/// [`RegionDesc::tag`]: only rest points in the box moved.
pub const REGION_BOX: u32 = 2;

/// Opaque plugin instance.
pub type Instance = *mut c_void;

/// The functions of a deformation plugin. Mirrors
/// `voxflex_core::deformation::DeformationModel` one to one.
#[repr(C)]
#[derive(Debug)]
pub struct DeformationVTable {
    /// Creates an instance from the TOML text of the scene's `[model.params]`.
    pub create: unsafe extern "C" fn(
        params_toml: StrRef,
        host: *const HostApi,
        out: *mut Instance,
        err: *mut ErrorBuf,
    ) -> i32,
    /// Destroys an instance made by `create`.
    pub destroy: unsafe extern "C" fn(instance: Instance),
    /// `DeformationModel::init`; `backend` is `ExecutionBackend` as u32.
    pub init: unsafe extern "C" fn(
        instance: Instance,
        volume: *const VolumeDesc,
        backend: u32,
        err: *mut ErrorBuf,
    ) -> i32,
    /// `DeformationModel::bind`.
    pub bind: unsafe extern "C" fn(
        instance: Instance,
        rest: *const RestPointsDesc,
        out_binding: *mut u64,
        err: *mut ErrorBuf,
    ) -> i32,
    /// `DeformationModel::interact` with the interaction's TOML text.
    pub interact: unsafe extern "C" fn(instance: Instance, toml: StrRef, err: *mut ErrorBuf) -> i32,
    /// `DeformationModel::step`; writes 1 to `out_changed` when the field changed.
    pub step: unsafe extern "C" fn(
        instance: Instance,
        frame: *const FrameDesc,
        out_changed: *mut u32,
        err: *mut ErrorBuf,
    ) -> i32,
    /// `DeformationModel::dirty_region`.
    pub dirty_region:
        unsafe extern "C" fn(instance: Instance, out: *mut RegionDesc, err: *mut ErrorBuf) -> i32,
    /// `DeformationModel::map` into three host-owned CPU arrays of `len` f32 (mm).
    pub map_cpu: unsafe extern "C" fn(
        instance: Instance,
        binding: u64,
        x: *mut f32,
        y: *mut f32,
        z: *mut f32,
        len: u64,
        err: *mut ErrorBuf,
    ) -> i32,
    /// `DeformationModel::map` into three GPU buffers (ids of the host's GPU service).
    pub map_gpu: unsafe extern "C" fn(
        instance: Instance,
        binding: u64,
        x: u64,
        y: u64,
        z: u64,
        err: *mut ErrorBuf,
    ) -> i32,
    /// `DeformationModel::removed_tetrahedra` on a host-owned array of
    /// `len` cell bytes; writes 1 to `out_changed` when it set new bits.
    pub removed_tetrahedra: unsafe extern "C" fn(
        instance: Instance,
        binding: u64,
        cell_bits: *mut u8,
        len: u64,
        out_changed: *mut u32,
        err: *mut ErrorBuf,
    ) -> i32,
    /// `DeformationModel::notes`, written into the host's `out` buffer as
    /// UTF-8 lines `name<TAB>value` (value as Rust prints an `f64`); fails
    /// with an error instead of truncating when they do not fit.
    pub notes:
        unsafe extern "C" fn(instance: Instance, out: *mut ErrorBuf, err: *mut ErrorBuf) -> i32,
    /// `DeformationModel::set_point_loads`: `len` forces `[x, y, z]` (µN)
    /// on the binding's points.
    pub set_point_loads: unsafe extern "C" fn(
        instance: Instance,
        binding: u64,
        forces: *const [f64; 3],
        len: u64,
        err: *mut ErrorBuf,
    ) -> i32,
    /// `DeformationModel::compliance`: `len` forces (µN) on the binding's
    /// points in, `len` displacements (mm) into the host's array `out`.
    pub compliance: unsafe extern "C" fn(
        instance: Instance,
        binding: u64,
        forces: *const [f64; 3],
        len: u64,
        out: *mut [f64; 3],
        err: *mut ErrorBuf,
    ) -> i32,
    /// `DeformationModel::resolve`; writes 1 to `out_changed` when the
    /// field changed.
    pub resolve:
        unsafe extern "C" fn(instance: Instance, out_changed: *mut u32, err: *mut ErrorBuf) -> i32,
}

/// An actuator's points at rest (mirror of
/// `voxflex_core::actuator::ActuatorGeometry`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct ActuatorGeometryDesc {
    /// `len` points `[x, y, z]`, world mm.
    pub points: *const [f64; 3],
    /// Number of points.
    pub len: u64,
    /// `triangle_count` triangles (indices into `points`).
    pub triangles: *const [u32; 3],
    /// Number of triangles (0 for an actuator that is not a surface).
    pub triangle_count: u64,
    /// Gravity, m/s², world axes.
    pub gravity_m_s2: [f64; 3],
}

/// A frame's command (mirror of `voxflex_core::actuator::ActuatorCommand`):
/// [`COMMAND_FREE`], [`COMMAND_EFFORT`] or [`COMMAND_MEASURE`] with `value`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct ActuatorCommandDesc {
    /// Which command.
    pub tag: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// The effort or measure.
    pub value: f64,
}

/// [`ActuatorCommandDesc::tag`]: the inverse solve chooses the effort.
pub const COMMAND_FREE: u32 = 0;
/// [`ActuatorCommandDesc::tag`]: the effort is given.
pub const COMMAND_EFFORT: u32 = 1;
/// [`ActuatorCommandDesc::tag`]: the measure is given.
pub const COMMAND_MEASURE: u32 = 2;

/// The scalars of a linearisation (mirror of
/// `voxflex_core::actuator::ActuatorLinearisation` without its arrays,
/// which go into host arrays).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct ActuatorScalarsDesc {
    /// The measure now, relative to rest.
    pub measure: f64,
    /// Effort interval.
    pub effort_bounds: [f64; 2],
    /// Measure interval, relative to rest.
    pub measure_bounds: [f64; 2],
    /// 1 when `loads` was written.
    pub has_loads: u32,
    /// 1 when `load_growth` was written.
    pub has_load_growth: u32,
}

/// The functions of an actuator plugin; mirrors
/// `voxflex_core::actuator::ActuatorModel` one to one.
#[repr(C)]
#[derive(Debug)]
pub struct ActuatorVTable {
    /// Creates an instance from the TOML text of the scene's
    /// `[actuator.params]`.
    pub create: unsafe extern "C" fn(
        params_toml: StrRef,
        host: *const HostApi,
        out: *mut Instance,
        err: *mut ErrorBuf,
    ) -> i32,
    /// Destroys an instance made by `create`.
    pub destroy: unsafe extern "C" fn(instance: Instance),
    /// `ActuatorModel::init`.
    pub init: unsafe extern "C" fn(
        instance: Instance,
        geometry: *const ActuatorGeometryDesc,
        err: *mut ErrorBuf,
    ) -> i32,
    /// `ActuatorModel::command`.
    pub command: unsafe extern "C" fn(
        instance: Instance,
        frame: *const FrameDesc,
        out: *mut ActuatorCommandDesc,
        err: *mut ErrorBuf,
    ) -> i32,
    /// `ActuatorModel::linearise` at `len` positions (mm): directions,
    /// loads and load growth into three host arrays of `len` entries.
    pub linearise: unsafe extern "C" fn(
        instance: Instance,
        positions: *const [f64; 3],
        len: u64,
        directions: *mut [f64; 3],
        loads: *mut [f64; 3],
        load_growth: *mut [f64; 3],
        out: *mut ActuatorScalarsDesc,
        err: *mut ErrorBuf,
    ) -> i32,
    /// `ActuatorModel::notes`, as the deformation vtable's `notes`.
    pub notes:
        unsafe extern "C" fn(instance: Instance, out: *mut ErrorBuf, err: *mut ErrorBuf) -> i32,
}

/// Log levels for [`HostApi::log`].
pub mod log_level {
    /// Error.
    pub const ERROR: u32 = 1;
    /// Warning.
    pub const WARN: u32 = 2;
    /// Information.
    pub const INFO: u32 = 3;
    /// Debug.
    pub const DEBUG: u32 = 4;
    /// Trace.
    pub const TRACE: u32 = 5;
}

/// Device limits as the host reports them (mirror of `voxflex_core::gpu::GpuLimits`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct GpuLimitsDesc {
    /// Largest storage binding, bytes.
    pub max_storage_buffer_binding_size: u64,
    /// Largest buffer, bytes.
    pub max_buffer_size: u64,
    /// Largest workgroup count per dimension.
    pub max_compute_workgroups_per_dimension: u32,
    /// Storage binding offset alignment, bytes.
    pub min_storage_buffer_offset_alignment: u32,
}

/// One buffer binding of a dispatch (mirror of `voxflex_core::gpu::BufferBinding`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct BindingDesc {
    /// `@binding(n)` in group 0.
    pub binding: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Buffer id.
    pub buffer: u64,
    /// Byte offset.
    pub offset: u64,
    /// Bytes bound, 0 = to the end.
    pub size: u64,
}

/// What the host offers every plugin: logging into the host's `tracing`
/// subscriber, its thread count, and the GPU command service (the mirror of
/// `voxflex_core::gpu::GpuService` as C functions). `ctx` is passed back to
/// every function. Valid until the plugin instance is destroyed.
#[repr(C)]
#[derive(Debug)]
pub struct HostApi {
    /// Host context pointer, passed back to every function.
    pub ctx: *mut c_void,
    /// Logs one message at a [`log_level`]. Must not use `ctx` (plugins call
    /// it with null from their process-wide log bridge, after the instance
    /// that received this table may be gone).
    pub log: unsafe extern "C" fn(ctx: *mut c_void, level: u32, target: StrRef, message: StrRef),
    /// Worker threads the plugin may use (size its thread pool to this).
    pub thread_count: unsafe extern "C" fn(ctx: *mut c_void) -> u32,
    /// 1 when a GPU service is available (backend resolved to GPU), else 0.
    pub gpu_available: unsafe extern "C" fn(ctx: *mut c_void) -> u32,
    /// Writes the adapter description (truncated) into `out`.
    pub gpu_adapter_description: unsafe extern "C" fn(ctx: *mut c_void, out: *mut ErrorBuf),
    /// Device limits.
    pub gpu_limits: unsafe extern "C" fn(ctx: *mut c_void, out: *mut GpuLimitsDesc) -> i32,
    /// `GpuService::create_buffer`.
    pub gpu_create_buffer: unsafe extern "C" fn(
        ctx: *mut c_void,
        size: u64,
        label: StrRef,
        out: *mut u64,
        err: *mut ErrorBuf,
    ) -> i32,
    /// `GpuService::destroy_buffer`.
    pub gpu_destroy_buffer: unsafe extern "C" fn(ctx: *mut c_void, id: u64),
    /// `GpuService::buffer_size`.
    pub gpu_buffer_size:
        unsafe extern "C" fn(ctx: *mut c_void, id: u64, out: *mut u64, err: *mut ErrorBuf) -> i32,
    /// `GpuService::write_buffer`.
    pub gpu_write_buffer: unsafe extern "C" fn(
        ctx: *mut c_void,
        id: u64,
        offset: u64,
        data: *const u8,
        len: u64,
        err: *mut ErrorBuf,
    ) -> i32,
    /// `GpuService::read_buffer`.
    pub gpu_read_buffer: unsafe extern "C" fn(
        ctx: *mut c_void,
        id: u64,
        offset: u64,
        out: *mut u8,
        len: u64,
        err: *mut ErrorBuf,
    ) -> i32,
    /// `GpuService::compile`.
    pub gpu_compile: unsafe extern "C" fn(
        ctx: *mut c_void,
        wgsl: StrRef,
        entry_point: StrRef,
        out: *mut u64,
        err: *mut ErrorBuf,
    ) -> i32,
    /// `GpuService::dispatch`.
    pub gpu_dispatch: unsafe extern "C" fn(
        ctx: *mut c_void,
        pipeline: u64,
        bindings: *const BindingDesc,
        count: u64,
        workgroups: *const [u32; 3],
        err: *mut ErrorBuf,
    ) -> i32,
    /// `GpuService::dispatch_indirect`: the workgroup counts are three
    /// `u32`s of buffer `args` at byte `offset`.
    pub gpu_dispatch_indirect: unsafe extern "C" fn(
        ctx: *mut c_void,
        pipeline: u64,
        bindings: *const BindingDesc,
        count: u64,
        args: u64,
        offset: u64,
        err: *mut ErrorBuf,
    ) -> i32,
}

/// An orbit camera (mirror of `voxflex_core::camera::Camera`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct CameraDesc {
    /// Point looked at, world mm.
    pub target: [f64; 3],
    /// Degrees about world +z.
    pub azimuth_deg: f64,
    /// Degrees above the x–y plane.
    pub elevation_deg: f64,
    /// Eye–target distance, mm.
    pub distance_mm: f64,
    /// [`PROJECTION_ORTHOGRAPHIC`] or [`PROJECTION_PERSPECTIVE`].
    pub projection: u32,
    /// Image width, pixels.
    pub width: u32,
    /// Orthographic image height (mm) or perspective vertical field of view (degrees).
    pub projection_parameter: f64,
    /// Image height, pixels.
    pub height: u32,
    /// Reserved, zero.
    pub reserved: u32,
}

/// [`CameraDesc::projection`]: parallel rays.
pub const PROJECTION_ORTHOGRAPHIC: u32 = 0;
/// [`CameraDesc::projection`]: rays through the eye.
pub const PROJECTION_PERSPECTIVE: u32 = 1;

/// The volume a renderer draws: CPU values valid during the call
/// ([`RENDER_VOLUME_CPU`], `volume`), CPU values lent until released
/// ([`RENDER_VOLUME_SHARED`], `volume`, `owner`, `release`) or an f32 GPU
/// buffer on `volume.grid` ([`RENDER_VOLUME_GPU`], `buffer`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct RenderVolumeDesc {
    /// Which of the three.
    pub tag: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// The volume (for GPU: only `grid` is read).
    pub volume: VolumeDesc,
    /// GPU buffer id of `grid.len()` f32.
    pub buffer: u64,
    /// [`RENDER_VOLUME_SHARED`]: the host's handle on `volume`'s values,
    /// passed to `release`; null otherwise.
    pub owner: *mut c_void,
    /// [`RENDER_VOLUME_SHARED`]: the plugin calls it exactly once with
    /// `owner` (from any thread, whatever `set_volume` returns) when it no
    /// longer reads the values; until then they stay alive and unchanged.
    /// `None` otherwise.
    pub release: Option<unsafe extern "C" fn(owner: *mut c_void)>,
}

/// [`RenderVolumeDesc::tag`]: values on the CPU, valid during the call.
pub const RENDER_VOLUME_CPU: u32 = 0;
/// [`RenderVolumeDesc::tag`]: values in a GPU buffer.
pub const RENDER_VOLUME_GPU: u32 = 1;
/// [`RenderVolumeDesc::tag`]: values on the CPU, lent until the plugin
/// calls [`RenderVolumeDesc::release`] (`voxflex_core::shared_volume::SharedVolume`).
pub const RENDER_VOLUME_SHARED: u32 = 2;

/// A spatial opacity map (mirror of `voxflex_core::opacity_map::OpacityMap`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct OpacityMapDesc {
    /// First voxel of the box, voxel indices.
    pub origin: [u64; 3],
    /// Box size, voxels.
    pub dims: [u64; 3],
    /// u16 fixed-point opacity outside the box.
    pub outside: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// `len` u16 fixed-point opacities, x fastest.
    pub values: *const u16,
    /// Number of values.
    pub len: u64,
}

/// Where a render goes: [`IMAGE_TARGET_CPU`] (`len` bytes RGBA8 at `pixels`)
/// or [`IMAGE_TARGET_GPU`] (packed RGBA8 u32 buffer `buffer`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct ImageTargetDesc {
    /// Which of the two.
    pub tag: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// CPU pixels.
    pub pixels: *mut u8,
    /// CPU byte count.
    pub len: u64,
    /// GPU buffer id.
    pub buffer: u64,
}

/// [`ImageTargetDesc::tag`]: CPU bytes.
pub const IMAGE_TARGET_CPU: u32 = 0;
/// [`ImageTargetDesc::tag`]: GPU buffer.
pub const IMAGE_TARGET_GPU: u32 = 1;

/// Counters of one render (mirror of `voxflex_core::render::RenderStats`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct RenderStatsDesc {
    /// Primary rays.
    pub rays: u64,
    /// Volume samples.
    pub samples: u64,
    /// Rays stopped by early termination.
    pub terminated_early: u64,
}

/// The functions of a renderer plugin; mirrors `voxflex_core::render::Renderer`.
#[repr(C)]
#[derive(Debug)]
pub struct RendererVTable {
    /// Creates an instance from the TOML text of the scene's `[render]` parameters.
    pub create: unsafe extern "C" fn(
        params_toml: StrRef,
        host: *const HostApi,
        out: *mut Instance,
        err: *mut ErrorBuf,
    ) -> i32,
    /// Destroys an instance made by `create`.
    pub destroy: unsafe extern "C" fn(instance: Instance),
    /// `Renderer::init`; `backend` is `ExecutionBackend` as u32.
    pub init: unsafe extern "C" fn(instance: Instance, backend: u32, err: *mut ErrorBuf) -> i32,
    /// `Renderer::configure` with TOML text.
    pub configure:
        unsafe extern "C" fn(instance: Instance, toml: StrRef, err: *mut ErrorBuf) -> i32,
    /// `Renderer::set_volume`.
    pub set_volume: unsafe extern "C" fn(
        instance: Instance,
        volume: *const RenderVolumeDesc,
        dirty: *const RegionDesc,
        err: *mut ErrorBuf,
    ) -> i32,
    /// `Renderer::set_opacity_maps` (`count` maps at `maps`).
    pub set_opacity_maps: unsafe extern "C" fn(
        instance: Instance,
        maps: *const OpacityMapDesc,
        count: u64,
        err: *mut ErrorBuf,
    ) -> i32,
    /// `Renderer::render`.
    pub render: unsafe extern "C" fn(
        instance: Instance,
        camera: *const CameraDesc,
        target: *const ImageTargetDesc,
        out_stats: *mut RenderStatsDesc,
        err: *mut ErrorBuf,
    ) -> i32,
}
