//! The host side of the boundary: the [`HostApi`] table the host hands to
//! plugins (backed by any `GpuService`), and [`DeformationProxy`], which
//! turns a plugin's vtable back into a `DeformationModel`.
//!
//! Both live here, not in the host crate, so the whole round trip
//! (trait → C → trait) is tested in one place without loading a library.

use crate::ffi::*;
use crate::guard::{ErrorSink, guard};
use std::ffi::c_void;
use std::sync::Arc;
use voxflex_core::deformation::{
    BindingId, DeformationModel, DirtyRegion, DisplacementTarget, ExecutionBackend, FrameInfo,
    ModelNotes, RestPoints, StepOutcome,
};
use voxflex_core::error::ModelError;
use voxflex_core::glam::DVec3;
use voxflex_core::gpu::{BufferBinding, BufferId, GpuService, PipelineId};
use voxflex_core::volume::VolumeView;

struct HostState {
    gpu: Option<Arc<dyn GpuService>>,
    threads: usize,
}

/// The services a host offers plugins, with the C table that exposes them.
/// Keep it alive (it is reference-counted by every proxy) while any plugin
/// instance created with it lives.
pub struct HostServices {
    api: HostApi,
    _state: Box<HostState>,
}

// SAFETY: `api.ctx` points into `_state`, which is immutable and whose GPU
// service is Send + Sync.
unsafe impl Send for HostServices {}
// SAFETY: as above.
unsafe impl Sync for HostServices {}

impl HostServices {
    /// Services with an optional GPU and a worker-thread budget.
    pub fn new(gpu: Option<Arc<dyn GpuService>>, threads: usize) -> Arc<Self> {
        let mut state = Box::new(HostState {
            gpu,
            threads: threads.max(1),
        });
        let ctx: *mut HostState = &mut *state;
        Arc::new(Self {
            api: HostApi {
                ctx: ctx.cast(),
                log: host_log,
                thread_count: host_thread_count,
                gpu_available: host_gpu_available,
                gpu_adapter_description: host_gpu_adapter_description,
                gpu_limits: host_gpu_limits,
                gpu_create_buffer: host_gpu_create_buffer,
                gpu_destroy_buffer: host_gpu_destroy_buffer,
                gpu_buffer_size: host_gpu_buffer_size,
                gpu_write_buffer: host_gpu_write_buffer,
                gpu_read_buffer: host_gpu_read_buffer,
                gpu_compile: host_gpu_compile,
                gpu_dispatch: host_gpu_dispatch,
                gpu_dispatch_indirect: host_gpu_dispatch_indirect,
            },
            _state: state,
        })
    }

    /// The C table to pass to a plugin's `create`.
    pub fn api(&self) -> *const HostApi {
        &self.api
    }
}

unsafe fn host<'a>(ctx: *mut c_void) -> &'a HostState {
    // SAFETY: ctx is the HostState owned by a live HostServices.
    unsafe { &*ctx.cast::<HostState>() }
}

fn gpu_of(ctx: *mut c_void) -> Result<&'static Arc<dyn GpuService>, String> {
    // SAFETY: ctx from a live HostServices; the reference is used only during
    // the call (the 'static is local to this module's callers).
    let state: &'static HostState = unsafe { host(ctx) };
    state
        .gpu
        .as_ref()
        .ok_or_else(|| "the host has no GPU for this scene (backend resolved to cpu)".to_owned())
}

/// Ignores `ctx` (see [`HostApi::log`]).
unsafe extern "C" fn host_log(_ctx: *mut c_void, level: u32, target: StrRef, message: StrRef) {
    let _ = std::panic::catch_unwind(|| {
        // SAFETY: plugin keeps the strings alive during the call.
        let (target, message) = unsafe { (target.to_string_lossy(), message.to_string_lossy()) };
        match level {
            log_level::ERROR => tracing::error!(plugin_target = %target, "{message}"),
            log_level::WARN => tracing::warn!(plugin_target = %target, "{message}"),
            log_level::INFO => tracing::info!(plugin_target = %target, "{message}"),
            log_level::DEBUG => tracing::debug!(plugin_target = %target, "{message}"),
            _ => tracing::trace!(plugin_target = %target, "{message}"),
        }
    });
}

