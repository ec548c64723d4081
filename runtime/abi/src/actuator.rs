//! Actuator plugins across the boundary: the plugin side
//! ([`ActuatorPlugin`], [`crate::export_actuator_plugin!`]) and the host
//! side ([`ActuatorProxy`]), mirroring `voxflex_core::actuator::ActuatorModel`.

use crate::ffi::*;
use crate::guard::guard;
use crate::host_side::{
    HostServices, checked_call, create_proxy_instance, plugin_error, read_notes,
};
use crate::plugin::{
    HostContext, create_instance, destroy_instance, state, vectors_in, vectors_out,
};
use std::sync::Arc;
use voxflex_core::actuator::{
    ActuatorCommand, ActuatorGeometry, ActuatorLinearisation, ActuatorModel,
};
use voxflex_core::deformation::{FrameInfo, ModelNotes};
use voxflex_core::error::ModelError;
use voxflex_core::glam::DVec3;

/// An actuator model that can be exported as a plugin.
pub trait ActuatorPlugin:
    ActuatorModel + crate::params_schema::DeclaresParams + Sized + 'static
{
    /// Name scenes use (`[[actuator]] plugin = "..."`).
    const NAME: &'static str;
    /// One-line description for `voxflex plugins`.
    const DESCRIPTION: &'static str;
    /// [`CAPABILITY_CPU`] | [`CAPABILITY_GPU`].
    const CAPABILITIES: u32;
    /// Creates an instance from the TOML text of the scene's
    /// `[actuator.params]` table. Errors must name the offending key.
    fn create(params_toml: &str, host: HostContext) -> Result<Self, ModelError>;
}

unsafe extern "C" fn create<P: ActuatorPlugin>(
    params: StrRef,
    host: *const HostApi,
    out: *mut Instance,
    err: *mut ErrorBuf,
) -> i32 {
    create_instance(params, host, out, err, P::create)
}

unsafe extern "C" fn destroy<P: ActuatorPlugin>(instance: Instance) {
    // SAFETY: host contract.
    unsafe { destroy_instance::<P>(instance) }
}

unsafe extern "C" fn init<P: ActuatorPlugin>(
    instance: Instance,
    geometry: *const ActuatorGeometryDesc,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        if geometry.is_null() {
            return Err("null geometry".into());
        }
        // SAFETY: checked non-null; host contract.
        let g = unsafe { &*geometry };
        // SAFETY: host contract: `len` points.
        let points = unsafe { vectors_in(g.points, g.len) }?;
        let triangles: &[[u32; 3]] = if g.triangle_count == 0 {
            &[]
        } else if g.triangles.is_null() {
            return Err("null triangle array".into());
        } else {
            // SAFETY: host contract: `triangle_count` triangles.
            unsafe { std::slice::from_raw_parts(g.triangles, g.triangle_count as usize) }
        };
        s.model
            .init(ActuatorGeometry {
                points: &points,
                triangles,
                gravity_m_s2: DVec3::from_array(g.gravity_m_s2),
            })
            .map_err(|e| e.to_string())
    })
}

unsafe extern "C" fn command<P: ActuatorPlugin>(
    instance: Instance,
    frame: *const FrameDesc,
    out: *mut ActuatorCommandDesc,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        if frame.is_null() || out.is_null() {
            return Err("null frame or output".into());
        }
        // SAFETY: checked non-null.
        let f = unsafe { *frame };
        let c = s
            .model
            .command(FrameInfo {
                frame: f.frame,
                frames: f.frames,
                dt_s: f.dt_s,
            })
            .map_err(|e| e.to_string())?;
        // SAFETY: checked non-null.
        unsafe { *out = c.into() };
        Ok(())
    })
}

