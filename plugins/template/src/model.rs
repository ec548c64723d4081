//! STEP 4: the model — [`DeformationModel`], the contract every deformation
//! plugin fulfils, with its rayon path and its WGSL path side by side.
//!
//! The host calls, in order: `interact` (before `init`: a dry run that only
//! validates, for `voxflex validate`), `init` once, `bind` once per point
//! set, then every frame `interact` (scripted interactions), `step`, and —
//! when `step` said something changed — `dirty_region` and `map`.

use crate::field::{FieldUniforms, UNIFORM_BYTES};
use crate::params::TemplateParams;
use rayon::prelude::*;
use std::sync::Arc;
use voxflex_core::deformation::{
    BindingId, DeformationModel, DirtyRegion, DisplacementTarget, ExecutionBackend, FrameInfo,
    RestPoints, StepOutcome,
};
use voxflex_core::error::ModelError;
use voxflex_core::glam::{DVec3, Vec3};
use voxflex_core::gpu::{BufferId, GpuService, GpuServiceExt};
use voxflex_core::grid::Grid;
use voxflex_core::interaction::InteractionSpec;
use voxflex_core::point_slabs::PointFieldDispatch;
use voxflex_core::volume::VolumeView;

/// The WGSL twin of [`FieldUniforms::displacement`] (STEP 5).
pub const FIELD_WGSL: &str = include_str!("../../../shaders/template/bulge.wgsl");

/// Threads per workgroup of the kernel (`@workgroup_size` in the WGSL).
pub(crate) const WORKGROUP: u32 = 64;

/// Binding numbers of `bulge.wgsl`'s variables (named as there).
pub(crate) mod bind {
    pub const U: u32 = 0;
    pub const PX: u32 = 1;
    pub const PY: u32 = 2;
    pub const PZ: u32 = 3;
    pub const UX: u32 = 4;
    pub const UY: u32 = 5;
    pub const UZ: u32 = 6;
}

/// A point set the host bound (`bind`), and its device copy once a GPU
/// `map` needed one.
enum Binding {
    /// Every node of a lattice (the voxel centres of the sampling mesh),
    /// never materialised as a list.
    Lattice(Grid),
    /// An explicit list of points, world mm; `gpu` holds its x, y, z
    /// columns on the device after the first GPU map.
    List {
        points: Vec<[f32; 3]>,
        gpu: Option<[BufferId; 3]>,
    },
}

/// The bulge field: the model of the `template` plugin.
pub struct TemplateField {
    params: TemplateParams,
    /// The host's GPU service (`None` when the host has no GPU).
    gpu: Option<Arc<dyn GpuService>>,
    backend: ExecutionBackend,
    /// Ball centre, world mm (set in `init`).
    centre: DVec3,
    bindings: Vec<Binding>,
    /// Ramp factor of the current frame, 0 … 1.
    amount: f64,
    /// Ramp factor the last `map` wrote (nothing is dirty when equal).
    mapped_amount: f64,
    /// Device scratch: the constants block, created on first use.
    uniforms: Option<BufferId>,
    /// Device scratch: 4 bytes bound in place of a lattice's point columns.
    dummy: Option<BufferId>,
}

impl TemplateField {
    /// A field with parsed parameters, computing on the CPU until `init`.
    pub fn new(params: TemplateParams, gpu: Option<Arc<dyn GpuService>>) -> Self {
        Self {
            params,
            gpu,
            backend: ExecutionBackend::Cpu,
            centre: DVec3::ZERO,
            bindings: Vec::new(),
            amount: 0.0,
            mapped_amount: 0.0,
            uniforms: None,
            dummy: None,
        }
    }

    /// The constants of the current frame.
    pub fn uniforms(&self) -> FieldUniforms {
        FieldUniforms::new(&self.params, self.amount, self.centre)
    }

    fn binding(&self, id: BindingId) -> Result<&Binding, ModelError> {
        self.bindings
            .get(id.0 as usize)
            .ok_or_else(|| ModelError(format!("unknown binding id {}", id.0)))
    }