unsafe extern "C" fn host_thread_count(ctx: *mut c_void) -> u32 {
    // SAFETY: see `host`.
    unsafe { host(ctx) }.threads as u32
}

unsafe extern "C" fn host_gpu_available(ctx: *mut c_void) -> u32 {
    // SAFETY: see `host`.
    unsafe { host(ctx) }.gpu.is_some() as u32
}

unsafe extern "C" fn host_gpu_adapter_description(ctx: *mut c_void, out: *mut ErrorBuf) {
    let text = gpu_of(ctx)
        .map(|g| g.adapter_description())
        .unwrap_or_else(|e| e);
    if !out.is_null() {
        // SAFETY: plugin passes a valid buffer.
        unsafe { (*out).write(&text) };
    }
}

unsafe extern "C" fn host_gpu_limits(ctx: *mut c_void, out: *mut GpuLimitsDesc) -> i32 {
    guard(std::ptr::null_mut(), || {
        let limits = gpu_of(ctx)?.limits();
        if !out.is_null() {
            // SAFETY: plugin passes a valid pointer.
            unsafe { *out = limits.into() };
        }
        Ok(())
    })
}

unsafe extern "C" fn host_gpu_create_buffer(
    ctx: *mut c_void,
    size: u64,
    label: StrRef,
    out: *mut u64,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: label alive during the call.
        let label = unsafe { label.to_string_lossy() };
        let id = gpu_of(ctx)?
            .create_buffer(size, &label)
            .map_err(|e| e.to_string())?;
        if out.is_null() {
            return Err("null output pointer".into());
        }
        // SAFETY: checked non-null.
        unsafe { *out = id.0 };
        Ok(())
    })
}

unsafe extern "C" fn host_gpu_destroy_buffer(ctx: *mut c_void, id: u64) {
    let _ = guard(std::ptr::null_mut(), || {
        gpu_of(ctx)?.destroy_buffer(BufferId(id));
        Ok(())
    });
}

unsafe extern "C" fn host_gpu_buffer_size(
    ctx: *mut c_void,
    id: u64,
    out: *mut u64,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        let size = gpu_of(ctx)?
            .buffer_size(BufferId(id))
            .map_err(|e| e.to_string())?;
        if out.is_null() {
            return Err("null output pointer".into());
        }
        // SAFETY: checked non-null.
        unsafe { *out = size };
        Ok(())
    })
}

unsafe extern "C" fn host_gpu_write_buffer(
    ctx: *mut c_void,
    id: u64,
    offset: u64,
    data: *const u8,
    len: u64,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        let len = usize::try_from(len).map_err(|_| "write too large".to_owned())?;
        let bytes = if len == 0 {
            &[][..]
        } else if data.is_null() {
            return Err("null data pointer".into());
        } else {
            // SAFETY: plugin passes `len` readable bytes.
            unsafe { std::slice::from_raw_parts(data, len) }
        };
        gpu_of(ctx)?
            .write_buffer(BufferId(id), offset, bytes)
            .map_err(|e| e.to_string())
    })
}

unsafe extern "C" fn host_gpu_read_buffer(
    ctx: *mut c_void,
    id: u64,
    offset: u64,
    out: *mut u8,
    len: u64,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        let len = usize::try_from(len).map_err(|_| "read too large".to_owned())?;
        let bytes = if len == 0 {
            &mut [][..]
        } else if out.is_null() {
            return Err("null output pointer".into());
        } else {
            // SAFETY: plugin passes `len` writable bytes.
            unsafe { std::slice::from_raw_parts_mut(out, len) }
        };
        gpu_of(ctx)?
            .read_buffer(BufferId(id), offset, bytes)
            .map_err(|e| e.to_string())
    })
}

