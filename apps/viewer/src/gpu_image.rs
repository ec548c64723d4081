//! The 3D image on the GPU path: the session renders into a buffer on
//! eframe's own wgpu device ([`GpuFrame`]), and [`GpuImage`] turns it into
//! the texture egui draws — no read-back of the image.
//!
//! The device is shared: eframe opens it with the adapter's own limits
//! ([`wgpu_setup`]; the ray caster and the resampler bind large storage
//! buffers) and the host's GPU service is built on it ([`shared_service`]),
//! so the session's buffers are buffers of the device egui draws with.
//!
//! **Ordering.** One queue serves both: the session submits every command
//! of a render before [`Session::render_to_gpu`] returns, the worker then
//! sends the frame over a channel, and the UI thread submits the copy pass
//! after receiving it; egui's own draw is submitted later still. wgpu runs
//! a queue's submissions in order and inserts the barriers between them
//! (buffer written by a compute pass → read by the next submission's
//! pass), so no fence is needed. A later render into the same buffer that
//! reaches the queue before the copy makes the copy show the newer whole
//! image — a render is one dispatch, so an image is never half written.

use crate::open::OpenRequest;
use eframe::egui_wgpu::{RenderState, WgpuSetup, WgpuSetupCreateNew};
use eframe::wgpu;
use std::sync::Arc;
use voxflex_core::camera::Camera;
use voxflex_runtime::gpu_context::WgpuService;
use voxflex_runtime::pipeline::RunError;
use voxflex_runtime::session::{RenderParams, Session};

/// The kernel unpacking the session's image into egui's texture.
pub const PREMULTIPLY_WGSL: &str = include_str!("../../../shaders/viewer/premultiply.wgsl");
/// The kernel's workgroup edge (`TILE` in the WGSL), pixels.
pub const TILE: u32 = 8;

/// The device eframe (and the viewer's tests) open: the adapter's own
/// limits, not wgpu's defaults (which cap storage bindings at 128 MiB).
pub fn device_descriptor(adapter: &wgpu::Adapter) -> wgpu::DeviceDescriptor<'static> {
    wgpu::DeviceDescriptor {
        label: Some("voxflex viewer (shared with the session)"),
        required_limits: adapter.limits(),
        ..Default::default()
    }
}

/// `setup` opening its device with [`device_descriptor`].
pub fn with_adapter_limits(setup: WgpuSetup) -> WgpuSetup {
    match setup {
        WgpuSetup::CreateNew(s) => WgpuSetup::CreateNew(WgpuSetupCreateNew {
            device_descriptor: Arc::new(device_descriptor),
            ..s
        }),
        existing => existing,
    }
}

/// eframe's default wgpu setup with [`device_descriptor`].
pub fn wgpu_setup() -> WgpuSetup {
    with_adapter_limits(WgpuSetup::without_display_handle())
}

/// The host's GPU service on eframe's device and queue.
pub fn shared_service(state: &RenderState) -> Arc<WgpuService> {
    Arc::new(WgpuService::from_device(
        state.adapter.get_info(),
        state.device.clone(),
        state.queue.clone(),
    ))
}

/// A 3D image the session rendered into a buffer on the shared device:
/// `width · height` u32, RGBA8 (sRGB, straight alpha) packed with R in the
/// low byte, top row first.
#[derive(Clone, Debug)]
pub struct GpuFrame {
    /// The session's image buffer (this handle keeps it alive).
    pub buffer: wgpu::Buffer,
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
}

impl GpuFrame {
    /// Renders through `camera` into the session's GPU buffer when the
    /// session computes on `shared` (the UI's device); `None` otherwise
    /// (the CPU path, or no shared device), where the caller renders into
    /// memory.
    pub fn render(
        session: &mut Session,
        shared: Option<&Arc<WgpuService>>,
        camera: &Camera,
        params: &RenderParams,
    ) -> Result<Option<Self>, RunError> {
        let Some(gpu) = session
            .wgpu()
            .filter(|g| shared.is_some_and(|s| s.same_device(g)))
            .cloned()
        else {
            return Ok(None);
        };
        let id = session.render_to_gpu(camera, params)?;
        let buffer = gpu
            .raw_buffer(id)
            .map_err(|e| RunError::Other(format!("the 3D view's image buffer: {e}")))?;
        Ok(Some(Self {
            buffer,
            width: camera.width,
            height: camera.height,
        }))
    }
}

/// The texture egui draws the GPU path's 3D image from, filled from each
/// [`GpuFrame`] by [`PREMULTIPLY_WGSL`] (egui's textures hold premultiplied
/// alpha; the session's image straight alpha).
pub struct GpuImage {
    state: RenderState,
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    texture: Option<wgpu::Texture>,
    id: Option<egui::TextureId>,
    /// True when the last 3D image shown came from the GPU path.
    current: bool,
}

impl GpuImage {
    /// With eframe's render `state`: the GPU path's texture, and `req.gpu`
    /// set to eframe's device so that the session computes on it. Without a
    /// render state, or when the kernel fails on it (logged), `None` and
    /// `req` unchanged: a GPU session then opens its own device and its
    /// images come back to the CPU.
    pub fn share(state: Option<&RenderState>, req: &mut OpenRequest) -> Option<Self> {
        let state = state?;
        match Self::new(state.clone()) {
            Ok(g) => {
                req.gpu = Some(shared_service(state));
                Some(g)
            }
            Err(e) => {
                tracing::warn!("the 3D view cannot share eframe's device: {e}");
                None
            }
        }
    }

