//! The cavity as an [`ActuatorModel`]: its measure is the enclosed volume's
//! growth from rest, `m = V(x) − V₀`, whose gradient `∂V/∂xᵢ = Σ_t S_t n_t
//! / 3` (the area-weighted normals of the triangles around vertex `i`) is
//! the force a unit pressure puts on vertex `i` — SoftRobots'
//! SurfacePressureConstraint. A hydraulic cavity also carries its fluid's
//! weight ([`crate::fluid_load`]).

use crate::fluid_load::{FluidLoad, Loads, Weigher};
use crate::params::{CavityParams, Fluid};
use std::sync::Arc;
use voxflex_core::actuator::{
    ActuatorCommand, ActuatorGeometry, ActuatorLinearisation, ActuatorModel,
};
use voxflex_core::deformation::{FrameInfo, ModelNotes};
use voxflex_core::error::ModelError;
use voxflex_core::glam::DVec3;
use voxflex_core::gpu::GpuService;
use voxflex_core::triangle_surface::TriangleSurface;

/// What `init` learnt about the cavity at rest.
#[derive(Debug)]
struct Rest {
    /// The surface; its vertices are overwritten with the current
    /// positions by every `linearise` (the triangles never change).
    surface: TriangleSurface,
    /// Enclosed volume at rest, mm³ (> 0).
    volume_mm3: f64,
    /// The fluid's weighing; `None` when the fluid has no weight (air,
    /// or zero gravity).
    fluid: Option<FluidLoad>,
}

/// A pneumatic or hydraulic cavity: the model of the `cavity` plugin.
pub struct Cavity {
    params: CavityParams,
    /// The host's GPU, offered when the scene's backend resolved to `gpu`:
    /// the fluid is then weighed there.
    gpu: Option<Arc<dyn GpuService>>,
    rest: Option<Rest>,
    /// `linearise` calls so far.
    linearisations: u64,
    /// The enclosed volume at the last `linearise`, mm³.
    last_volume_mm3: Option<f64>,
}

impl Cavity {
    /// A cavity with parsed parameters, weighing its fluid on the CPU;
    /// [`ActuatorModel::init`] gives it its surface.
    pub fn new(params: CavityParams) -> Self {
        Self::on(params, None)
    }

    /// [`Cavity::new`], weighing the fluid on `gpu` when one is given.
    pub fn on(params: CavityParams, gpu: Option<Arc<dyn GpuService>>) -> Self {
        Self {
            params,
            gpu,
            rest: None,
            linearisations: 0,
            last_volume_mm3: None,
        }
    }

    /// The parameters.
    pub fn params(&self) -> &CavityParams {
        &self.params
    }

    /// The enclosed volume at rest, mm³ (`None` before `init`).
    pub fn rest_volume_mm3(&self) -> Option<f64> {
        self.rest.as_ref().map(|r| r.volume_mm3)
    }

    /// The fluid's weighing for this gravity, `None` when it weighs nothing.
    fn fluid_load(&self, gravity_m_s2: DVec3) -> Result<Option<FluidLoad>, ModelError> {
        if !gravity_m_s2.is_finite() {
            return Err(ModelError(format!(
                "cavity: gravity {:?} m/s² is not finite; fix the scene's gravity",
                gravity_m_s2.to_array()
            )));
        }
        let weighing = self.params.weighing(gravity_m_s2);
        if weighing.is_none() && self.params.fluid == Fluid::Water {
            tracing::warn!(
                "cavity: fluid = \"water\" but the scene's gravity is zero: the fluid weighs \
                 nothing, so the cavity carries no loads"
            );
        }
        Ok(weighing.map(|w| FluidLoad::new(w, Weigher::on(self.gpu.clone()))))
    }

    fn rest_mut(&mut self) -> Result<&mut Rest, ModelError> {
        self.rest
            .as_mut()
            .ok_or_else(|| ModelError::new("cavity: linearise before init"))
    }
}

impl std::fmt::Debug for Cavity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Cavity")
            .field("params", &self.params)
            .field("gpu", &self.gpu.as_ref().map(|g| g.adapter_description()))
            .field("rest", &self.rest)
            .field("linearisations", &self.linearisations)
            .finish()
    }
}

