//! Renderer plugins across the boundary, in one process: a renderer exported
//! with `renderer_vtable`, driven through `RendererProxy`.

use std::cell::Cell;
use std::sync::Arc;
use voxflex_abi::ffi::CAPABILITY_CPU;
use voxflex_abi::host_side::HostServices;
use voxflex_abi::renderer::{RendererProxy, renderer_vtable};
use voxflex_abi::{HostContext, RendererPlugin};
use voxflex_core::camera::{Camera, Projection};
use voxflex_core::deformation::{DirtyRegion, ExecutionBackend};
use voxflex_core::error::ModelError;
use voxflex_core::glam::DVec3;
use voxflex_core::gpu::BufferId;
use voxflex_core::grid::Grid;
use voxflex_core::opacity_map::OpacityMap;
use voxflex_core::render::{ImageTarget, RenderStats, RenderVolume, Renderer};
use voxflex_core::shared_volume::SharedVolume;
use voxflex_core::volume::{Volume, VolumeView, VoxelData, VoxelSlice};

thread_local! {
    /// The address of the last shared volume's first value `Flat` saw on
    /// this thread (the calls run on the caller's thread).
    static SEEN_AT: Cell<usize> = const { Cell::new(0) };
}

/// Paints every pixel with (mean voxel, #maps, azimuth, 255).
#[derive(Default)]
struct Flat {
    mean: f32,
    maps: usize,
    log: Vec<String>,
    /// The last shared volume, kept as a renderer keeps its volume.
    kept: Option<SharedVolume>,
    /// Refuses shared volumes (after looking at them).
    refuse_shared: bool,
}

impl Renderer for Flat {
    fn init(&mut self, backend: ExecutionBackend) -> Result<(), ModelError> {
        self.log.push(format!("{backend:?}"));
        Ok(())
    }
    fn configure(&mut self, toml: &str) -> Result<(), ModelError> {
        if toml.contains("bad") {
            return Err(ModelError::new("[render] bad: unknown key"));
        }
        self.refuse_shared = toml.contains("refuse_shared");
        Ok(())
    }
    fn set_volume(
        &mut self,
        volume: RenderVolume<'_>,
        dirty: DirtyRegion,
    ) -> Result<(), ModelError> {
        match volume {
            RenderVolume::Cpu(v) => {
                let all = v.data.to_f32_vec();
                self.mean = all.iter().sum::<f32>() / all.len() as f32;
            }
            RenderVolume::Gpu { values, .. } => self.mean = values.0 as f32,
            RenderVolume::Shared(v) => {
                let all = v.view().data.to_f32_vec();
                self.mean = all.iter().sum::<f32>() / all.len() as f32;
                let first = v.view().data.as_bytes().as_ptr();
                SEEN_AT.set(first as usize);
                if self.refuse_shared {
                    return Err(ModelError::new("refused"));
                }
                self.kept = Some(v.clone());
                self.log.push(format!("{dirty:?}"));
                return Ok(());
            }
        }
        self.kept = None;
        self.log.push(format!("{dirty:?}"));
        Ok(())
    }
    fn set_opacity_maps(&mut self, maps: &[OpacityMap]) -> Result<(), ModelError> {
        self.maps = maps.len();
        assert!(
            maps.iter()
                .all(|m| m.values.len() == m.dims.iter().product::<usize>())
        );
        Ok(())
    }
    fn render(
        &mut self,
        camera: &Camera,
        target: ImageTarget<'_>,
    ) -> Result<RenderStats, ModelError> {
        let ImageTarget::Cpu(px) = target else {
            return Err(ModelError::new("cpu only"));
        };
        for p in px.chunks_mut(4) {
            p.copy_from_slice(&[
                self.mean as u8,
                self.maps as u8,
                camera.azimuth_deg as u8,
                255,
            ]);
        }
        Ok(RenderStats {
            rays: (camera.width * camera.height) as u64,
            samples: 7,
            terminated_early: 1,
        })
    }
}