unsafe extern "C" fn host_gpu_compile(
    ctx: *mut c_void,
    wgsl: StrRef,
    entry_point: StrRef,
    out: *mut u64,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: strings alive during the call.
        let (wgsl, entry) = unsafe { (wgsl.to_string_lossy(), entry_point.to_string_lossy()) };
        let id = gpu_of(ctx)?
            .compile(&wgsl, &entry)
            .map_err(|e| e.to_string())?;
        if out.is_null() {
            return Err("null output pointer".into());
        }
        // SAFETY: checked non-null.
        unsafe { *out = id.0 };
        Ok(())
    })
}

unsafe extern "C" fn host_gpu_dispatch(
    ctx: *mut c_void,
    pipeline: u64,
    bindings: *const BindingDesc,
    count: u64,
    workgroups: *const [u32; 3],
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        if workgroups.is_null() {
            return Err("null workgroups pointer".into());
        }
        // SAFETY: the plugin passes `count` initialised descriptors that
        // outlive this call.
        let bindings = unsafe { bindings_of(bindings, count) }?;
        // SAFETY: checked non-null.
        let wg = unsafe { *workgroups };
        gpu_of(ctx)?
            .dispatch(PipelineId(pipeline), &bindings, wg)
            .map_err(|e| e.to_string())
    })
}

unsafe extern "C" fn host_gpu_dispatch_indirect(
    ctx: *mut c_void,
    pipeline: u64,
    bindings: *const BindingDesc,
    count: u64,
    args: u64,
    offset: u64,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: the plugin passes `count` initialised descriptors that
        // outlive this call.
        let bindings = unsafe { bindings_of(bindings, count) }?;
        gpu_of(ctx)?
            .dispatch_indirect(PipelineId(pipeline), &bindings, BufferId(args), offset)
            .map_err(|e| e.to_string())
    })
}

/// The `count` binding descriptors at `bindings`, checked for a null
/// pointer.
///
/// # Safety
/// A non-null `bindings` must point at `count` initialised descriptors.
unsafe fn bindings_of(
    bindings: *const BindingDesc,
    count: u64,
) -> Result<Vec<BufferBinding>, String> {
    let count = usize::try_from(count).map_err(|_| "too many bindings".to_owned())?;
    if count > 0 && bindings.is_null() {
        return Err("null bindings pointer".into());
    }
    let descs = if count == 0 {
        &[][..]
    } else {
        // SAFETY: non-null (checked above); the caller vouches for `count`.
        unsafe { std::slice::from_raw_parts(bindings, count) }
    };
    Ok(descs.iter().map(|&b| b.into()).collect())
}

/// A plugin kind's `create` entry point.
pub(crate) type CreateFn =
    unsafe extern "C" fn(StrRef, *const HostApi, *mut Instance, *mut ErrorBuf) -> i32;

/// Calls a plugin's `create` and returns the instance, or the plugin's
/// message prefixed with its name.
///
/// # Safety
/// `create` must be a valid entry point of a library that is never unloaded.
pub(crate) unsafe fn create_proxy_instance(
    name: &str,
    create: CreateFn,
    params_toml: &str,
    services: &HostServices,
) -> Result<Instance, ModelError> {
    let mut sink = ErrorSink::new();
    let mut instance: Instance = std::ptr::null_mut();
    // SAFETY: valid entry point; arguments live during the call.
    let status = unsafe {
        create(
            StrRef::new(params_toml),
            services.api(),
            &mut instance,
            sink.as_ffi(),
        )
    };
    sink.check(status).map_err(|m| plugin_error(name, &m))?;
    if instance.is_null() {
        return Err(plugin_error(name, "create returned no instance"));
    }
    Ok(instance)
}

/// A plugin's notes: `call` writes them into the host buffer it is given
/// (`name<TAB>value` lines, [`crate::notes_text`]); errors name the plugin.
pub(crate) fn read_notes(
    name: &str,
    call: impl FnOnce(*mut ErrorBuf, *mut ErrorBuf) -> i32,
) -> Result<ModelNotes, ModelError> {
    let mut storage = vec![0u8; crate::notes_text::HOST_CAPACITY];
    let mut out = ErrorBuf {
        ptr: storage.as_mut_ptr(),
        cap: storage.len(),
        len: 0,
    };
    checked_call(name, |err| call(&mut out, err))?;
    storage.truncate(out.len.min(storage.len()));
    crate::notes_text::decode(&storage)
        .map_err(|e| ModelError(format!("plugin '{name}': its notes: {e}")))
}

