//! The whole boundary in one process: a model exported with the macro's
//! vtable, driven through `DeformationProxy`, with a recording GPU service
//! behind `HostServices` — trait → C → trait, both ways, panics included.

use std::sync::{Arc, Mutex};
use voxflex_abi::ffi::CAPABILITY_CPU;
use voxflex_abi::host_side::{DeformationProxy, HostServices};
use voxflex_abi::plugin::deformation_vtable;
use voxflex_abi::{DeformationPlugin, HostContext};
use voxflex_core::deformation::*;
use voxflex_core::error::{GpuError, ModelError};
use voxflex_core::glam::DVec3;
use voxflex_core::gpu::*;
use voxflex_core::grid::Grid;
use voxflex_core::volume::{VolumeView, VoxelSlice};

/// A model that records what it receives and misbehaves on request.
struct Probe {
    host: HostContext,
    seen: Vec<String>,
    offset: f32,
}

impl DeformationModel for Probe {
    fn init(
        &mut self,
        volume: VolumeView<'_>,
        backend: ExecutionBackend,
    ) -> Result<(), ModelError> {
        self.seen.push(format!(
            "init {:?} {} {:?}",
            volume.grid.dims,
            volume.data.get_f32(1),
            backend
        ));
        Ok(())
    }
    fn bind(&mut self, rest: RestPoints<'_>) -> Result<BindingId, ModelError> {
        Ok(BindingId(rest.len() as u64))
    }
    fn interact(&mut self, toml: &str) -> Result<(), ModelError> {
        match toml.trim() {
            "panic = true" => panic!("probe was asked to panic"),
            "fail = true" => Err(ModelError::new("probe refuses: key `fail`")),
            other => {
                self.seen.push(other.to_owned());
                Ok(())
            }
        }
    }
    fn step(&mut self, frame: FrameInfo) -> Result<StepOutcome, ModelError> {
        self.offset = frame.frame as f32;
        Ok(StepOutcome {
            changed: frame.frame < 2,
        })
    }
    fn dirty_region(&self) -> DirtyRegion {
        DirtyRegion::Box {
            min: DVec3::splat(-1.0),
            max: DVec3::splat(self.offset as f64),
        }
    }
    fn map(&mut self, binding: BindingId, out: DisplacementTarget<'_>) -> Result<(), ModelError> {
        match out {
            DisplacementTarget::Cpu { x, y, z } => {
                assert_eq!(x.len() as u64, binding.0);
                x.fill(self.offset);
                y.fill(2.0);
                z.fill(self.host.thread_count() as f32);
                Ok(())
            }
            DisplacementTarget::Gpu { x, .. } => {
                let gpu = self.host.gpu().ok_or_else(|| ModelError::new("no gpu"))?;
                gpu.write_buffer(x, 0, &7f32.to_le_bytes())?;
                let p = gpu.compile("wgsl text", "main")?;
                gpu.dispatch(p, &[BufferBinding::whole(0, x)], [1, 2, 3])?;
                gpu.dispatch_indirect(p, &[BufferBinding::whole(1, x)], BufferId(6), 12)?;
                Ok(())
            }
        }
    }
}