#[allow(clippy::too_many_arguments)]
unsafe extern "C" fn linearise<P: ActuatorPlugin>(
    instance: Instance,
    positions: *const [f64; 3],
    len: u64,
    directions: *mut [f64; 3],
    loads: *mut [f64; 3],
    load_growth: *mut [f64; 3],
    out: *mut ActuatorScalarsDesc,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        if out.is_null() {
            return Err("null output".into());
        }
        // SAFETY: host contract: `len` positions.
        let x = unsafe { vectors_in(positions, len) }?;
        let l = crate::plugin::on_worker(|| s.model.linearise(&x)).map_err(|e| e.to_string())?;
        l.check(x.len(), P::NAME).map_err(|e| e.to_string())?;
        // SAFETY: host contract: three arrays of `len` entries.
        unsafe {
            vectors_out(&l.directions, directions, len)?;
            if !l.loads.is_empty() {
                vectors_out(&l.loads, loads, len)?;
            }
            if !l.load_growth.is_empty() {
                vectors_out(&l.load_growth, load_growth, len)?;
            }
            *out = ActuatorScalarsDesc {
                measure: l.measure,
                effort_bounds: l.effort_bounds,
                measure_bounds: l.measure_bounds,
                has_loads: u32::from(!l.loads.is_empty()),
                has_load_growth: u32::from(!l.load_growth.is_empty()),
            };
        }
        Ok(())
    })
}

unsafe extern "C" fn notes<P: ActuatorPlugin>(
    instance: Instance,
    out: *mut ErrorBuf,
    err: *mut ErrorBuf,
) -> i32 {
    guard(err, || {
        // SAFETY: host contract.
        let s = unsafe { state::<P>(instance) }?;
        let notes = s.model.notes().map_err(|e| e.to_string())?;
        let text = crate::notes_text::encode(&notes)?;
        // SAFETY: host contract: `out` is the host's buffer of `cap` bytes.
        unsafe { ErrorBuf::write_whole(out, &text, "the actuator's notes") }
    })
}

impl From<ActuatorCommand> for ActuatorCommandDesc {
    fn from(c: ActuatorCommand) -> Self {
        let (tag, value) = match c {
            ActuatorCommand::Free => (COMMAND_FREE, 0.0),
            ActuatorCommand::Effort(v) => (COMMAND_EFFORT, v),
            ActuatorCommand::Measure(v) => (COMMAND_MEASURE, v),
        };
        Self {
            tag,
            reserved: 0,
            value,
        }
    }
}

impl TryFrom<ActuatorCommandDesc> for ActuatorCommand {
    type Error = String;
    fn try_from(d: ActuatorCommandDesc) -> Result<Self, String> {
        match d.tag {
            COMMAND_FREE => Ok(Self::Free),
            COMMAND_EFFORT => Ok(Self::Effort(d.value)),
            COMMAND_MEASURE => Ok(Self::Measure(d.value)),
            t => Err(format!("unknown command tag {t}")),
        }
    }
}

/// The vtable of actuator type `P` (used by [`crate::export_actuator_plugin!`]).
pub const fn actuator_vtable<P: ActuatorPlugin>() -> ActuatorVTable {
    ActuatorVTable {
        create: create::<P>,
        destroy: destroy::<P>,
        init: init::<P>,
        command: command::<P>,
        linearise: linearise::<P>,
        notes: notes::<P>,
    }
}

/// Exports an [`ActuatorPlugin`] as this library's `voxflex_plugin_v1`
/// entry point.
#[macro_export]
macro_rules! export_actuator_plugin {
    ($ty:ty) => {
        static __VOXFLEX_VTABLE: $crate::ffi::ActuatorVTable =
            $crate::actuator::actuator_vtable::<$ty>();
        static __VOXFLEX_DECLARATION: $crate::ffi::PluginDeclaration =
            $crate::ffi::PluginDeclaration {
                name: $crate::ffi::StrRef::from_static(
                    <$ty as $crate::actuator::ActuatorPlugin>::NAME,
                ),
                version: $crate::ffi::StrRef::from_static(env!("CARGO_PKG_VERSION")),
                description: $crate::ffi::StrRef::from_static(
                    <$ty as $crate::actuator::ActuatorPlugin>::DESCRIPTION,
                ),
                kind: $crate::ffi::PluginKind::Actuator as u32,
                capabilities: <$ty as $crate::actuator::ActuatorPlugin>::CAPABILITIES,
                deformation: ::std::ptr::null(),
                renderer: ::std::ptr::null(),
                actuator: &__VOXFLEX_VTABLE,
                params_schema: $crate::params_schema::entry::<$ty>,
            };
        $crate::__export_header!(__VOXFLEX_DECLARATION);
    };
}

