//! # voxflex-affine — analytic deformation fields as a plugin
//!
//! Affine matrix, twist about an axis, and Barr bend, optionally confined to
//! a ball with a smooth fall-off and ramped in over several frames. Because
//! every field is known in closed form, this plugin is the exact reference
//! for the resampler's accuracy — and the model plugin authors copy: one
//! [`DeformationPlugin`] impl and one `export_deformation_plugin!` line.
//!
//! Scene usage:
//!
//! ```toml
//! [model]
//! plugin = "affine"
//! [model.params]
//! field = "twist"      # "affine" | "twist" | "bend"
//! axis = "z"
//! angle_deg = 40       # over the volume's extent along `axis`
//! ramp_frames = 10
//! ```
//!
//! The GPU path (`shaders/affine/field.wgsl`) writes the displacement
//! arrays in slabs of points where they exceed one storage binding (a
//! 512³ lattice's arrays are 512 MiB each), one dispatch per slab over a
//! window of every per-point array ([`PointFieldDispatch`]).

#![warn(missing_docs)]

pub mod field;
pub mod params;

use field::{FieldUniforms, UNIFORM_BYTES};
use params::AffineParams;
use rayon::prelude::*;
use std::sync::Arc;
use voxflex_abi::ffi::{CAPABILITY_CPU, CAPABILITY_GPU};
use voxflex_abi::{DeformationPlugin, HostContext};
use voxflex_core::deformation::{
    BindingId, DeformationModel, DirtyRegion, DisplacementTarget, ExecutionBackend, FrameInfo,
    RestPoints, StepOutcome,
};
use voxflex_core::error::ModelError;
use voxflex_core::glam::{DVec3, Vec3};
use voxflex_core::gpu::{BufferId, GpuService, GpuServiceExt};
use voxflex_core::grid::Grid;
use voxflex_core::point_slabs::PointFieldDispatch;
use voxflex_core::volume::VolumeView;

/// The WGSL twin of [`field::FieldUniforms::displacement`].
pub const FIELD_WGSL: &str = include_str!("../../../shaders/affine/field.wgsl");

/// Threads per workgroup of the field kernel (`@workgroup_size` in
/// `field.wgsl`).
const WORKGROUP: u32 = 64;

/// Binding numbers of `field.wgsl`'s variables (named as there).
mod bind {
    pub const U: u32 = 0;
    pub const PX: u32 = 1;
    pub const PY: u32 = 2;
    pub const PZ: u32 = 3;
    pub const UX: u32 = 4;
    pub const UY: u32 = 5;
    pub const UZ: u32 = 6;
}

enum Binding {
    Lattice(Grid),
    List {
        points: Vec<[f32; 3]>,
        gpu: Option<[BufferId; 3]>,
    },
}

/// An analytic deformation field (the `affine` plugin's model).
pub struct AffineField {
    params: AffineParams,
    gpu: Option<Arc<dyn GpuService>>,
    backend: ExecutionBackend,
    centre: DVec3,
    extent: DVec3,
    bindings: Vec<Binding>,
    /// Ramp factor of the current frame.
    amount: f64,
    /// Ramp factor the last `map` wrote.
    mapped_amount: f64,
    /// GPU scratch: the uniforms buffer.
    uniforms: Option<BufferId>,
    /// GPU scratch: 4-byte dummy for unused list bindings.
    dummy: Option<BufferId>,
}

impl AffineField {
    /// A field with parsed parameters, computing on the CPU until `init`.
    pub fn new(params: AffineParams, gpu: Option<Arc<dyn GpuService>>) -> Self {
        Self {
            params,
            gpu,
            backend: ExecutionBackend::Cpu,
            centre: DVec3::ZERO,
            extent: DVec3::ONE,
            bindings: Vec::new(),
            amount: 0.0,
            mapped_amount: 0.0,
            uniforms: None,
            dummy: None,
        }
    }

    /// The uniforms of the current frame.
    pub fn uniforms(&self) -> FieldUniforms {
        FieldUniforms::new(&self.params, self.amount, self.centre, self.extent)
    }

    fn binding(&self, id: BindingId) -> Result<&Binding, ModelError> {
        self.bindings
            .get(id.0 as usize)
            .ok_or_else(|| ModelError(format!("unknown binding id {}", id.0)))
    }

