//! [`SessionDefaults`]: the settings of a session built from a volume
//! rather than a scene file.

use crate::backend::BackendChoice;
use crate::gpu_context::WgpuService;
use std::path::PathBuf;
use std::sync::Arc;
use voxflex_io::ReadOptions;
use voxflex_resample::ResampleParams;

/// Settings of [`super::Session::from_volume`]; a scene file's `[scene]`
/// and `[resample]` tables hold the same.
#[derive(Clone, Debug)]
pub struct SessionDefaults {
    /// Where stages compute (`cpu`, `gpu` or `auto`; default `auto`).
    pub backend: BackendChoice,
    /// Plugin directories searched before `VOXFLEX_PLUGIN_PATH` and the
    /// executable's directory.
    pub plugin_dirs: Vec<PathBuf>,
    /// rayon worker threads; 0 = one per core. Only the first session (or
    /// scene) of a process sets it.
    pub threads: usize,
    /// Frames the model is told the run has (`FrameInfo::frames`); models
    /// say whether they came to rest on the last one. Default: unbounded.
    pub frames: u64,
    /// Time step per frame, seconds.
    pub dt_s: f64,
    /// Resampler parameters; their `background` is replaced by
    /// [`Self::background`].
    pub resample: ResampleParams,
    /// Background of the resampled volume (volume units); `None`: the
    /// source's lowest value.
    pub background: Option<f32>,
    /// Wait for the GPU at the end of each resample, so the stage's wall
    /// time is the work's (what `voxflex bench` measures); otherwise the
    /// work may still be queued when the stage returns.
    pub wait_for_gpu: bool,
    /// A device to compute on instead of opening one: a front end's (the
    /// viewer's eframe device), so the session's buffers live where the UI
    /// draws. `gpu` takes it, `auto` takes it when it is a hardware adapter
    /// ([`crate::backend::resolve_on`]); also after [`super::Session::set_backend`].
    pub gpu: Option<Arc<WgpuService>>,
    /// How a volume file is read (a scene's `[volume] max_voxels` and
    /// `oblique`): the voxel limit and what an oblique header becomes.
    pub read: ReadOptions,
}

impl Default for SessionDefaults {
    fn default() -> Self {
        let scene = crate::scene::SceneSettings::default();
        Self {
            backend: scene.backend,
            plugin_dirs: vec![],
            threads: scene.threads,
            frames: u64::MAX,
            dt_s: scene.dt_s,
            resample: ResampleParams::default(),
            background: None,
            wait_for_gpu: false,
            gpu: None,
            read: ReadOptions::default(),
        }
    }
}
