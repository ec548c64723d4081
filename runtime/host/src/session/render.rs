//! [`Session::render`] and [`Session::render_to_gpu`]: the render stage
//! into an image in memory or into a GPU buffer the caller reads on the
//! session's device. Both go through one function with the target as a
//! parameter.

use super::model_stage::Displacements;
use super::{RenderParams, Session};
use crate::gpu_context::WgpuService;
use crate::pipeline::RunError;
use crate::visualise::RgbaImage;
use std::sync::Arc;
use std::time::Instant;
use voxflex_core::camera::Camera;
use voxflex_core::deformation::{DirtyRegion, ExecutionBackend};
use voxflex_core::gpu::{BufferId, GpuService};
use voxflex_core::grid::Grid;
use voxflex_core::opacity_map::OpacityMap;
use voxflex_core::render::{ImageTarget, RenderVolume};
use voxflex_core::shared_volume::SharedVolume;

impl Session {
    /// Renders the current volume with the session's ROI maps through
    /// `camera` into an RGBA8 image in memory. The renderer is built on
    /// first use (and rebuilt when `params` names another plugin); changed
    /// parameters are handed to it. Only the region the resampler re-filled
    /// since the last render is handed over as changed.
    pub fn render(
        &mut self,
        camera: &Camera,
        params: &RenderParams,
    ) -> Result<RgbaImage, RunError> {
        let mut pixels = vec![0u8; camera.width as usize * camera.height as usize * 4];
        self.render_into(camera, params, ImageTarget::Cpu(&mut pixels))?;
        Ok(RgbaImage {
            width: camera.width,
            height: camera.height,
            pixels,
        })
    }

    /// [`Self::render`] into a buffer on the session's GPU device instead of
    /// memory: `camera.width · camera.height` u32, each an RGBA8 pixel
    /// (sRGB, straight alpha) packed little-endian (R in the low byte), row
    /// by row from the top-left. Nothing is read back.
    ///
    /// The buffer belongs to the session and is reused by the next call of
    /// the same size (a new one is made for another size); it is destroyed
    /// when the backend changes or the session is dropped — a front end
    /// that keeps the wgpu buffer ([`WgpuService::raw_buffer`]) keeps it
    /// alive. Every command of the render has been submitted to the device's
    /// queue when this returns, so work the caller then submits on the same
    /// queue (e.g. a copy into a texture) runs after it. Errors on the CPU
    /// backend.
    pub fn render_to_gpu(
        &mut self,
        camera: &Camera,
        params: &RenderParams,
    ) -> Result<BufferId, RunError> {
        let Some(gpu) = self.resolved.gpu.clone() else {
            return Err(RunError::Other(format!(
                "{}: render_to_gpu: the session computes on the CPU; set the backend to `gpu` \
                 (Session::set_backend) or use Session::render",
                self.context
            )));
        };
        let bytes = camera.width as u64 * camera.height as u64 * 4;
        let id = self.gpu_image_buffer(&gpu, bytes)?;
        self.render_into(camera, params, ImageTarget::Gpu(id))?;
        gpu.flush()
            .map_err(|e| RunError::Other(format!("{}: render_to_gpu: {e}", self.context)))?;
        Ok(id)
    }

    /// The GPU service the session computes on, `None` on the CPU: the
    /// host-side handle on the device ([`WgpuService::raw_buffer`] for the
    /// buffer of [`Self::render_to_gpu`]).
    pub fn wgpu(&self) -> Option<&Arc<WgpuService>> {
        self.resolved.gpu.as_ref()
    }

    /// The session's image buffer of `bytes` bytes, made (and the old one
    /// destroyed) when there is none of that size.
    fn gpu_image_buffer(&mut self, gpu: &WgpuService, bytes: u64) -> Result<BufferId, RunError> {
        match self.gpu_image {
            Some((id, have)) if have == bytes => return Ok(id),
            Some((id, _)) => {
                gpu.destroy_buffer(id);
                self.gpu_image = None;
            }
            None => {}
        }
        let id = gpu
            .create_buffer(bytes, "session render image")
            .map_err(|e| RunError::Other(format!("{}: render_to_gpu: {e}", self.context)))?;
        self.gpu_image = Some((id, bytes));
        Ok(id)
    }

    /// The current volume in the resampler's GPU output buffer (grid, mm,
    /// and buffer of f32), when the session computes on the GPU and has
    /// resampled: the renderer binds it as is, so rendering reads nothing
    /// back. `None` on the CPU and before the first resample (the source).
    fn gpu_volume(&self) -> Option<(Grid, BufferId)> {
        if self.resolved.backend != ExecutionBackend::Gpu || self.versions.resample.version == 0 {
            return None;
        }
        let (Some(res), Some(Displacements::Gpu { .. })) = (&self.resample, &self.displacements)
        else {
            return None;
        };
        res.resampler
            .output_grid()
            .zip(res.resampler.gpu_output_buffer())
    }

    /// The render stage into `target`: builds or reconfigures the renderer,
    /// hands it the current volume's changed region (from the GPU buffer on
    /// the GPU path, see [`Self::gpu_volume`]) and the ROI maps,
    /// renders and records the stage's metrics.
    fn render_into(
        &mut self,
        camera: &Camera,
        params: &RenderParams,
        target: ImageTarget<'_>,
    ) -> Result<(), RunError> {
        match &mut self.renderer {
            Some(slot) if slot.plugin.name == params.plugin => {
                if slot.params_toml != params.params_toml {
                    slot.stage.configure(&params.params_toml)?;
                    slot.params_toml = params.params_toml.clone();
                }
            }
            _ => {
                let p = self.load_plugin(&params.plugin)?;
                self.build_renderer(&p, &params.params_toml)?;
            }
        }
        let t = Instant::now();
        let on_gpu = self.gpu_volume();
        if on_gpu.is_none() {
            self.ensure_volume()?;
        }
        let maps: Vec<OpacityMap> = self
            .rois
            .iter()
            .filter(|r| r.shown)
            .map(|r| r.map().clone())
            .collect();
        // The source never changes, so the renderer may keep it instead of
        // copying it; the resampled volume is rewritten in place each frame.
        let source = SharedVolume::new(self.source.clone());
        let volume = match (on_gpu, &self.resampled) {
            (Some((grid, values)), _) => RenderVolume::Gpu { grid, values },
            (None, Some((_, v))) => RenderVolume::Cpu(v.view()),
            (None, None) => RenderVolume::Shared(&source),
        };
        let slot = self.renderer.as_mut().expect("built above");
        slot.stage.set_scene_on(volume, self.render_dirty, &maps)?;
        let stats = slot.stage.render_into(camera, target)?;
        self.render_dirty = DirtyRegion::None;
        self.versions.render.ran_on(self.versions.resample.version);
        let stage = self.metrics.stage("render");
        stage.record_run(t.elapsed(), stats.rays);
        let samples = stage.notes.get("samples").and_then(|v| v.as_u64());
        stage.notes.insert(
            "samples".into(),
            (samples.unwrap_or(0) + stats.samples).into(),
        );
        Ok(())
    }
}