    /// Compiles the kernel on `state`'s device.
    pub fn new(state: RenderState) -> Result<Self, String> {
        let device = &state.device;
        let (pipeline, layout) = scoped(device, "compiling the 3D view's texture kernel", || {
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("viewer premultiply"),
                source: wgpu::ShaderSource::Wgsl(PREMULTIPLY_WGSL.into()),
            });
            let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some("viewer premultiply"),
                layout: None,
                module: &module,
                entry_point: Some("main"),
                compilation_options: wgpu::PipelineCompilationOptions::default(),
                cache: None,
            });
            let layout = pipeline.get_bind_group_layout(0);
            (pipeline, layout)
        })?;
        Ok(Self {
            state,
            pipeline,
            layout,
            texture: None,
            id: None,
            current: false,
        })
    }

    /// Fills the texture from `frame` (resized to it) on the shared queue
    /// and makes it the 3D view's image.
    pub fn show(&mut self, frame: &GpuFrame) -> Result<(), String> {
        let (w, h) = (frame.width, frame.height);
        let need = w as u64 * h as u64 * 4;
        if need == 0 || frame.buffer.size() < need {
            return Err(format!(
                "the 3D image buffer holds {} bytes but a {w}×{h} image needs {need}",
                frame.buffer.size()
            ));
        }
        let max = self.state.device.limits().max_texture_dimension_2d;
        if w > max || h > max {
            return Err(format!(
                "a {w}×{h} 3D image exceeds the device's {max}-pixel textures"
            ));
        }
        if self.texture.as_ref().map(|t| (t.width(), t.height())) != Some((w, h)) {
            self.resize(w, h)?;
        }
        let texture = self.texture.as_ref().expect("made by resize");
        let device = &self.state.device;
        let commands = scoped(device, "copying the 3D image into its texture", || {
            let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("viewer premultiply"),
                layout: &self.layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer: &frame.buffer,
                            offset: 0,
                            size: wgpu::BufferSize::new(need),
                        }),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: wgpu::BindingResource::TextureView(&view),
                    },
                ],
            });
            let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("viewer premultiply"),
            });
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("viewer premultiply"),
                    timestamp_writes: None,
                });
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &group, &[]);
                pass.dispatch_workgroups(w.div_ceil(TILE), h.div_ceil(TILE), 1);
            }
            encoder.finish()
        })?;
        scoped(device, "submitting the 3D image copy", || {
            self.state.queue.submit([commands]);
        })?;
        self.current = true;
        Ok(())
    }

    /// A new `w × h` texture, registered with egui's renderer under the
    /// same id as the last one.
    fn resize(&mut self, w: u32, h: u32) -> Result<(), String> {
        let device = &self.state.device;
        let texture = scoped(device, "creating the 3D view's texture", || {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some("viewer 3D image"),
                size: wgpu::Extent3d {
                    width: w,
                    height: h,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                // egui's native textures: sRGB values stored as plain unorm.
                format: wgpu::TextureFormat::Rgba8Unorm,
                usage: wgpu::TextureUsages::STORAGE_BINDING
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            })
        })?;
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        let mut renderer = self.state.renderer.write();
        let filter = wgpu::FilterMode::Linear;
        match self.id {
            Some(id) => renderer.update_egui_texture_from_wgpu_texture(device, &view, filter, id),
            None => self.id = Some(renderer.register_native_texture(device, &view, filter)),
        }
        self.texture = Some(texture);
        Ok(())
    }

    /// The texture the 3D view draws, while the last image shown came from
    /// the GPU path.
    pub fn texture_id(&self) -> Option<egui::TextureId> {
        self.id.filter(|_| self.current)
    }

    /// Marks the GPU image stale: a CPU image arrived (backend switched).
    pub fn set_stale(&mut self) {
        self.current = false;
    }

    /// The texture (premultiplied sRGB RGBA8), for tests that read it back.
    pub fn texture(&self) -> Option<&wgpu::Texture> {
        self.texture.as_ref()
    }

    /// The render state it draws with.
    pub fn render_state(&self) -> &RenderState {
        &self.state
    }
}

/// Runs `f` inside validation and out-of-memory error scopes: a wgpu error
/// comes back as a message naming `what` instead of reaching eframe's
/// handler.
fn scoped<R>(device: &wgpu::Device, what: &str, f: impl FnOnce() -> R) -> Result<R, String> {
    let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let out = f();
    let errors = [
        pollster::block_on(validation.pop()),
        pollster::block_on(oom.pop()),
    ];
    match errors.into_iter().flatten().next() {
        None => Ok(out),
        Some(e) => Err(format!("{what}: {e}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxflex_wgsl_check::ShaderSet;

    /// The kernel validates as wgpu would accept it, with the tile the
    /// dispatch divides by. (Its output against egui's CPU premultiply is
    /// checked on a GPU in tests/gpu_view.rs.)
    #[test]
    fn the_texture_kernel_validates_with_the_dispatch_tile() {
        let mut set = ShaderSet::new("viewer");
        let s = set.validate("viewer/premultiply.wgsl", PREMULTIPLY_WGSL);
        assert_eq!(s.compute_entry_points(), ["main"]);
        assert_eq!(s.workgroup_size("main"), [TILE, TILE, 1]);
        assert_eq!(s.const_u32("TILE"), TILE);
        set.finish();
    }
}
