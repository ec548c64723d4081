//! The plugin side of the boundary: what a plugin author uses.
//!
//! A plugin is one impl of [`DeformationPlugin`] (which extends
//! `voxflex_core::deformation::DeformationModel`) plus one line:
//!
//! ```ignore
//! voxflex_abi::export_deformation_plugin!(MyModel);
//! ```
//!
//! The macro emits the `voxflex_plugin_v1` symbol with the ABI version, the
//! layout hash and a vtable whose every entry catches panics and reports
//! errors as text.

use crate::ffi::*;
use crate::guard::{ErrorSink, guard};
use std::sync::{Arc, Once};
use voxflex_core::deformation::{
    DeformationModel, DisplacementTarget, ExecutionBackend, FrameInfo,
};
use voxflex_core::error::{GpuError, ModelError};
use voxflex_core::glam::DVec3;
use voxflex_core::gpu::{BufferBinding, BufferId, GpuLimits, GpuService, PipelineId};

/// What the host hands a plugin instance at creation.
#[derive(Clone)]
pub struct HostContext {
    api: *const HostApi,
}

// SAFETY: the host guarantees the HostApi table and its functions are
// thread-safe and outlive every instance created with it.
unsafe impl Send for HostContext {}
// SAFETY: as above.
unsafe impl Sync for HostContext {}

impl HostContext {
    /// Wraps the host's table.
    ///
    /// # Safety
    /// `api` must be valid for as long as any clone of the context lives.
    pub unsafe fn from_raw(api: *const HostApi) -> Self {
        Self { api }
    }

    fn api(&self) -> &HostApi {
        // SAFETY: guaranteed at construction.
        unsafe { &*self.api }
    }

    /// Worker threads the host allows this plugin.
    pub fn thread_count(&self) -> usize {
        let api = self.api();
        // SAFETY: host-provided function with its own context.
        (unsafe { (api.thread_count)(api.ctx) }).max(1) as usize
    }

    /// The host's GPU service, when the scene's backend resolved to a GPU.
    pub fn gpu(&self) -> Option<Arc<dyn GpuService>> {
        let api = self.api();
        // SAFETY: host-provided function with its own context.
        if unsafe { (api.gpu_available)(api.ctx) } == 0 {
            return None;
        }
        Some(Arc::new(HostGpu { host: self.clone() }))
    }

    /// Logs a message into the host's `tracing` subscriber.
    pub fn log(&self, level: u32, target: &str, message: &str) {
        let api = self.api();
        // SAFETY: host-provided function; strings live during the call.
        unsafe { (api.log)(api.ctx, level, StrRef::new(target), StrRef::new(message)) }
    }
}

/// The host's GPU service seen from inside a plugin: the same
/// [`GpuService`] trait, implemented over the host's C functions.
pub struct HostGpu {
    host: HostContext,
}

impl HostGpu {
    fn call(&self, f: impl FnOnce(&HostApi, *mut ErrorBuf) -> i32) -> Result<(), GpuError> {
        let mut sink = ErrorSink::new();
        let status = f(self.host.api(), sink.as_ffi());
        sink.check(status).map_err(GpuError)
    }
}

impl GpuService for HostGpu {
    fn adapter_description(&self) -> String {
        let mut sink = ErrorSink::new();
        let api = self.host.api();
        // SAFETY: host function; sink valid during the call.
        unsafe { (api.gpu_adapter_description)(api.ctx, sink.as_ffi()) };
        sink.message()
    }

    fn limits(&self) -> GpuLimits {
        let api = self.host.api();
        let mut out = GpuLimitsDesc::default();
        // SAFETY: host function; `out` valid during the call.
        unsafe { (api.gpu_limits)(api.ctx, &mut out) };
        out.into()
    }

    fn create_buffer(&self, size_bytes: u64, label: &str) -> Result<BufferId, GpuError> {
        let mut id = 0u64;
        // SAFETY: host function; pointers valid during the call.
        self.call(|api, err| unsafe {
            (api.gpu_create_buffer)(api.ctx, size_bytes, StrRef::new(label), &mut id, err)
        })?;
        Ok(BufferId(id))
    }

    fn destroy_buffer(&self, id: BufferId) {
        let api = self.host.api();
        // SAFETY: host function.
        unsafe { (api.gpu_destroy_buffer)(api.ctx, id.0) }
    }

