//! Renderer plugins across the boundary, in one process: a renderer exported
//! with `renderer_vtable`, driven through `RendererProxy`.

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
use voxflex_core::volume::{VolumeView, VoxelSlice};

/// Paints every pixel with (mean voxel, #maps, azimuth, 255).
#[derive(Default)]
struct Flat {
    mean: f32,
    maps: usize,
    log: Vec<String>,
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
        }
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
    let camera = Camera {
        target: DVec3::NAN,
        azimuth_deg: 0.0,
        elevation_deg: 0.0,
        distance_mm: 1.0,
        projection: Projection::Orthographic { height_mm: 1.0 },
        width: 1,
        height: 1,
    };
    let mut px = vec![0u8; 4];
    let e = r
        .render(&camera, ImageTarget::Cpu(&mut px))
        .unwrap_err()
        .to_string();
    assert!(e.contains("non-finite"), "{e}");
}