/// An actuator plugin instance seen as an [`ActuatorModel`].
pub struct ActuatorProxy {
    name: String,
    vtable: &'static ActuatorVTable,
    instance: Instance,
    /// Points given to `init` (the length every later array must have).
    points: usize,
    _services: Arc<HostServices>,
}

// SAFETY: used through &mut self only, one thread at a time.
unsafe impl Send for ActuatorProxy {}

impl ActuatorProxy {
    /// Creates an instance of an actuator plugin from its vtable.
    ///
    /// # Safety
    /// `vtable` must be a valid actuator vtable from a library never unloaded.
    pub unsafe fn create(
        name: &str,
        vtable: &'static ActuatorVTable,
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
            points: 0,
            _services: services,
        })
    }

    /// The plugin's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    fn call(&self, f: impl FnOnce(*mut ErrorBuf) -> i32) -> Result<(), ModelError> {
        checked_call(&self.name, f)
    }
}

impl Drop for ActuatorProxy {
    fn drop(&mut self) {
        // SAFETY: made by this vtable's create, destroyed once.
        unsafe { (self.vtable.destroy)(self.instance) }
    }
}

impl ActuatorModel for ActuatorProxy {
    fn init(&mut self, geometry: ActuatorGeometry<'_>) -> Result<(), ModelError> {
        let points: Vec<[f64; 3]> = geometry.points.iter().map(|p| p.to_array()).collect();
        let desc = ActuatorGeometryDesc {
            points: points.as_ptr(),
            len: points.len() as u64,
            triangles: geometry.triangles.as_ptr(),
            triangle_count: geometry.triangles.len() as u64,
            gravity_m_s2: geometry.gravity_m_s2.to_array(),
        };
        let (vt, inst) = (self.vtable, self.instance);
        // SAFETY: the arrays are alive during the call.
        self.call(|err| unsafe { (vt.init)(inst, &desc, err) })?;
        self.points = points.len();
        Ok(())
    }

    fn command(&mut self, frame: FrameInfo) -> Result<ActuatorCommand, ModelError> {
        let desc = FrameDesc {
            frame: frame.frame,
            frames: frame.frames,
            dt_s: frame.dt_s,
        };
        let mut out = ActuatorCommandDesc::default();
        let (vt, inst) = (self.vtable, self.instance);
        // SAFETY: plain values alive during the call.
        self.call(|err| unsafe { (vt.command)(inst, &desc, &mut out, err) })?;
        ActuatorCommand::try_from(out).map_err(|m| plugin_error(&self.name, &m))
    }

    fn linearise(&mut self, positions: &[DVec3]) -> Result<ActuatorLinearisation, ModelError> {
        if positions.len() != self.points {
            return Err(plugin_error(
                &self.name,
                &format!(
                    "linearise: {} positions for {} points",
                    positions.len(),
                    self.points
                ),
            ));
        }
        let x: Vec<[f64; 3]> = positions.iter().map(|p| p.to_array()).collect();
        let n = x.len();
        let (mut d, mut l, mut g) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
        let mut s = ActuatorScalarsDesc::default();
        let (vt, inst) = (self.vtable, self.instance);
        // SAFETY: every array is `n` long and alive during the call.
        self.call(|err| unsafe {
            (vt.linearise)(
                inst,
                x.as_ptr(),
                n as u64,
                d.as_mut_ptr(),
                l.as_mut_ptr(),
                g.as_mut_ptr(),
                &mut s,
                err,
            )
        })?;
        let vectors = |a: Vec<[f64; 3]>, has: bool| -> Vec<DVec3> {
            if has {
                a.into_iter().map(DVec3::from_array).collect()
            } else {
                Vec::new()
            }
        };
        let out = ActuatorLinearisation {
            directions: vectors(d, true),
            measure: s.measure,
            loads: vectors(l, s.has_loads != 0),
            load_growth: vectors(g, s.has_load_growth != 0),
            effort_bounds: s.effort_bounds,
            measure_bounds: s.measure_bounds,
        };
        out.check(n, &format!("plugin `{}`", self.name))?;
        Ok(out)
    }

    fn notes(&mut self) -> Result<ModelNotes, ModelError> {
        let (vt, inst) = (self.vtable, self.instance);
        // SAFETY: `read_notes` passes buffers alive during the call.
        read_notes(&self.name, |out, err| unsafe { (vt.notes)(inst, out, err) })
    }
}