    fn map_cpu(
        &self,
        id: BindingId,
        x: &mut [f32],
        y: &mut [f32],
        z: &mut [f32],
    ) -> Result<(), ModelError> {
        let binding = self.binding(id)?;
        let (u, n) = match binding {
            Binding::Lattice(g) => (self.uniforms().with_lattice(g), g.len()),
            Binding::List { points, .. } => (self.uniforms().with_list(), points.len()),
        };
        if x.len() != n || y.len() != n || z.len() != n {
            return Err(ModelError(format!(
                "displacement arrays hold {} values but the binding has {n} points",
                x.len()
            )));
        }
        let (origin, spacing) = (
            Vec3::from_slice(&u.origin[..3]),
            Vec3::from_slice(&u.spacing[..3]),
        );
        let (nx, ny) = (u.counts[0] as usize, u.counts[1] as usize);
        // Same f32 formula as the WGSL kernel, so both paths agree.
        let point = |i: usize| -> Vec3 {
            match binding {
                Binding::Lattice(_) => {
                    let idx = Vec3::new(
                        (i % nx) as f32,
                        ((i / nx) % ny) as f32,
                        (i / (nx * ny)) as f32,
                    );
                    origin + idx * spacing
                }
                Binding::List { points, .. } => Vec3::from_array(points[i]),
            }
        };
        const CHUNK: usize = 4096;
        x.par_chunks_mut(CHUNK)
            .zip(y.par_chunks_mut(CHUNK))
            .zip(z.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, ((xs, ys), zs))| {
                let base = c * CHUNK;
                for o in 0..xs.len() {
                    let d = u.displacement(point(base + o));
                    xs[o] = d.x;
                    ys[o] = d.y;
                    zs[o] = d.z;
                }
            });
        Ok(())
    }

    fn map_gpu(&mut self, id: BindingId, out: [BufferId; 3]) -> Result<(), ModelError> {
        let gpu = self
            .gpu
            .clone()
            .ok_or_else(|| ModelError::new("map to GPU buffers, but the host gave no GPU"))?;
        let mut u = self.uniforms();
        let idx = id.0 as usize;
        let n = match self.binding(id)? {
            Binding::Lattice(g) => {
                u = u.with_lattice(g);
                g.len()
            }
            Binding::List { points, .. } => {
                u = u.with_list();
                points.len()
            }
        };
        if n > u32::MAX as usize {
            return Err(ModelError(format!(
                "{n} points exceed the GPU path's u32 index range"
            )));
        }
        let uniforms = match self.uniforms {
            Some(b) => b,
            None => *self
                .uniforms
                .insert(gpu.create_buffer(UNIFORM_BYTES as u64, "affine uniforms")?),
        };
        let dummy = match self.dummy {
            Some(b) => b,
            None => *self.dummy.insert(gpu.create_buffer(4, "affine dummy")?),
        };
        let list = match &mut self.bindings[idx] {
            Binding::Lattice(_) => None,
            Binding::List { points, gpu: slot } => Some(match slot {
                Some(ids) => *ids,
                None => {
                    let cols: [Vec<f32>; 3] =
                        std::array::from_fn(|a| points.iter().map(|p| p[a]).collect());
                    let ids = [
                        gpu.upload(&cols[0], "affine points x")?,
                        gpu.upload(&cols[1], "affine points y")?,
                        gpu.upload(&cols[2], "affine points z")?,
                    ];
                    *slot.insert(ids)
                }
            }),
        };
        // Compiled once: the host caches pipelines by the shader's hash.
        // Arrays longer than one storage binding (a 512³ lattice's are 512
        // MiB each) are written slab by slab, each dispatch binding a window
        // of every per-point array.
        let kernel = PointFieldDispatch {
            pipeline: gpu.compile(FIELD_WGSL, "main")?,
            workgroup: WORKGROUP,
            constants: (bind::U, uniforms),
            points: ([bind::PX, bind::PY, bind::PZ], list),
            spare: dummy,
            out: ([bind::UX, bind::UY, bind::UZ], out),
        };
        kernel.run(gpu.as_ref(), n, |slab| {
            bytemuck::bytes_of(&u.for_slab(slab.start, slab.len())).to_vec()
        })?;
        Ok(())
    }
}

impl Drop for AffineField {
    fn drop(&mut self) {
        if let Some(gpu) = &self.gpu {
            for id in self.uniforms.iter().chain(self.dummy.iter()) {
                gpu.destroy_buffer(*id);
            }
            for b in &self.bindings {
                if let Binding::List { gpu: Some(ids), .. } = b {
                    ids.iter().for_each(|&id| gpu.destroy_buffer(id));
                }
            }
        }
    }
}