/// An error reported by (or about) plugin `name`.
pub(crate) fn plugin_error(name: &str, message: &str) -> ModelError {
    ModelError(format!("plugin `{name}`: {message}"))
}

/// Runs one vtable call with a fresh error sink; errors name the plugin.
pub(crate) fn checked_call(
    name: &str,
    f: impl FnOnce(*mut ErrorBuf) -> i32,
) -> Result<(), ModelError> {
    let mut sink = ErrorSink::new();
    let status = f(sink.as_ffi());
    sink.check(status).map_err(|m| plugin_error(name, &m))
}

/// A plugin instance seen as a [`DeformationModel`]: every call goes through
/// the plugin's C vtable, and errors come back prefixed with the plugin name.
pub struct DeformationProxy {
    name: String,
    vtable: &'static DeformationVTable,
    instance: Instance,
    _services: Arc<HostServices>,
}

// SAFETY: the plugin instance is only used through &mut self (one thread at a
// time), which is what the plugin contract requires.
unsafe impl Send for DeformationProxy {}

impl DeformationProxy {
    /// Creates an instance of a plugin from its vtable.
    ///
    /// # Safety
    /// `vtable` must be a valid deformation vtable from a library that is
    /// never unloaded.
    pub unsafe fn create(
        name: &str,
        vtable: &'static DeformationVTable,
        params_toml: &str,
        services: Arc<HostServices>,
    ) -> Result<Self, ModelError> {
        // SAFETY: a valid vtable (caller contract).
        let instance =
            unsafe { create_proxy_instance(name, vtable.create, params_toml, &services) }?;
        Ok(Self {
            name: name.to_owned(),
            vtable,
            instance,
            _services: services,
        })
    }

    /// The plugin's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    fn call(&self, f: impl FnOnce(*mut ErrorBuf) -> i32) -> Result<(), ModelError> {
        checked_call(&self.name, f)
    }
}

impl Drop for DeformationProxy {
    fn drop(&mut self) {
        // SAFETY: instance made by this vtable's create, destroyed once.
        unsafe { (self.vtable.destroy)(self.instance) }
    }
}

impl DeformationModel for DeformationProxy {
    fn init(
        &mut self,
        volume: VolumeView<'_>,
        backend: ExecutionBackend,
    ) -> Result<(), ModelError> {
        let desc = VolumeDesc::from_view(&volume);
        let (vt, inst) = (self.vtable, self.instance);
        // SAFETY: volume alive during the call.
        self.call(|err| unsafe { (vt.init)(inst, &desc, backend as u32, err) })
    }

    fn bind(&mut self, rest: RestPoints<'_>) -> Result<BindingId, ModelError> {
        let desc = RestPointsDesc::from_rest(&rest);
        let mut id = 0u64;
        let (vt, inst) = (self.vtable, self.instance);
        // SAFETY: points alive during the call.
        self.call(|err| unsafe { (vt.bind)(inst, &desc, &mut id, err) })?;
        Ok(BindingId(id))
    }

    fn interact(&mut self, interaction_toml: &str) -> Result<(), ModelError> {
        let (vt, inst) = (self.vtable, self.instance);
        // SAFETY: text alive during the call.
        self.call(|err| unsafe { (vt.interact)(inst, StrRef::new(interaction_toml), err) })
    }

    fn step(&mut self, frame: FrameInfo) -> Result<StepOutcome, ModelError> {
        let desc: FrameDesc = frame.into();
        let mut changed = 0u32;
        let (vt, inst) = (self.vtable, self.instance);
        // SAFETY: pointers alive during the call.
        self.call(|err| unsafe { (vt.step)(inst, &desc, &mut changed, err) })?;
        Ok(StepOutcome {
            changed: changed != 0,
        })
    }