    fn buffer_size(&self, id: BufferId) -> Result<u64, GpuError> {
        let mut size = 0u64;
        // SAFETY: host function; pointers valid during the call.
        self.call(|api, err| unsafe { (api.gpu_buffer_size)(api.ctx, id.0, &mut size, err) })?;
        Ok(size)
    }

    fn write_buffer(&self, id: BufferId, offset: u64, bytes: &[u8]) -> Result<(), GpuError> {
        // SAFETY: host function; `bytes` valid during the call.
        self.call(|api, err| unsafe {
            (api.gpu_write_buffer)(
                api.ctx,
                id.0,
                offset,
                bytes.as_ptr(),
                bytes.len() as u64,
                err,
            )
        })
    }

    fn read_buffer(&self, id: BufferId, offset: u64, out: &mut [u8]) -> Result<(), GpuError> {
        // SAFETY: host function; `out` valid during the call.
        self.call(|api, err| unsafe {
            (api.gpu_read_buffer)(
                api.ctx,
                id.0,
                offset,
                out.as_mut_ptr(),
                out.len() as u64,
                err,
            )
        })
    }

    fn compile(&self, wgsl: &str, entry_point: &str) -> Result<PipelineId, GpuError> {
        let mut id = 0u64;
        // SAFETY: host function; strings valid during the call.
        self.call(|api, err| unsafe {
            (api.gpu_compile)(
                api.ctx,
                StrRef::new(wgsl),
                StrRef::new(entry_point),
                &mut id,
                err,
            )
        })?;
        Ok(PipelineId(id))
    }

    fn dispatch(
        &self,
        pipeline: PipelineId,
        bindings: &[BufferBinding],
        workgroups: [u32; 3],
    ) -> Result<(), GpuError> {
        let descs: Vec<BindingDesc> = bindings.iter().map(|&b| b.into()).collect();
        // SAFETY: host function; arrays valid during the call.
        self.call(|api, err| unsafe {
            (api.gpu_dispatch)(
                api.ctx,
                pipeline.0,
                descs.as_ptr(),
                descs.len() as u64,
                &workgroups,
                err,
            )
        })
    }

    fn dispatch_indirect(
        &self,
        pipeline: PipelineId,
        bindings: &[BufferBinding],
        args: BufferId,
        offset: u64,
    ) -> Result<(), GpuError> {
        let descs: Vec<BindingDesc> = bindings.iter().map(|&b| b.into()).collect();
        // SAFETY: host function; the array is valid during the call.
        self.call(|api, err| unsafe {
            (api.gpu_dispatch_indirect)(
                api.ctx,
                pipeline.0,
                descs.as_ptr(),
                descs.len() as u64,
                args.0,
                offset,
                err,
            )
        })
    }
}

/// A deformation model that can be exported as a plugin.
pub trait DeformationPlugin:
    DeformationModel + crate::params_schema::DeclaresParams + Sized + 'static
{
    /// Name scenes use (`plugin = "..."`): lower-case, hyphens allowed.
    const NAME: &'static str;
    /// One-line description for `voxflex plugins`.
    const DESCRIPTION: &'static str;
    /// [`CAPABILITY_CPU`] | [`CAPABILITY_GPU`].
    const CAPABILITIES: u32;

    /// Creates an instance from the TOML text of the scene's `[model.params]`
    /// table. Errors must name the offending key.
    fn create(params_toml: &str, host: HostContext) -> Result<Self, ModelError>;
}

/// Per-process setup inside a plugin library: size rayon's pool to the
/// host's thread count and route this library's `tracing` into the host.
fn setup_once(host: &HostContext) {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let _ = rayon::ThreadPoolBuilder::new()
            .num_threads(host.thread_count())
            .build_global();
        let _ = tracing::subscriber::set_global_default(crate::log_bridge::HostLogSubscriber::new(
            host.api().log,
        ));
    });
}

pub(crate) struct InstanceState<P> {
    pub(crate) model: P,
    _host: HostContext,
}

/// # Safety
/// `instance` is null or was made by [`create_instance::<P>`] and not destroyed.
pub(crate) unsafe fn state<'a, P>(instance: Instance) -> Result<&'a mut InstanceState<P>, String> {
    if instance.is_null() {
        return Err("null plugin instance".into());
    }
    // SAFETY: created by `create_instance::<P>` and not yet destroyed (host contract).
    Ok(unsafe { &mut *instance.cast::<InstanceState<P>>() })
}