impl voxflex_abi::DeclaresParams for Flat {
    fn params_schema() -> Result<String, String> {
        Ok(r#"{"type":"object"}"#.into())
    }
}

impl RendererPlugin for Flat {
    const NAME: &'static str = "flat";
    const DESCRIPTION: &'static str = "test";
    const CAPABILITIES: u32 = CAPABILITY_CPU;
    fn create(params: &str, _: HostContext) -> Result<Self, ModelError> {
        if params.contains("panic") {
            panic!("flat panics on request");
        }
        Ok(Self::default())
    }
}

static VTABLE: voxflex_abi::ffi::RendererVTable = renderer_vtable::<Flat>();

fn proxy(params: &str) -> Result<RendererProxy, ModelError> {
    // SAFETY: static vtable of this test binary.
    unsafe { RendererProxy::create("flat", &VTABLE, params, HostServices::new(None, 1)) }
}

#[test]
fn render_round_trip() {
    let mut r = proxy("").unwrap();
    r.init(ExecutionBackend::Cpu).unwrap();
    r.configure("shading = true").unwrap();
    let grid = Grid::new([2, 1, 1], DVec3::ONE, DVec3::ZERO);
    let data = [10u8, 30];
    r.set_volume(
        RenderVolume::Cpu(VolumeView {
            grid,
            data: VoxelSlice::U8(&data),
        }),
        DirtyRegion::All,
    )
    .unwrap();
    r.set_volume(
        RenderVolume::Gpu {
            grid,
            values: BufferId(9),
        },
        DirtyRegion::None,
    )
    .unwrap();
    r.set_volume(
        RenderVolume::Cpu(VolumeView {
            grid,
            data: VoxelSlice::U8(&data),
        }),
        DirtyRegion::All,
    )
    .unwrap();
    let map = OpacityMap {
        origin: [0, 0, 0],
        dims: [2, 1, 1],
        outside: 0,
        values: vec![1, 2],
    };
    r.set_opacity_maps(&[map.clone(), map]).unwrap();
    let camera = Camera {
        target: DVec3::ZERO,
        azimuth_deg: 33.0,
        elevation_deg: 0.0,
        distance_mm: 10.0,
        projection: Projection::Perspective { fov_y_deg: 30.0 },
        width: 3,
        height: 2,
    };
    let mut px = vec![0u8; 3 * 2 * 4];
    let stats = r.render(&camera, ImageTarget::Cpu(&mut px)).unwrap();
    assert_eq!(&px[..4], &[20, 2, 33, 255]);
    assert_eq!(
        stats,
        RenderStats {
            rays: 6,
            samples: 7,
            terminated_early: 1
        }
    );
}

#[test]
fn renderer_errors_and_panics_name_the_plugin() {
    let e = proxy("panic").err().unwrap().to_string();
    assert!(
        e.starts_with("plugin `flat`: plugin panicked: flat panics on request"),
        "{e}"
    );
    let mut r = proxy("").unwrap();
    assert_eq!(
        r.configure("bad = 1").unwrap_err().to_string(),
        "plugin `flat`: [render] bad: unknown key"
    );
    let camera = one_pixel_camera(DVec3::NAN);
    let mut px = vec![0u8; 4];
    let e = r
        .render(&camera, ImageTarget::Cpu(&mut px))
        .unwrap_err()
        .to_string();
    assert!(e.contains("non-finite"), "{e}");
}

/// A 2-voxel u8 volume (10, 50) the host keeps in an `Arc`.
fn two_voxels() -> Arc<Volume> {
    let grid = Grid::new([2, 1, 1], DVec3::ONE, DVec3::ZERO);
    Arc::new(Volume::new(grid, VoxelData::U8(vec![10, 50])).unwrap())
}

/// A 1 × 1 orthographic camera looking at `target`.
fn one_pixel_camera(target: DVec3) -> Camera {
    Camera {
        target,
        azimuth_deg: 0.0,
        elevation_deg: 0.0,
        distance_mm: 10.0,
        projection: Projection::Orthographic { height_mm: 1.0 },
        width: 1,
        height: 1,
    }
}

/// A shared volume crosses without a copy, stays alive while the plugin
/// keeps it, and is released exactly once: when the plugin lets go of it,
/// when `set_volume` fails, and when the plugin is dropped.
#[test]
fn shared_volumes_are_lent_not_copied_and_released_once() {
    let volume = two_voxels();
    let shared = SharedVolume::new(volume.clone());
    let holders = || Arc::strong_count(&volume);
    assert_eq!(holders(), 2);
    let mut r = proxy("").unwrap();
    r.init(ExecutionBackend::Cpu).unwrap();
    r.set_volume(RenderVolume::Shared(&shared), DirtyRegion::All)
        .unwrap();
    // The plugin keeps the host's loan (one more holder), not a copy.
    assert_eq!(holders(), 3);
    drop(shared);
    assert_eq!(holders(), 2);
    let mut px = vec![0u8; 4];
    r.render(&one_pixel_camera(DVec3::ZERO), ImageTarget::Cpu(&mut px))
        .unwrap();
    assert_eq!(px[0], 30);
    // A copied volume replaces it: the loan is released.
    let other = two_voxels();
    r.set_volume(RenderVolume::Cpu(other.view()), DirtyRegion::All)
        .unwrap();
    assert_eq!(holders(), 1);
    // A failed call releases it too, and so does dropping the plugin.
    let shared = SharedVolume::new(volume.clone());
    r.configure("refuse_shared = true").unwrap();
    let e = r
        .set_volume(RenderVolume::Shared(&shared), DirtyRegion::All)
        .unwrap_err();
    assert!(e.to_string().ends_with("refused"), "{e}");
    assert_eq!(holders(), 2);
    r.configure("").unwrap();
    r.set_volume(RenderVolume::Shared(&shared), DirtyRegion::All)
        .unwrap();
    assert_eq!(holders(), 3);
    drop(r);
    assert_eq!(holders(), 2);
}

/// The plugin reads the host's own bytes: the address it saw (recorded
/// in a thread-local, as plugin and host share this process and thread) is the host's.
#[test]
fn a_shared_volume_reaches_the_plugin_at_the_hosts_address() {
    let volume = two_voxels();
    let first = volume.view().data.as_bytes().as_ptr() as usize;
    let shared = SharedVolume::new(volume);
    let mut r = proxy("").unwrap();
    r.set_volume(RenderVolume::Shared(&shared), DirtyRegion::All)
        .unwrap();
    assert_eq!(SEEN_AT.get(), first);
}
