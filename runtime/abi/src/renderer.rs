//! Renderer plugins across the boundary: the plugin side
//! ([`RendererPlugin`], [`crate::export_renderer_plugin!`]) and the host side
//! ([`RendererProxy`]), mirroring `voxflex_core::render::Renderer`.

use crate::ffi::*;
use crate::guard::guard;
use crate::host_side::{HostServices, checked_call, create_proxy_instance};
use crate::plugin::{HostContext, create_instance, destroy_instance, state};
use std::ffi::c_void;
use std::sync::Arc;
use voxflex_core::camera::Camera;
use voxflex_core::deformation::{DirtyRegion, ExecutionBackend};
use voxflex_core::error::ModelError;
use voxflex_core::gpu::BufferId;
use voxflex_core::opacity_map::OpacityMap;
use voxflex_core::render::{ImageTarget, RenderStats, RenderVolume, Renderer};
use voxflex_core::shared_volume::SharedVolume;

/// A renderer that can be exported as a plugin.
pub trait RendererPlugin:
    Renderer + crate::params_schema::DeclaresParams + Sized + 'static
{
    /// Name scenes use (`[render] plugin = "..."`).
    const NAME: &'static str;
    /// One-line description for `voxflex plugins`.
    const DESCRIPTION: &'static str;
    /// [`CAPABILITY_CPU`] | [`CAPABILITY_GPU`].
    const CAPABILITIES: u32;
    /// Creates an instance from the TOML text of the scene's render parameters.
    fn create(params_toml: &str, host: HostContext) -> Result<Self, ModelError>;
}

fn backend_of(code: u32) -> Result<ExecutionBackend, String> {
    match code {
        0 => Ok(ExecutionBackend::Cpu),
        1 => Ok(ExecutionBackend::Gpu),
        b => Err(format!("unknown backend code {b}")),
    }
}

unsafe extern "C" fn create<P: RendererPlugin>(
    params: StrRef,
    host: *const HostApi,
    out: *mut Instance,
    err: *mut ErrorBuf,
) -> i32 {
    create_instance(params, host, out, err, P::create)
}

unsafe extern "C" fn destroy<P: RendererPlugin>(instance: Instance) {
    // SAFETY: host contract.
    unsafe { destroy_instance::<P>(instance) }
}

unsafe extern "C" fn init<P: RendererPlugin>(
    instance: Instance,
    backend: u32,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        s.model
            .init(backend_of(backend)?)
            .map_err(|e| e.to_string())
    })
}

unsafe extern "C" fn configure<P: RendererPlugin>(
    instance: Instance,
    toml: StrRef,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract; text alive during the call.
        let (s, text) = unsafe { (state::<P>(instance)?, toml.to_string_lossy()) };
        s.model.configure(&text).map_err(|e| e.to_string())
    })
}

unsafe extern "C" fn set_volume<P: RendererPlugin>(
    instance: Instance,
    volume: *const RenderVolumeDesc,
    dirty: *const RegionDesc,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        if volume.is_null() {
            return Err("null volume".into());
        }
        // SAFETY: checked non-null; the host keeps the descriptor alive
        // during the call.
        let desc = unsafe { *volume };
        // Taken first, so lent values are released whatever happens below.
        // SAFETY: host contract for a shared volume's `owner` and `release`.
        let loan = unsafe { HostLoan::take(&desc) }?;
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        if dirty.is_null() {
            return Err("null region".into());
        }
        // SAFETY: checked non-null; alive during the call.
        let region = unsafe { (*dirty).to_region() };
        let shared;
        let volume = match (desc.tag, loan) {
            // SAFETY: the host keeps the data alive during the call.
            (RENDER_VOLUME_CPU, _) => RenderVolume::Cpu(unsafe { desc.volume.to_view() }?),
            (RENDER_VOLUME_GPU, _) => RenderVolume::Gpu {
                grid: desc.volume.grid.to_grid()?,
                values: BufferId(desc.buffer),
            },
            (RENDER_VOLUME_SHARED, Some(loan)) => {
                // SAFETY: the host keeps the values alive and unchanged
                // until `loan` (inside the shared volume) releases them.
                shared = unsafe { SharedVolume::from_raw(desc.volume.to_view()?, Arc::new(loan)) };
                RenderVolume::Shared(&shared)
            }
            (t, _) => return Err(format!("unknown render volume tag {t}")),
        };
        s.model
            .set_volume(volume, region)
            .map_err(|e| e.to_string())
    })
}

/// The host's hold on values it lent ([`RENDER_VOLUME_SHARED`]): calls
/// the host's `release` with its `owner` once, when dropped.
struct HostLoan {
    owner: *mut c_void,
    release: unsafe extern "C" fn(owner: *mut c_void),
}

// SAFETY: the ABI lets `release` run on any thread, and nothing else
// touches `owner`.
unsafe impl Send for HostLoan {}
// SAFETY: as above; `&HostLoan` gives no access at all.
unsafe impl Sync for HostLoan {}