/// The cavity's surface at rest, checked: triangles present and in range,
/// closed and consistently oriented, normals out (positive volume).
pub fn rest_surface(
    points: &[DVec3],
    triangles: &[[u32; 3]],
) -> Result<TriangleSurface, ModelError> {
    if triangles.is_empty() {
        return Err(ModelError::new(
            "cavity: no triangles: a cavity needs the closed triangle surface of its fluid",
        ));
    }
    let mesh_error = |e: voxflex_core::error::MeshError| ModelError(e.to_string());
    let surface =
        TriangleSurface::new("cavity", points.to_vec(), triangles.to_vec()).map_err(mesh_error)?;
    surface.check_closed("cavity").map_err(mesh_error)?;
    let volume = surface.signed_volume();
    if volume.is_nan() || volume <= 0.0 {
        return Err(ModelError(format!(
            "cavity: its surface encloses a signed volume of {volume} mm³ (≤ 0): the \
             normals point into the cavity: reverse the triangles' winding (or the surface \
             is flat)"
        )));
    }
    Ok(surface)
}

/// Refuses `positions` that are not one finite position per vertex.
fn check_positions(positions: &[DVec3], vertices: usize) -> Result<(), ModelError> {
    if positions.len() != vertices {
        return Err(ModelError(format!(
            "cavity: linearise got {} positions for {vertices} surface vertices",
            positions.len()
        )));
    }
    if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
        return Err(ModelError(format!(
            "cavity: vertex {i} is at {:?}, not a finite position (mm)",
            positions[i].to_array()
        )));
    }
    Ok(())
}

impl ActuatorModel for Cavity {
    fn init(&mut self, geometry: ActuatorGeometry<'_>) -> Result<(), ModelError> {
        let surface = rest_surface(geometry.points, geometry.triangles)?;
        let fluid = self.fluid_load(geometry.gravity_m_s2)?;
        let volume_mm3 = surface.signed_volume();
        tracing::debug!(
            vertices = surface.vertices.len(),
            triangles = surface.triangles.len(),
            volume_mm3,
            weighed = fluid.is_some(),
            "cavity initialised"
        );
        self.rest = Some(Rest {
            surface,
            volume_mm3,
            fluid,
        });
        self.linearisations = 0;
        self.last_volume_mm3 = None;
        Ok(())
    }

    fn command(&mut self, frame: FrameInfo) -> Result<ActuatorCommand, ModelError> {
        Ok(self.params.command(frame))
    }

    fn linearise(&mut self, positions: &[DVec3]) -> Result<ActuatorLinearisation, ModelError> {
        let (effort_bounds, measure_bounds) =
            (self.params.effort_bounds(), self.params.measure_bounds());
        let rest = self.rest_mut()?;
        check_positions(positions, rest.surface.vertices.len())?;
        rest.surface.vertices.copy_from_slice(positions);
        let volume = rest.surface.signed_volume();
        let Loads { loads, load_growth } = match &mut rest.fluid {
            Some(fluid) => fluid.weigh(&rest.surface)?,
            None => Loads::default(),
        };
        let out = ActuatorLinearisation {
            directions: rest.surface.area_weighted_normals(),
            measure: volume - rest.volume_mm3,
            loads,
            load_growth,
            effort_bounds,
            measure_bounds,
        };
        self.linearisations += 1;
        self.last_volume_mm3 = Some(volume);
        Ok(out)
    }

    fn notes(&mut self) -> Result<ModelNotes, ModelError> {
        let mut notes = ModelNotes::new();
        notes.insert("linearisations".into(), self.linearisations as f64);
        let Some(rest) = &self.rest else {
            return Ok(notes);
        };
        notes.insert("rest_volume_mm3".into(), rest.volume_mm3);
        if let Some(v) = self.last_volume_mm3 {
            notes.insert("volume_mm3".into(), v);
            notes.insert("volume_growth_mm3".into(), v - rest.volume_mm3);
        }
        add_fluid_notes(&mut notes, rest.fluid.as_ref());
        Ok(notes)
    }
}

/// The weighing's figures; zeros for a fluid that is not weighed (its
/// weight is neglected).
fn add_fluid_notes(notes: &mut ModelNotes, fluid: Option<&FluidLoad>) {
    let figures = fluid.map_or([0.0; 7], |f| {
        [
            f64::from(u8::from(f.on_gpu())),
            f.last_weight,
            f.last_fluid_volume,
            f.irregular_columns_max as f64,
            f.irregular_weighings as f64,
            f.weighings as f64,
            f.weighing_s,
        ]
    });
    let names = [
        "weighed_on_gpu",
        "fluid_weight_uN",
        "fluid_volume_mm3",
        "irregular_columns_max",
        "irregular_weighings",
        "weighings",
        "weighing_s",
    ];
    for (name, value) in names.into_iter().zip(figures) {
        notes.insert(name.into(), value);
    }
}

#[cfg(test)]
#[path = "model_tests.rs"]
mod tests;