impl DeformationModel for AffineField {
    fn init(
        &mut self,
        volume: VolumeView<'_>,
        backend: ExecutionBackend,
    ) -> Result<(), ModelError> {
        if backend == ExecutionBackend::Gpu && self.gpu.is_none() {
            return Err(ModelError::new(
                "backend is gpu but the host offered no GPU service",
            ));
        }
        self.backend = backend;
        let (lo, hi) = volume.grid.world_bounds();
        // A twist or bend spreads its angle over the extent along its axis:
        // a volume one voxel thick there has none (the rate would be ∞ and
        // every displacement NaN; found by `voxflex bench --stress`).
        let axis = self.params.axis as usize;
        if self.params.field != params::FieldKind::Affine && hi[axis] - lo[axis] <= 0.0 {
            return Err(ModelError(format!(
                "field = \"{}\" spreads `angle_deg` over the volume's extent along `axis` = \"{}\", \
                 but the volume is one voxel thick there ({:?} voxels); choose another `axis` or \
                 use field = \"affine\"",
                if self.params.field == params::FieldKind::Twist {
                    "twist"
                } else {
                    "bend"
                },
                ["x", "y", "z"][axis],
                volume.grid.dims
            )));
        }
        self.extent = (hi - lo).max(DVec3::splat(f64::MIN_POSITIVE));
        self.centre = self
            .params
            .centre
            .map_or(volume.grid.centre(), DVec3::from_array);
        Ok(())
    }

    fn bind(&mut self, rest: RestPoints<'_>) -> Result<BindingId, ModelError> {
        rest.check_finite()?;
        self.bindings.push(match rest {
            RestPoints::Lattice(g) => Binding::Lattice(g),
            RestPoints::Points(p) => Binding::List {
                points: p.to_vec(),
                gpu: None,
            },
        });
        Ok(BindingId(self.bindings.len() as u64 - 1))
    }

    fn interact(&mut self, interaction_toml: &str) -> Result<(), ModelError> {
        // A scene written for a simulated model (grabs, fixes, cuts) must
        // still run when its `plugin =` line is swapped to this analytic
        // field: the interactions have nothing to act on, so they are
        // ignored, loudly.
        tracing::warn!(
            interaction = interaction_toml.lines().next().unwrap_or("").trim(),
            "the affine field takes no interactions; ignored (animate it with `ramp_frames`)"
        );
        Ok(())
    }

    fn step(&mut self, frame: FrameInfo) -> Result<StepOutcome, ModelError> {
        let ramp = self.params.ramp_frames.max(1);
        let amount = ((frame.frame + 1) as f64 / ramp as f64).min(1.0);
        let changed = amount != self.amount;
        self.amount = amount;
        Ok(StepOutcome { changed })
    }

    fn dirty_region(&self) -> DirtyRegion {
        if self.amount == self.mapped_amount {
            return DirtyRegion::None;
        }
        match self.params.region {
            Some(r) => DirtyRegion::Box {
                min: DVec3::from_array(r.centre) - DVec3::splat(r.radius),
                max: DVec3::from_array(r.centre) + DVec3::splat(r.radius),
            },
            None => DirtyRegion::All,
        }
    }

    fn map(&mut self, binding: BindingId, out: DisplacementTarget<'_>) -> Result<(), ModelError> {
        match out {
            DisplacementTarget::Cpu { x, y, z } => self.map_cpu(binding, x, y, z)?,
            DisplacementTarget::Gpu { x, y, z } => self.map_gpu(binding, [x, y, z])?,
        }
        self.mapped_amount = self.amount;
        Ok(())
    }
}

impl voxflex_abi::DeclaresParams for AffineField {
    fn params_schema() -> Result<String, String> {
        voxflex_abi::params_schema::json(&schemars::schema_for!(AffineParams))
    }
}

impl DeformationPlugin for AffineField {
    const NAME: &'static str = "affine";
    const DESCRIPTION: &'static str =
        "analytic fields: affine matrix, twist, bend (exact reference)";
    const CAPABILITIES: u32 = CAPABILITY_CPU | CAPABILITY_GPU;

    fn create(params_toml: &str, host: HostContext) -> Result<Self, ModelError> {
        let params = AffineParams::from_toml(params_toml)?;
        tracing::debug!(?params, "affine plugin created");
        Ok(Self::new(params, host.gpu()))
    }
}

voxflex_abi::export_deformation_plugin!(AffineField);

#[cfg(test)]
mod shader_tests;

#[cfg(test)]
mod tests {
    use super::*;
    use voxflex_core::volume::VoxelSlice;

    fn field(text: &str) -> (AffineField, Grid) {
        let grid = Grid::centred([9, 8, 7], DVec3::new(1.0, 1.5, 2.0));
        let mut f = AffineField::new(AffineParams::from_toml(text).unwrap(), None);
        let data = vec![0u8; grid.len()];
        f.init(
            VolumeView {
                grid,
                data: VoxelSlice::U8(&data),
            },
            ExecutionBackend::Cpu,
        )
        .unwrap();
        (f, grid)
    }