impl HostLoan {
    /// The loan of a [`RENDER_VOLUME_SHARED`] descriptor (`None` for the
    /// other tags).
    ///
    /// # Safety
    /// For that tag, `owner` and `release` are the host's, to be called
    /// once.
    unsafe fn take(desc: &RenderVolumeDesc) -> Result<Option<Self>, String> {
        if desc.tag != RENDER_VOLUME_SHARED {
            return Ok(None);
        }
        match desc.release {
            Some(release) => Ok(Some(Self {
                owner: desc.owner,
                release,
            })),
            None => Err("shared render volume without a release function".into()),
        }
    }
}

impl Drop for HostLoan {
    fn drop(&mut self) {
        // SAFETY: called once, with the host's own handle.
        unsafe { (self.release)(self.owner) }
    }
}

/// The host's `release` for a volume it lent: drops the boxed clone that
/// [`RendererProxy::set_volume`] made.
unsafe extern "C" fn release_shared(owner: *mut c_void) {
    // SAFETY: `owner` is the `Box<SharedVolume>` made for this loan, and
    // the plugin releases it once.
    drop(unsafe { Box::from_raw(owner.cast::<SharedVolume>()) });
}

unsafe extern "C" fn set_opacity_maps<P: RendererPlugin>(
    instance: Instance,
    maps: *const OpacityMapDesc,
    count: u64,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        let count = usize::try_from(count).map_err(|_| "too many maps".to_owned())?;
        if count > 0 && maps.is_null() {
            return Err("null opacity map array".into());
        }
        let descs = if count == 0 {
            &[][..]
        } else {
            // SAFETY: `count` descriptors, alive during the call.
            unsafe { std::slice::from_raw_parts(maps, count) }
        };
        // SAFETY: each descriptor's values alive during the call.
        let maps: Vec<OpacityMap> = descs
            .iter()
            .map(|d| unsafe { d.to_map() })
            .collect::<Result<_, _>>()?;
        s.model.set_opacity_maps(&maps).map_err(|e| e.to_string())
    })
}

unsafe extern "C" fn render<P: RendererPlugin>(
    instance: Instance,
    camera: *const CameraDesc,
    target: *const ImageTargetDesc,
    out_stats: *mut RenderStatsDesc,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        if camera.is_null() || target.is_null() || out_stats.is_null() {
            return Err("null camera, target or stats pointer".into());
        }
        // SAFETY: checked non-null; plain data.
        let (camera, t) = unsafe { ((*camera).to_camera()?, *target) };
        let target = match t.tag {
            IMAGE_TARGET_CPU => {
                let len = usize::try_from(t.len).map_err(|_| "image too large".to_owned())?;
                if len > 0 && t.pixels.is_null() {
                    return Err("null pixel pointer".into());
                }
                let pixels: &mut [u8] = if len == 0 {
                    &mut []
                } else {
                    // SAFETY: the host passes `len` writable bytes.
                    unsafe { std::slice::from_raw_parts_mut(t.pixels, len) }
                };
                ImageTarget::Cpu(pixels)
            }
            IMAGE_TARGET_GPU => ImageTarget::Gpu(BufferId(t.buffer)),
            other => return Err(format!("unknown image target tag {other}")),
        };
        let stats = s.model.render(&camera, target).map_err(|e| e.to_string())?;
        // SAFETY: checked non-null.
        unsafe { *out_stats = stats.into() };
        Ok(())
    })
}

/// The vtable of renderer type `P` (used by [`crate::export_renderer_plugin!`]).
pub const fn renderer_vtable<P: RendererPlugin>() -> RendererVTable {
    RendererVTable {
        create: create::<P>,
        destroy: destroy::<P>,
        init: init::<P>,
        configure: configure::<P>,
        set_volume: set_volume::<P>,
        set_opacity_maps: set_opacity_maps::<P>,
        render: render::<P>,
    }
}

/// Exports a [`RendererPlugin`] as this library's `voxflex_plugin_v1` entry point.
#[macro_export]
macro_rules! export_renderer_plugin {
    ($ty:ty) => {
        static __VOXFLEX_VTABLE: $crate::ffi::RendererVTable =
            $crate::renderer::renderer_vtable::<$ty>();
        static __VOXFLEX_DECLARATION: $crate::ffi::PluginDeclaration =
            $crate::ffi::PluginDeclaration {
                name: $crate::ffi::StrRef::from_static(
                    <$ty as $crate::renderer::RendererPlugin>::NAME,
                ),
                version: $crate::ffi::StrRef::from_static(env!("CARGO_PKG_VERSION")),
                description: $crate::ffi::StrRef::from_static(
                    <$ty as $crate::renderer::RendererPlugin>::DESCRIPTION,
                ),
                kind: $crate::ffi::PluginKind::Renderer as u32,
                capabilities: <$ty as $crate::renderer::RendererPlugin>::CAPABILITIES,
                deformation: ::std::ptr::null(),
                renderer: &__VOXFLEX_VTABLE,
                actuator: ::std::ptr::null(),
                params_schema: $crate::params_schema::entry::<$ty>,
            };
        $crate::__export_header!(__VOXFLEX_DECLARATION);
    };
}