    /// The rayon path: every point's displacement, in chunks over the
    /// host-sized thread pool.
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
        let point = |i: usize| match binding {
            Binding::Lattice(_) => u.lattice_point(i),
            Binding::List { points, .. } => Vec3::from_array(points[i]),
        };
        const CHUNK: usize = 4096;
        x.par_chunks_mut(CHUNK)
            .zip(y.par_chunks_mut(CHUNK))
            .zip(z.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, ((xs, ys), zs))| {
                for o in 0..xs.len() {
                    let d = u.displacement(point(c * CHUNK + o));
                    (xs[o], ys[o], zs[o]) = (d.x, d.y, d.z);
                }
            });
        Ok(())
    }

    /// The WGSL path: one dispatch writing the host's three displacement
    /// buffers on the device (no trip through the CPU).
    fn map_gpu(&mut self, id: BindingId, out: [BufferId; 3]) -> Result<(), ModelError> {
        let gpu = self
            .gpu
            .clone()
            .ok_or_else(|| ModelError::new("map to GPU buffers, but the host gave no GPU"))?;
        let (u, n) = match self.binding(id)? {
            Binding::Lattice(g) => (self.uniforms().with_lattice(g), g.len()),
            Binding::List { points, .. } => (self.uniforms().with_list(), points.len()),
        };
        if n > u32::MAX as usize {
            return Err(ModelError(format!(
                "{n} points exceed the kernel's u32 point index; use backend = \"cpu\""
            )));
        }
        let uniforms = match self.uniforms {
            Some(b) => b,
            None => *self
                .uniforms
                .insert(gpu.create_buffer(UNIFORM_BYTES as u64, "template uniforms")?),
        };
        let dummy = match self.dummy {
            Some(b) => b,
            None => *self.dummy.insert(gpu.create_buffer(4, "template dummy")?),
        };
        let list = match &mut self.bindings[id.0 as usize] {
            Binding::Lattice(_) => None,
            Binding::List { points, gpu: slot } => Some(match slot {
                Some(ids) => *ids,
                None => {
                    let column = |a: usize| points.iter().map(|p| p[a]).collect::<Vec<f32>>();
                    *slot.insert([
                        gpu.upload(&column(0), "template points x")?,
                        gpu.upload(&column(1), "template points y")?,
                        gpu.upload(&column(2), "template points z")?,
                    ])
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

/// Device buffers are the host's: give them back when the model goes.
impl Drop for TemplateField {
    fn drop(&mut self) {
        let Some(gpu) = &self.gpu else { return };
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

impl DeformationModel for TemplateField {
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
        // Checks that need the volume belong here (those that do not were
        // made in `create`): a ball entirely outside the volume moves
        // nothing, which is almost certainly a mistake in the scene.
        self.centre = self
            .params
            .centre
            .map_or(volume.grid.centre(), DVec3::from_array);
        let (lo, hi) = volume.grid.world_bounds();
        let nearest = self.centre.clamp(lo, hi);
        if nearest.distance(self.centre) >= self.params.radius_mm {
            return Err(ModelError(format!(
                "[model.params] centre = {:?} with radius_mm = {}: the ball lies outside the \
                 volume ({:?} … {:?} mm), so nothing would move; move `centre` or raise \
                 `radius_mm`",
                self.centre.to_array(),
                self.params.radius_mm,
                lo.to_array(),
                hi.to_array()
            )));
        }
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
        // Parse with the shared vocabulary, so a typo in a scene's
        // [[interaction]] is refused (also by `voxflex validate`, which
        // calls this before `init`). A field has nothing to grab, so a
        // valid interaction is ignored, loudly. A simulated model applies
        // it here instead (see the chainmail and mesh-model plugins).
        let spec = InteractionSpec::from_toml(interaction_toml)?;
        tracing::warn!(
            kind = spec.kind(),
            "this field takes no interactions; ignored (animate it with `ramp_frames`)"
        );
        Ok(())
    }

    fn step(&mut self, frame: FrameInfo) -> Result<StepOutcome, ModelError> {
        let amount = ((frame.frame + 1) as f64 / self.params.ramp_frames as f64).min(1.0);
        // Say "changed" only when the field moved: an unchanged field makes
        // the host skip map, resample and output for this frame.
        let changed = amount != self.amount;
        self.amount = amount;
        Ok(StepOutcome { changed })
    }

    fn dirty_region(&self) -> DirtyRegion {
        if self.amount == self.mapped_amount {
            return DirtyRegion::None;
        }
        // Only rest points inside the ball move: the resampler re-fills
        // only this box (rest mm).
        let r = DVec3::splat(self.params.radius_mm);
        DirtyRegion::Box {
            min: self.centre - r,
            max: self.centre + r,
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

#[cfg(test)]
mod tests {
    use super::*;
    use voxflex_core::volume::VoxelSlice;

    fn field(params: &str, grid: Grid) -> TemplateField {
        let mut f = TemplateField::new(TemplateParams::from_toml(params).unwrap(), None);
        let data = vec![0u8; grid.len()];
        let view = VolumeView {
            grid,
            data: VoxelSlice::U8(&data),
        };
        f.init(view, ExecutionBackend::Cpu).unwrap();
        f
    }

    fn frame(frame: u64) -> FrameInfo {
        FrameInfo {
            frame,
            frames: 10,
            dt_s: 0.1,
        }
    }

    fn map(f: &mut TemplateField, b: BindingId, n: usize) -> [Vec<f32>; 3] {
        let mut d = [vec![0f32; n], vec![0f32; n], vec![0f32; n]];
        let [x, y, z] = &mut d;
        f.map(b, DisplacementTarget::Cpu { x, y, z }).unwrap();
        d
    }

    #[test]
    fn ramps_in_then_stays_still_with_a_dirty_box_around_the_ball() {
        let grid = Grid::centred([12, 10, 8], DVec3::new(1.0, 1.5, 2.0));
        let mut f = field("radius_mm = 5\namplitude_mm = 3\nramp_frames = 3", grid);
        let b = f.bind(RestPoints::Lattice(grid)).unwrap();
        let mut changes = vec![];
        for n in 0..5 {
            let s = f.step(frame(n)).unwrap();
            changes.push(s.changed);
            if s.changed {
                let c = grid.centre();
                assert_eq!(
                    f.dirty_region(),
                    DirtyRegion::Box {
                        min: c - DVec3::splat(5.0),
                        max: c + DVec3::splat(5.0)
                    }
                );
                map(&mut f, b, grid.len());
                assert_eq!(f.dirty_region(), DirtyRegion::None);
            }
        }
        assert_eq!(changes, [true, true, true, false, false]);
    }

    #[test]
    fn lattice_and_list_bindings_agree_and_only_the_ball_moves() {
        let grid = Grid::centred([11, 9, 7], DVec3::new(1.0, 1.25, 2.0));
        let mut f = field("radius_mm = 6\namplitude_mm = 4", grid);
        let pts: Vec<[f32; 3]> = (0..grid.len())
            .map(|n| RestPoints::Lattice(grid).point(n).as_vec3().to_array())
            .collect();
        let a = f.bind(RestPoints::Lattice(grid)).unwrap();
        let b = f.bind(RestPoints::Points(&pts)).unwrap();
        f.step(frame(0)).unwrap();
        let (da, db) = (map(&mut f, a, grid.len()), map(&mut f, b, grid.len()));
        for axis in 0..3 {
            for (p, q) in da[axis].iter().zip(&db[axis]) {
                assert!((p - q).abs() < 1e-5, "{p} vs {q}");
            }
        }
        let mut moved = 0;
        for (n, p) in pts.iter().enumerate() {
            let r = (Vec3::from_array(*p) - grid.centre().as_vec3()).length();
            let d = Vec3::new(da[0][n], da[1][n], da[2][n]).length();
            if r >= 6.0 {
                assert_eq!(d, 0.0, "point {n} at {r} mm moved");
            } else if d > 0.0 {
                moved += 1;
            }
        }
        assert!(moved > 10, "only {moved} points moved");
    }

    #[test]
    fn a_ball_outside_the_volume_and_a_gpu_without_gpu_are_refused() {
        let grid = Grid::centred([8, 8, 8], DVec3::ONE);
        let data = vec![0u8; grid.len()];
        let view = VolumeView {
            grid,
            data: VoxelSlice::U8(&data),
        };
        let params = "centre = [100, 0, 0]\nradius_mm = 5\namplitude_mm = 1";
        let mut f = TemplateField::new(TemplateParams::from_toml(params).unwrap(), None);
        let e = f.init(view, ExecutionBackend::Cpu).unwrap_err().0;
        assert!(e.contains("centre") && e.contains("radius_mm"), "{e}");
        let params = "radius_mm = 5\namplitude_mm = 1";
        let mut f = TemplateField::new(TemplateParams::from_toml(params).unwrap(), None);
        let e = f.init(view, ExecutionBackend::Gpu).unwrap_err().0;
        assert!(e.contains("no GPU"), "{e}");
    }

    #[test]
    fn interactions_are_validated_then_ignored() {
        let grid = Grid::centred([8, 8, 8], DVec3::ONE);
        let mut f = field("radius_mm = 3\namplitude_mm = 1", grid);
        f.interact("kind = \"release\"").unwrap();
        let e = f.interact("kind = \"grab\"\npoint = [0, 0, 0]\nbyy = [1, 0, 0]");
        assert!(e.unwrap_err().0.contains("byy"));
    }

    #[test]
    fn map_rejects_wrong_lengths_and_unknown_bindings() {
        let grid = Grid::centred([5, 5, 5], DVec3::ONE);
        let mut f = field("radius_mm = 3\namplitude_mm = 1", grid);
        let b = f.bind(RestPoints::Lattice(grid)).unwrap();
        let (mut x, mut y, mut z) = (vec![0.0; 3], vec![0.0; 3], vec![0.0; 3]);
        for id in [b, BindingId(7)] {
            let out = DisplacementTarget::Cpu {
                x: &mut x,
                y: &mut y,
                z: &mut z,
            };
            assert!(f.map(id, out).is_err());
        }
    }
}