impl voxflex_abi::DeclaresParams for Probe {
    fn params_schema() -> Result<String, String> {
        Ok(r#"{"type":"object","properties":{"offset":{"type":"number"}}}"#.into())
    }
}

impl DeformationPlugin for Probe {
    const NAME: &'static str = "probe";
    const DESCRIPTION: &'static str = "test probe";
    const CAPABILITIES: u32 = CAPABILITY_CPU;
    fn create(params: &str, host: HostContext) -> Result<Self, ModelError> {
        if params.contains("bad") {
            return Err(ModelError::new("[model.params] bad: not allowed"));
        }
        Ok(Self {
            host,
            seen: vec![],
            offset: 0.0,
        })
    }
}

static VTABLE: voxflex_abi::ffi::DeformationVTable = deformation_vtable::<Probe>();

#[derive(Default)]
struct RecordingGpu {
    log: Mutex<Vec<String>>,
}

impl GpuService for RecordingGpu {
    fn adapter_description(&self) -> String {
        "recording".into()
    }
    fn limits(&self) -> GpuLimits {
        GpuLimits {
            max_storage_buffer_binding_size: 1 << 27,
            max_buffer_size: 1 << 31,
            max_compute_workgroups_per_dimension: 65535,
            min_storage_buffer_offset_alignment: 256,
        }
    }
    fn create_buffer(&self, size: u64, label: &str) -> Result<BufferId, GpuError> {
        self.log
            .lock()
            .unwrap()
            .push(format!("create {size} {label}"));
        Ok(BufferId(42))
    }
    fn destroy_buffer(&self, id: BufferId) {
        self.log.lock().unwrap().push(format!("destroy {}", id.0));
    }
    fn buffer_size(&self, _: BufferId) -> Result<u64, GpuError> {
        Ok(4)
    }
    fn write_buffer(&self, id: BufferId, offset: u64, bytes: &[u8]) -> Result<(), GpuError> {
        self.log
            .lock()
            .unwrap()
            .push(format!("write {} {offset} {bytes:?}", id.0));
        Ok(())
    }
    fn read_buffer(&self, _: BufferId, _: u64, _: &mut [u8]) -> Result<(), GpuError> {
        Err(GpuError("reads are not recorded".into()))
    }
    fn compile(&self, wgsl: &str, entry: &str) -> Result<PipelineId, GpuError> {
        self.log
            .lock()
            .unwrap()
            .push(format!("compile {wgsl} {entry}"));
        Ok(PipelineId(9))
    }
    fn dispatch(&self, p: PipelineId, b: &[BufferBinding], wg: [u32; 3]) -> Result<(), GpuError> {
        self.log
            .lock()
            .unwrap()
            .push(format!("dispatch {} {:?} {wg:?}", p.0, b));
        Ok(())
    }
    fn dispatch_indirect(
        &self,
        p: PipelineId,
        b: &[BufferBinding],
        args: BufferId,
        offset: u64,
    ) -> Result<(), GpuError> {
        self.log
            .lock()
            .unwrap()
            .push(format!("indirect {} {:?} {} {offset}", p.0, b, args.0));
        Ok(())
    }
}

fn proxy(params: &str, gpu: Option<Arc<dyn GpuService>>) -> Result<DeformationProxy, ModelError> {
    // SAFETY: a static vtable of this test binary.
    unsafe { DeformationProxy::create("probe", &VTABLE, params, HostServices::new(gpu, 3)) }
}

#[test]
fn every_call_round_trips() {
    let mut m = proxy("", None).unwrap();
    let grid = Grid::new([2, 2, 1], DVec3::ONE, DVec3::ZERO);
    let data = [1i16, -5, 3, 4];
    m.init(
        VolumeView {
            grid,
            data: VoxelSlice::I16(&data),
        },
        ExecutionBackend::Cpu,
    )
    .unwrap();
    let pts = [[0.0f32; 3]; 5];
    let b = m.bind(RestPoints::Points(&pts)).unwrap();
    assert_eq!(b, BindingId(5));
    assert_eq!(m.bind(RestPoints::Lattice(grid)).unwrap(), BindingId(4));
    m.interact("hello = 1").unwrap();
    assert!(
        m.step(FrameInfo {
            frame: 1,
            frames: 3,
            dt_s: 0.1
        })
        .unwrap()
        .changed
    );
    assert!(
        !m.step(FrameInfo {
            frame: 2,
            frames: 3,
            dt_s: 0.1
        })
        .unwrap()
        .changed
    );
    assert_eq!(
        m.dirty_region(),
        DirtyRegion::Box {
            min: DVec3::splat(-1.0),
            max: DVec3::splat(2.0)
        }
    );
    let (mut x, mut y, mut z) = (vec![0.0; 5], vec![0.0; 5], vec![0.0; 5]);
    m.map(
        b,
        DisplacementTarget::Cpu {
            x: &mut x,
            y: &mut y,
            z: &mut z,
        },
    )
    .unwrap();
    assert_eq!(
        (x[4], y[0], z[2]),
        (2.0, 2.0, 3.0),
        "thread count reaches the plugin"
    );
}

#[test]
fn errors_and_panics_come_back_as_messages_naming_the_plugin() {
    let e = proxy("bad = 1", None).err().unwrap().to_string();
    assert_eq!(e, "plugin `probe`: [model.params] bad: not allowed");
    let mut m = proxy("", None).unwrap();
    let e = m.interact("fail = true").unwrap_err().to_string();
    assert_eq!(e, "plugin `probe`: probe refuses: key `fail`");
    let e = m.interact("panic = true").unwrap_err().to_string();
    assert!(
        e.starts_with("plugin `probe`: plugin panicked: probe was asked to panic"),
        "{e}"
    );
    // The instance survives a caught panic.
    m.interact("after = 1").unwrap();
}

#[test]
fn gpu_calls_reach_the_host_service() {
    let gpu = Arc::new(RecordingGpu::default());
    let mut m = proxy("", Some(gpu.clone())).unwrap();
    let b = m
        .bind(RestPoints::Lattice(Grid::new(
            [1, 1, 1],
            DVec3::ONE,
            DVec3::ZERO,
        )))
        .unwrap();
    m.map(
        b,
        DisplacementTarget::Gpu {
            x: BufferId(5),
            y: BufferId(6),
            z: BufferId(7),
        },
    )
    .unwrap();
    let log = gpu.log.lock().unwrap().clone();
    assert_eq!(
        log,
        vec![
            "write 5 0 [0, 0, 224, 64]".to_owned(),
            "compile wgsl text main".to_owned(),
            "dispatch 9 [BufferBinding { binding: 0, buffer: BufferId(5), offset: 0, size: 0 }] [1, 2, 3]".to_owned(),
            "indirect 9 [BufferBinding { binding: 1, buffer: BufferId(5), offset: 0, size: 0 }] 6 12".to_owned(),
        ]
    );
    // Without a GPU the plugin sees none.
    let mut m = proxy("", None).unwrap();
    let e = m
        .map(
            b,
            DisplacementTarget::Gpu {
                x: BufferId(5),
                y: BufferId(6),
                z: BufferId(7),
            },
        )
        .unwrap_err();
    assert!(e.to_string().contains("no gpu"));
}