/// The body of every kind's `create`: set up the library, parse nothing
/// itself, box what `make` builds.
pub(crate) fn create_instance<P>(
    params: StrRef,
    host: *const HostApi,
    out: *mut Instance,
    err: *mut ErrorBuf,
    make: impl FnOnce(&str, HostContext) -> Result<P, ModelError>,
) -> i32 {
    guard(err, || {
        if host.is_null() || out.is_null() {
            return Err("null host table or output pointer".into());
        }
        // SAFETY: host contract: the table outlives the instance.
        let ctx = unsafe { HostContext::from_raw(host) };
        setup_once(&ctx);
        // SAFETY: the host keeps the text alive during the call.
        let text = unsafe { params.to_string_lossy() };
        let model = make(&text, ctx.clone()).map_err(|e| e.to_string())?;
        let boxed = Box::new(InstanceState { model, _host: ctx });
        // SAFETY: `out` checked non-null.
        unsafe { *out = Box::into_raw(boxed).cast() };
        Ok(())
    })
}

/// The body of every kind's `destroy`.
///
/// # Safety
/// `instance` is null or was made by [`create_instance::<P>`], destroyed once.
pub(crate) unsafe fn destroy_instance<P>(instance: Instance) {
    if instance.is_null() {
        return;
    }
    let _ = std::panic::catch_unwind(|| {
        // SAFETY: guaranteed by the caller.
        drop(unsafe { Box::from_raw(instance.cast::<InstanceState<P>>()) });
    });
}

unsafe extern "C" fn create<P: DeformationPlugin>(
    params: StrRef,
    host: *const HostApi,
    out: *mut Instance,
    err: *mut ErrorBuf,
) -> i32 {
    create_instance(params, host, out, err, P::create)
}

unsafe extern "C" fn destroy<P: DeformationPlugin>(instance: Instance) {
    // SAFETY: host contract.
    unsafe { destroy_instance::<P>(instance) }
}

unsafe extern "C" fn init<P: DeformationPlugin>(
    instance: Instance,
    volume: *const VolumeDesc,
    backend: u32,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        if volume.is_null() {
            return Err("null volume".into());
        }
        // SAFETY: host keeps the volume alive during the call.
        let view = unsafe { (*volume).to_view() }?;
        let backend = match backend {
            0 => ExecutionBackend::Cpu,
            1 => ExecutionBackend::Gpu,
            b => return Err(format!("unknown backend code {b}")),
        };
        s.model.init(view, backend).map_err(|e| e.to_string())
    })
}

unsafe extern "C" fn bind<P: DeformationPlugin>(
    instance: Instance,
    rest: *const RestPointsDesc,
    out_binding: *mut u64,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        if rest.is_null() || out_binding.is_null() {
            return Err("null rest points or output pointer".into());
        }
        // SAFETY: host keeps the points alive during the call.
        let rest = unsafe { (*rest).to_rest() }?;
        let id = s.model.bind(rest).map_err(|e| e.to_string())?;
        // SAFETY: checked non-null.
        unsafe { *out_binding = id.0 };
        Ok(())
    })
}

unsafe extern "C" fn interact<P: DeformationPlugin>(
    instance: Instance,
    toml: StrRef,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        // SAFETY: text alive during the call.
        let text = unsafe { toml.to_string_lossy() };
        s.model.interact(&text).map_err(|e| e.to_string())
    })
}

unsafe extern "C" fn step<P: DeformationPlugin>(
    instance: Instance,
    frame: *const FrameDesc,
    out_changed: *mut u32,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        if frame.is_null() || out_changed.is_null() {
            return Err("null frame or output pointer".into());
        }
        // SAFETY: checked non-null; plain data.
        let info: FrameInfo = unsafe { *frame }.into();
        let outcome = on_worker(|| s.model.step(info)).map_err(|e| e.to_string())?;
        // SAFETY: checked non-null.
        unsafe { *out_changed = outcome.changed as u32 };
        Ok(())
    })
}

unsafe extern "C" fn dirty_region<P: DeformationPlugin>(
    instance: Instance,
    out: *mut RegionDesc,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        if out.is_null() {
            return Err("null output pointer".into());
        }
        // SAFETY: checked non-null.
        unsafe { *out = s.model.dirty_region().into() };
        Ok(())
    })
}