    fn dirty_region(&self) -> DirtyRegion {
        let mut out = RegionDesc::from(DirtyRegion::All);
        let (vt, inst) = (self.vtable, self.instance);
        // SAFETY: pointer alive during the call.
        match self.call(|err| unsafe { (vt.dirty_region)(inst, &mut out, err) }) {
            Ok(()) => out.to_region(),
            Err(e) => {
                tracing::warn!("{e}; treating the whole field as dirty");
                DirtyRegion::All
            }
        }
    }

    fn map(&mut self, binding: BindingId, out: DisplacementTarget<'_>) -> Result<(), ModelError> {
        let (vt, inst) = (self.vtable, self.instance);
        match out {
            DisplacementTarget::Cpu { x, y, z } => {
                if x.len() != y.len() || y.len() != z.len() {
                    return Err(ModelError::new("displacement arrays differ in length"));
                }
                let len = x.len() as u64;
                // SAFETY: three disjoint arrays of `len` f32.
                self.call(|err| unsafe {
                    (vt.map_cpu)(
                        inst,
                        binding.0,
                        x.as_mut_ptr(),
                        y.as_mut_ptr(),
                        z.as_mut_ptr(),
                        len,
                        err,
                    )
                })
            }
            DisplacementTarget::Gpu { x, y, z } => {
                // SAFETY: plain ids.
                self.call(|err| unsafe { (vt.map_gpu)(inst, binding.0, x.0, y.0, z.0, err) })
            }
        }
    }

    fn removed_tetrahedra(
        &mut self,
        binding: BindingId,
        cell_bits: &mut [u8],
    ) -> Result<bool, ModelError> {
        let (vt, inst) = (self.vtable, self.instance);
        let mut changed = 0u32;
        let len = cell_bits.len() as u64;
        // SAFETY: one array of `len` bytes and one u32, alive during the call.
        self.call(|err| unsafe {
            (vt.removed_tetrahedra)(
                inst,
                binding.0,
                cell_bits.as_mut_ptr(),
                len,
                &mut changed,
                err,
            )
        })?;
        Ok(changed != 0)
    }

    fn notes(&mut self) -> Result<ModelNotes, ModelError> {
        let (vt, inst) = (self.vtable, self.instance);
        // SAFETY: `read_notes` passes buffers alive during the call.
        read_notes(&self.name, |out, err| unsafe { (vt.notes)(inst, out, err) })
    }

    fn set_point_loads(&mut self, binding: BindingId, forces: &[DVec3]) -> Result<(), ModelError> {
        let raw: Vec<[f64; 3]> = forces.iter().map(|f| f.to_array()).collect();
        let (vt, inst) = (self.vtable, self.instance);
        // SAFETY: `raw` alive during the call.
        self.call(|err| unsafe {
            (vt.set_point_loads)(inst, binding.0, raw.as_ptr(), raw.len() as u64, err)
        })
    }

    fn resolve(&mut self) -> Result<StepOutcome, ModelError> {
        let mut changed = 0u32;
        let (vt, inst) = (self.vtable, self.instance);
        // SAFETY: plain output alive during the call.
        self.call(|err| unsafe { (vt.resolve)(inst, &mut changed, err) })?;
        Ok(StepOutcome {
            changed: changed != 0,
        })
    }

    fn compliance(
        &mut self,
        binding: BindingId,
        forces: &[DVec3],
        out: &mut [DVec3],
    ) -> Result<(), ModelError> {
        if out.len() != forces.len() {
            return Err(plugin_error(
                &self.name,
                &format!(
                    "compliance: {} forces but {} outputs",
                    forces.len(),
                    out.len()
                ),
            ));
        }
        let raw: Vec<[f64; 3]> = forces.iter().map(|f| f.to_array()).collect();
        let mut u = vec![[0.0f64; 3]; raw.len()];
        let (vt, inst) = (self.vtable, self.instance);
        // SAFETY: both arrays alive and `len` long during the call.
        self.call(|err| unsafe {
            (vt.compliance)(
                inst,
                binding.0,
                raw.as_ptr(),
                raw.len() as u64,
                u.as_mut_ptr(),
                err,
            )
        })?;
        for (o, v) in out.iter_mut().zip(u) {
            *o = DVec3::from_array(v);
        }
        Ok(())
    }
}