    /// Regression (bench --stress, seed 13, affine scene 3): a twist about z
    /// of a volume one voxel thick along z mapped every point to NaN.
    #[test]
    fn twist_across_a_single_slice_is_refused() {
        let grid = Grid::centred([9, 4, 1], DVec3::new(1.2, 0.7, 0.5));
        let data = vec![0u8; grid.len()];
        let view = VolumeView {
            grid,
            data: VoxelSlice::U8(&data),
        };
        for field in ["twist", "bend"] {
            let text = format!("field = \"{field}\"\naxis = \"z\"\nangle_deg = 237");
            let mut f = AffineField::new(AffineParams::from_toml(&text).unwrap(), None);
            let e = f.init(view, ExecutionBackend::Cpu).unwrap_err().0;
            assert!(e.contains("one voxel thick") && e.contains("axis"), "{e}");
        }
        // Along an axis with an extent it runs, finite.
        let text = "field = \"twist\"\naxis = \"x\"\nangle_deg = 237";
        let mut f = AffineField::new(AffineParams::from_toml(text).unwrap(), None);
        f.init(view, ExecutionBackend::Cpu).unwrap();
        let b = f.bind(RestPoints::Lattice(grid)).unwrap();
        f.step(FrameInfo {
            frame: 0,
            frames: 1,
            dt_s: 0.1,
        })
        .unwrap();
        let n = grid.len();
        let (mut x, mut y, mut z) = (vec![0f32; n], vec![0f32; n], vec![0f32; n]);
        f.map(
            b,
            DisplacementTarget::Cpu {
                x: &mut x,
                y: &mut y,
                z: &mut z,
            },
        )
        .unwrap();
        assert!(x.iter().chain(&y).chain(&z).all(|v| v.is_finite()));
        assert!(y.iter().any(|v| v.abs() > 0.01), "the twist moved nothing");
    }

    #[test]
    fn ramps_then_converges() {
        let (mut f, grid) = field("field = \"twist\"\nangle_deg = 30\nramp_frames = 3");
        let b = f.bind(RestPoints::Lattice(grid)).unwrap();
        let n = grid.len();
        let (mut x, mut y, mut z) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        let mut changes = vec![];
        for frame in 0..5 {
            let s = f
                .step(FrameInfo {
                    frame,
                    frames: 5,
                    dt_s: 0.1,
                })
                .unwrap();
            changes.push(s.changed);
            if s.changed {
                assert_eq!(f.dirty_region(), DirtyRegion::All);
                f.map(
                    b,
                    DisplacementTarget::Cpu {
                        x: &mut x,
                        y: &mut y,
                        z: &mut z,
                    },
                )
                .unwrap();
                assert_eq!(f.dirty_region(), DirtyRegion::None);
            }
        }
        assert_eq!(changes, [true, true, true, false, false]);
    }

    #[test]
    fn lattice_and_list_bindings_agree() {
        let (mut f, grid) =
            field("field = \"bend\"\nangle_deg = 45\naxis = \"y\"\ntowards = \"z\"");
        let pts: Vec<[f32; 3]> = (0..grid.len())
            .map(|n| RestPoints::Lattice(grid).point(n).as_vec3().to_array())
            .collect();
        let a = f.bind(RestPoints::Lattice(grid)).unwrap();
        let b = f.bind(RestPoints::Points(&pts)).unwrap();
        f.step(FrameInfo {
            frame: 0,
            frames: 1,
            dt_s: 0.0,
        })
        .unwrap();
        let n = grid.len();
        let mut r = [
            vec![0.0; n],
            vec![0.0; n],
            vec![0.0; n],
            vec![0.0; n],
            vec![0.0; n],
            vec![0.0; n],
        ];
        let [ax, ay, az, bx, by, bz] = &mut r;
        f.map(
            a,
            DisplacementTarget::Cpu {
                x: ax,
                y: ay,
                z: az,
            },
        )
        .unwrap();
        f.map(
            b,
            DisplacementTarget::Cpu {
                x: bx,
                y: by,
                z: bz,
            },
        )
        .unwrap();
        for i in 0..3 {
            for (p, q) in r[i].iter().zip(&r[i + 3]) {
                assert!((p - q).abs() < 1e-4);
            }
        }
        assert!(r[0].iter().any(|v| *v != 0.0) || r[2].iter().any(|v| *v != 0.0));
    }

    #[test]
    fn map_rejects_wrong_lengths_and_unknown_bindings() {
        let (mut f, grid) = field("field = \"twist\"");
        let b = f.bind(RestPoints::Lattice(grid)).unwrap();
        let mut v = vec![0.0; 3];
        let (mut w, mut s) = (v.clone(), v.clone());
        assert!(
            f.map(
                b,
                DisplacementTarget::Cpu {
                    x: &mut v,
                    y: &mut w,
                    z: &mut s
                }
            )
            .is_err()
        );
        assert!(
            f.map(
                BindingId(9),
                DisplacementTarget::Cpu {
                    x: &mut v,
                    y: &mut w,
                    z: &mut s
                }
            )
            .is_err()
        );
    }
}