#[allow(clippy::too_many_arguments)]
unsafe extern "C" fn map_cpu<P: DeformationPlugin>(
    instance: Instance,
    binding: u64,
    x: *mut f32,
    y: *mut f32,
    z: *mut f32,
    len: u64,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        let len = usize::try_from(len).map_err(|_| "too many points".to_owned())?;
        if len > 0 && (x.is_null() || y.is_null() || z.is_null()) {
            return Err("null displacement array".into());
        }
        let mk = |p: *mut f32| -> &mut [f32] {
            if len == 0 {
                &mut []
            } else {
                // SAFETY: the host passes three disjoint arrays of `len` f32.
                unsafe { std::slice::from_raw_parts_mut(p, len) }
            }
        };
        let target = DisplacementTarget::Cpu {
            x: mk(x),
            y: mk(y),
            z: mk(z),
        };
        s.model
            .map(voxflex_core::deformation::BindingId(binding), target)
            .map_err(|e| e.to_string())
    })
}

unsafe extern "C" fn map_gpu<P: DeformationPlugin>(
    instance: Instance,
    binding: u64,
    x: u64,
    y: u64,
    z: u64,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        let target = DisplacementTarget::Gpu {
            x: BufferId(x),
            y: BufferId(y),
            z: BufferId(z),
        };
        s.model
            .map(voxflex_core::deformation::BindingId(binding), target)
            .map_err(|e| e.to_string())
    })
}

unsafe extern "C" fn removed_tetrahedra<P: DeformationPlugin>(
    instance: Instance,
    binding: u64,
    cell_bits: *mut u8,
    len: u64,
    out_changed: *mut u32,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        let len = usize::try_from(len).map_err(|_| "too many cells".to_owned())?;
        if out_changed.is_null() || (len > 0 && cell_bits.is_null()) {
            return Err("null cell array or output pointer".into());
        }
        let bits: &mut [u8] = if len == 0 {
            &mut []
        } else {
            // SAFETY: the host passes an array of `len` bytes for the call.
            unsafe { std::slice::from_raw_parts_mut(cell_bits, len) }
        };
        let changed = s
            .model
            .removed_tetrahedra(voxflex_core::deformation::BindingId(binding), bits)
            .map_err(|e| e.to_string())?;
        // SAFETY: checked non-null above.
        unsafe { *out_changed = changed as u32 };
        Ok(())
    })
}

unsafe extern "C" fn notes<P: DeformationPlugin>(
    instance: Instance,
    out: *mut ErrorBuf,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        let notes = s.model.notes().map_err(|e| e.to_string())?;
        let text = crate::notes_text::encode(&notes)?;
        // SAFETY: host contract: `out` is the host's buffer of `cap` bytes.
        unsafe { ErrorBuf::write_whole(out, &text, "the model's notes") }
    })
}

/// `len` triples at `ptr` as vectors (an empty slice for `len == 0`).
///
/// # Safety
/// `ptr` is null only with `len == 0`, else valid for `len` reads.
pub(crate) unsafe fn vectors_in(ptr: *const [f64; 3], len: u64) -> Result<Vec<DVec3>, String> {
    if len == 0 {
        return Ok(Vec::new());
    }
    if ptr.is_null() {
        return Err("null array".into());
    }
    // SAFETY: caller contract.
    let raw = unsafe { std::slice::from_raw_parts(ptr, len as usize) };
    Ok(raw.iter().map(|v| DVec3::from_array(*v)).collect())
}

/// Writes `values` into the host's array of `len` triples at `ptr`.
///
/// # Safety
/// `ptr` is null only with `len == 0`, else valid for `len` writes.
pub(crate) unsafe fn vectors_out(
    values: &[DVec3],
    ptr: *mut [f64; 3],
    len: u64,
) -> Result<(), String> {
    if values.len() as u64 != len {
        return Err(format!("{} values for an array of {len}", values.len()));
    }
    if len == 0 {
        return Ok(());
    }
    if ptr.is_null() {
        return Err("null output array".into());
    }
    // SAFETY: caller contract.
    let out = unsafe { std::slice::from_raw_parts_mut(ptr, len as usize) };
    for (o, v) in out.iter_mut().zip(values) {
        *o = v.to_array();
    }
    Ok(())
}

unsafe extern "C" fn set_point_loads<P: DeformationPlugin>(
    instance: Instance,
    binding: u64,
    forces: *const [f64; 3],
    len: u64,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        // SAFETY: host contract: `len` forces at `forces`.
        let forces = unsafe { vectors_in(forces, len) }?;
        s.model
            .set_point_loads(voxflex_core::deformation::BindingId(binding), &forces)
            .map_err(|e| e.to_string())
    })
}