/// A renderer plugin instance seen as a [`Renderer`].
pub struct RendererProxy {
    name: String,
    vtable: &'static RendererVTable,
    instance: Instance,
    _services: Arc<HostServices>,
}

// SAFETY: used through &mut self only, one thread at a time.
unsafe impl Send for RendererProxy {}

impl RendererProxy {
    /// Creates an instance of a renderer plugin from its vtable.
    ///
    /// # Safety
    /// `vtable` must be a valid renderer vtable from a library never unloaded.
    pub unsafe fn create(
        name: &str,
        vtable: &'static RendererVTable,
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

    fn call(&self, f: impl FnOnce(*mut ErrorBuf) -> i32) -> Result<(), ModelError> {
        checked_call(&self.name, f)
    }
}

impl Drop for RendererProxy {
    fn drop(&mut self) {
        // SAFETY: made by this vtable's create, destroyed once.
        unsafe { (self.vtable.destroy)(self.instance) }
    }
}

impl Renderer for RendererProxy {
    fn init(&mut self, backend: ExecutionBackend) -> Result<(), ModelError> {
        let (vt, inst) = (self.vtable, self.instance);
        // SAFETY: plain arguments.
        self.call(|err| unsafe { (vt.init)(inst, backend as u32, err) })
    }

    fn configure(&mut self, settings_toml: &str) -> Result<(), ModelError> {
        let (vt, inst) = (self.vtable, self.instance);
        // SAFETY: text alive during the call.
        self.call(|err| unsafe { (vt.configure)(inst, StrRef::new(settings_toml), err) })
    }

    fn set_volume(
        &mut self,
        volume: RenderVolume<'_>,
        dirty: DirtyRegion,
    ) -> Result<(), ModelError> {
        let desc = match volume {
            RenderVolume::Cpu(view) => RenderVolumeDesc {
                tag: RENDER_VOLUME_CPU,
                reserved: 0,
                volume: VolumeDesc::from_view(&view),
                buffer: 0,
                owner: std::ptr::null_mut(),
                release: None,
            },
            RenderVolume::Shared(shared) => RenderVolumeDesc {
                tag: RENDER_VOLUME_SHARED,
                reserved: 0,
                volume: VolumeDesc::from_view(&shared.view()),
                buffer: 0,
                // Released by the plugin (`release_shared`), once.
                owner: Box::into_raw(Box::new(shared.clone())).cast(),
                release: Some(release_shared),
            },
            RenderVolume::Gpu { grid, values } => RenderVolumeDesc {
                tag: RENDER_VOLUME_GPU,
                reserved: 0,
                volume: VolumeDesc {
                    grid: grid.into(),
                    scalar_type: voxflex_core::volume::ScalarType::F32 as u32,
                    reserved: 0,
                    data: std::ptr::null(),
                    len: grid.len() as u64,
                },
                buffer: values.0,
                owner: std::ptr::null_mut(),
                release: None,
            },
        };
        let region = RegionDesc::from(dirty);
        let (vt, inst) = (self.vtable, self.instance);
        // SAFETY: descriptors and data alive during the call.
        self.call(|err| unsafe { (vt.set_volume)(inst, &desc, &region, err) })
    }

    fn set_opacity_maps(&mut self, maps: &[OpacityMap]) -> Result<(), ModelError> {
        let descs: Vec<OpacityMapDesc> = maps.iter().map(OpacityMapDesc::from_map).collect();
        let (vt, inst) = (self.vtable, self.instance);
        // SAFETY: descriptors and maps alive during the call.
        self.call(|err| unsafe {
            (vt.set_opacity_maps)(inst, descs.as_ptr(), descs.len() as u64, err)
        })
    }

    fn render(
        &mut self,
        camera: &Camera,
        target: ImageTarget<'_>,
    ) -> Result<RenderStats, ModelError> {
        let cam = CameraDesc::from(camera);
        let desc = match target {
            ImageTarget::Cpu(pixels) => ImageTargetDesc {
                tag: IMAGE_TARGET_CPU,
                reserved: 0,
                pixels: pixels.as_mut_ptr(),
                len: pixels.len() as u64,
                buffer: 0,
            },
            ImageTarget::Gpu(b) => ImageTargetDesc {
                tag: IMAGE_TARGET_GPU,
                reserved: 0,
                pixels: std::ptr::null_mut(),
                len: 0,
                buffer: b.0,
            },
        };
        let mut stats = RenderStatsDesc::default();
        let (vt, inst) = (self.vtable, self.instance);
        // SAFETY: everything alive during the call.
        self.call(|err| unsafe { (vt.render)(inst, &cam, &desc, &mut stats, err) })?;
        Ok(stats.into())
    }
}