unsafe extern "C" fn compliance<P: DeformationPlugin>(
    instance: Instance,
    binding: u64,
    forces: *const [f64; 3],
    len: u64,
    out: *mut [f64; 3],
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        // SAFETY: host contract: `len` forces at `forces`.
        let forces = unsafe { vectors_in(forces, len) }?;
        let mut u = vec![DVec3::ZERO; forces.len()];
        let binding = voxflex_core::deformation::BindingId(binding);
        on_worker(|| s.model.compliance(binding, &forces, &mut u)).map_err(|e| e.to_string())?;
        // SAFETY: host contract: `len` entries at `out`.
        unsafe { vectors_out(&u, out, len) }
    })
}

unsafe extern "C" fn resolve<P: DeformationPlugin>(
    instance: Instance,
    out_changed: *mut u32,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        if out_changed.is_null() {
            return Err("null output".into());
        }
        let o = on_worker(|| s.model.resolve()).map_err(|e| e.to_string())?;
        // SAFETY: checked non-null.
        unsafe { *out_changed = u32::from(o.changed) };
        Ok(())
    })
}

/// [`voxflex_core::on_worker::on_worker`] in this library: every plugin
/// library links its own copy of rayon, so the host's thread is a
/// stranger to its pool, and a call that runs many parallel loops (a
/// static solve) hands over once instead of once per loop.
pub(crate) use voxflex_core::on_worker::on_worker;

/// The vtable of plugin type `P` (used by [`crate::export_deformation_plugin!`]).
pub const fn deformation_vtable<P: DeformationPlugin>() -> DeformationVTable {
    DeformationVTable {
        create: create::<P>,
        destroy: destroy::<P>,
        init: init::<P>,
        bind: bind::<P>,
        interact: interact::<P>,
        step: step::<P>,
        dirty_region: dirty_region::<P>,
        map_cpu: map_cpu::<P>,
        map_gpu: map_gpu::<P>,
        removed_tetrahedra: removed_tetrahedra::<P>,
        notes: notes::<P>,
        set_point_loads: set_point_loads::<P>,
        compliance: compliance::<P>,
        resolve: resolve::<P>,
    }
}

/// Exports a [`DeformationPlugin`] as this library's `voxflex_plugin_v1`
/// entry point. One line per plugin crate:
///
/// ```ignore
/// voxflex_abi::export_deformation_plugin!(AffineField);
/// ```
#[macro_export]
macro_rules! export_deformation_plugin {
    ($ty:ty) => {
        static __VOXFLEX_VTABLE: $crate::ffi::DeformationVTable =
            $crate::plugin::deformation_vtable::<$ty>();
        static __VOXFLEX_DECLARATION: $crate::ffi::PluginDeclaration =
            $crate::ffi::PluginDeclaration {
                name: $crate::ffi::StrRef::from_static(
                    <$ty as $crate::plugin::DeformationPlugin>::NAME,
                ),
                version: $crate::ffi::StrRef::from_static(env!("CARGO_PKG_VERSION")),
                description: $crate::ffi::StrRef::from_static(
                    <$ty as $crate::plugin::DeformationPlugin>::DESCRIPTION,
                ),
                kind: $crate::ffi::PluginKind::Deformation as u32,
                capabilities: <$ty as $crate::plugin::DeformationPlugin>::CAPABILITIES,
                deformation: &__VOXFLEX_VTABLE,
                renderer: ::std::ptr::null(),
                actuator: ::std::ptr::null(),
                params_schema: $crate::params_schema::entry::<$ty>,
            };
        $crate::__export_header!(__VOXFLEX_DECLARATION);
    };
}

/// Emits the `voxflex_plugin_v1` entry point for a declaration static
/// (shared by every kind's export macro).
#[doc(hidden)]
#[macro_export]
macro_rules! __export_header {
    ($decl:ident) => {
        static __VOXFLEX_HEADER: $crate::ffi::PluginHeader = $crate::ffi::PluginHeader {
            magic: $crate::ffi::PLUGIN_MAGIC,
            abi_version: $crate::ABI_VERSION,
            reserved: 0,
            layout_hash: $crate::LAYOUT_HASH,
            declaration: &$decl,
        };
        /// The plugin's entry point, read by the voxflex host.
        #[unsafe(no_mangle)]
        pub extern "C" fn voxflex_plugin_v1() -> *const $crate::ffi::PluginHeader {
            &__VOXFLEX_HEADER
        }
    };
}
