//! The WGSL path of the explicit integrator: the springs, the node →
//! spring incidence and the node state mirrored in GPU buffers, and the two
//! kernels of `shaders/mass-spring/springs.wgsl` (the twins of
//! [`crate::kernel::SpringKernel::spring_pass`] and `integrate`) dispatched
//! once each per sub-step, plus `tet_forces` (the volume springs) when
//! `volume_stiffness` is above 0. The state goes up at the start of a frame and
//! comes back at its end (24 B per node each way), so interactions, the
//! change test and the `.vtu` export work on the CPU copy as on the rayon
//! path; a frame's sub-steps never leave the device except for their
//! 32-byte parameter block.

use crate::kernel::SpringKernel;
use std::sync::Arc;
use voxflex_core::error::ModelError;
use voxflex_core::glam::DVec3;
use voxflex_core::gpu::{BufferBinding, BufferId, GpuService, GpuServiceExt, PipelineId};
use voxflex_mesh::mesh_model::boundary::TieTables;
use voxflex_mesh::mesh_model::{Boundary, NodeState};

/// The kernels.
pub const SPRINGS_WGSL: &str = include_str!("../../../shaders/mass-spring/springs.wgsl");

/// Threads per workgroup of every kernel (`WG` in `springs.wgsl`).
const WORKGROUP: u32 = 64;
/// 32-bit words of the kernels' `Params`.
const PARAM_WORDS: usize = 8;

/// Binding numbers of `springs.wgsl`'s variables (named as there; `PARAMS` is `p`).
mod bind {
    pub const PARAMS: u32 = 0;
    pub const SPRINGS: u32 = 1;
    pub const ENDS: u32 = 2;
    pub const KC: u32 = 3;
    pub const FORCE: u32 = 4;
    pub const START: u32 = 5;
    pub const INCIDENT: u32 = 6;
    pub const U: u32 = 7;
    pub const V: u32 = 8;
    pub const NODE: u32 = 9;
    pub const DRIVE: u32 = 10;
    pub const FNODE: u32 = 11;
    pub const TIE_START: u32 = 12;
    pub const TIE_LIST: u32 = 13;
    pub const UNTIE_START: u32 = 14;
    pub const UNTIE_LIST: u32 = 15;
    pub const TETS: u32 = 16;
    pub const TET_GEOM: u32 = 17;
}

fn gpu_err(e: impl std::fmt::Display) -> ModelError {
    ModelError(format!("mass-spring (GPU): {e}"))
}

/// The model's buffers on the device.
pub struct GpuSprings {
    gpu: Arc<dyn GpuService>,
    springs: usize,
    nodes: usize,
    params: BufferId,
    table: BufferId,
    ends: BufferId,
    kc: BufferId,
    force: BufferId,
    start: BufferId,
    incident: BufferId,
    u: BufferId,
    v: BufferId,
    node: BufferId,
    drive: BufferId,
    spring_forces: PipelineId,
    tet_forces: PipelineId,
    /// Volume springs: count, corners, rest edges.
    tets: usize,
    tet_corners: BufferId,
    tet_geom: BufferId,
    integrate: PipelineId,
    node_forces: PipelineId,
    integrate_tied: PipelineId,
    tie_state: PipelineId,
    /// Total force per node, for meshes with hanging nodes.
    fnode: BufferId,
}

impl GpuSprings {
    /// Uploads the kernel's springs and incidence; refuses meshes whose
    /// arrays exceed one storage binding.
    pub fn new(
        gpu: Arc<dyn GpuService>,
        kernel: &SpringKernel,
        nodes: usize,
    ) -> Result<Self, ModelError> {
        let limit = gpu.limits().max_storage_buffer_binding_size;
        let springs = kernel.springs();
        let tets = kernel.tets();
        if 16 * (springs + 4 * tets).max(2 * nodes).max(3 * tets) as u64 > limit {
            return Err(gpu_err(format!(
                "{springs} springs and {nodes} nodes exceed this device's storage binding of {limit} \
                 bytes; use a coarser proxy or backend = \"cpu\""
            )));
        }
        let table = kernel.spring_table();
        let (start, incident) = kernel.incidence();
        let (mut corners, mut geometry) = kernel.tet_table();
        // Buffers of at least one element (none are bound empty).
        corners.resize(tets.max(1), [0; 4]);
        geometry.resize(3 * tets.max(1), [0.0; 4]);
        let g = &*gpu;
        let buffers = (|| {
            Ok::<_, voxflex_core::error::GpuError>((
                g.create_buffer(4 * PARAM_WORDS as u64, "mass-spring params")?,
                g.upload(&table.geometry, "mass-spring springs")?,
                g.upload(&table.ends, "mass-spring ends")?,
                g.upload(&table.kc, "mass-spring stiffness and damping")?,
                g.create_buffer(
                    16 * (springs + 4 * tets).max(1) as u64,
                    "mass-spring forces",
                )?,
                g.upload(&start, "mass-spring incidence start")?,
                g.upload(&incident, "mass-spring incidence")?,
                [
                    g.create_buffer(16 * nodes as u64, "mass-spring u")?,
                    g.create_buffer(16 * nodes as u64, "mass-spring v")?,
                    g.create_buffer(16 * nodes as u64, "mass-spring node forces and masses")?,
                    g.create_buffer(32 * nodes as u64, "mass-spring drives")?,
                ],
            ))
        })()
        .map_err(gpu_err)?;
        let (params, table, ends, kc, force, start, incident, [u, v, node, drive]) = buffers;
        Ok(Self {
            spring_forces: gpu
                .compile(SPRINGS_WGSL, "spring_forces")
                .map_err(gpu_err)?,
            integrate: gpu.compile(SPRINGS_WGSL, "integrate").map_err(gpu_err)?,
            tet_forces: gpu.compile(SPRINGS_WGSL, "tet_forces").map_err(gpu_err)?,
            tets,
            tet_corners: gpu
                .upload(&corners, "mass-spring volume springs")
                .map_err(gpu_err)?,
            tet_geom: gpu
                .upload(&geometry, "mass-spring volume-spring rest edges")
                .map_err(gpu_err)?,
            node_forces: gpu.compile(SPRINGS_WGSL, "node_forces").map_err(gpu_err)?,
            integrate_tied: gpu
                .compile(SPRINGS_WGSL, "integrate_tied")
                .map_err(gpu_err)?,
            tie_state: gpu.compile(SPRINGS_WGSL, "tie_state").map_err(gpu_err)?,
            fnode: gpu
                .create_buffer(16 * nodes.max(1) as u64, "mass-spring node forces")
                .map_err(gpu_err)?,
            gpu,
            springs,
            nodes,
            params,
            table,
            ends,
            kc,
            force,
            start,
            incident,
            u,
            v,
            node,
            drive,
        })
    }

    /// One frame of `substeps` explicit sub-steps of `h` seconds, as
    /// `MassSpring::step_explicit` takes them on the CPU.
    #[allow(clippy::too_many_arguments)]
    pub fn frame(
        &self,
        substeps: u32,
        h: f64,
        alpha: f64,
        masses: &[f64],
        bc: &Boundary,
        state: &mut NodeState,
    ) -> Result<(), ModelError> {
        let g = &*self.gpu;
        let vec4 = |v: &[DVec3]| -> Vec<[f32; 4]> {
            v.iter()
                .map(|p| [p.x as f32, p.y as f32, p.z as f32, 0.0])
                .collect()
        };
        let node: Vec<[f32; 4]> = bc
            .force
            .iter()
            .zip(masses)
            .map(|(f, &m)| [f.x as f32, f.y as f32, f.z as f32, m as f32])
            .collect();
        let mut drive = vec![[0f32; 4]; 2 * self.nodes];
        for (n, &fixed) in bc.fixed.iter().enumerate() {
            if fixed {
                drive[2 * n][3] = 1.0;
            }
        }
        for h in &bc.hanging {
            drive[2 * h.node as usize][3] = 3.0;
        }
        for &(n, target) in &bc.driven {
            let (n, u) = (n as usize, state.u[n as usize]);
            drive[2 * n] = [u.x as f32, u.y as f32, u.z as f32, 2.0];
            drive[2 * n + 1] = [target.x as f32, target.y as f32, target.z as f32, 0.0];
        }
        let write =
            |id: BufferId, data: &[[f32; 4]]| g.write_buffer(id, 0, bytemuck::cast_slice(data));
        write(self.u, &vec4(&state.u)).map_err(gpu_err)?;
        write(self.v, &vec4(&state.v)).map_err(gpu_err)?;
        write(self.node, &node).map_err(gpu_err)?;
        write(self.drive, &drive).map_err(gpu_err)?;
        let whole = |i: u32, id: BufferId| BufferBinding::whole(i, id);
        // Each pipeline's layout holds only the bindings its entry point uses.
        let spring_bindings = [
            whole(bind::PARAMS, self.params),
            whole(bind::SPRINGS, self.table),
            whole(bind::ENDS, self.ends),
            whole(bind::KC, self.kc),
            whole(bind::FORCE, self.force),
            whole(bind::U, self.u),
            whole(bind::V, self.v),
        ];
        let tet_bindings = [
            whole(bind::PARAMS, self.params),
            whole(bind::FORCE, self.force),
            whole(bind::U, self.u),
            whole(bind::TETS, self.tet_corners),
            whole(bind::TET_GEOM, self.tet_geom),
        ];
        let tet_groups = g
            .workgroups_for(self.tets as u64, WORKGROUP)
            .map_err(gpu_err)?;
        let node_bindings = [
            whole(bind::PARAMS, self.params),
            whole(bind::FORCE, self.force),
            whole(bind::START, self.start),
            whole(bind::INCIDENT, self.incident),
            whole(bind::U, self.u),
            whole(bind::V, self.v),
            whole(bind::NODE, self.node),
            whole(bind::DRIVE, self.drive),
        ];
        let ties = if bc.hanging.is_empty() {
            None
        } else {
            let t = TieTables::new(&bc.hanging, self.nodes);
            Some(
                [
                    g.upload(&t.tie_start, "mass-spring tie starts"),
                    g.upload(&t.tie_list, "mass-spring ties"),
                    g.upload(&t.untie_start, "mass-spring untie starts"),
                    g.upload(&t.untie_list, "mass-spring unties"),
                ]
                .map(|r| r.map_err(gpu_err)),
            )
        };
        let ties = match ties {
            Some([a, b, c, d]) => Some([a?, b?, c?, d?]),
            None => None,
        };
        let spring_groups = g
            .workgroups_for(self.springs as u64, WORKGROUP)
            .map_err(gpu_err)?;
        let node_groups = g
            .workgroups_for(self.nodes as u64, WORKGROUP)
            .map_err(gpu_err)?;
        for s in 1..=substeps {
            let frac = s as f32 / substeps as f32;
            let params: [u32; PARAM_WORDS] = [
                self.springs as u32,
                self.nodes as u32,
                (h as f32).to_bits(),
                (alpha as f32).to_bits(),
                frac.to_bits(),
                self.tets as u32,
                0,
                0,
            ];
            g.write_buffer(self.params, 0, bytemuck::cast_slice(&params))
                .map_err(gpu_err)?;
            g.dispatch(self.spring_forces, &spring_bindings, spring_groups)
                .map_err(gpu_err)?;
            if self.tets > 0 {
                g.dispatch(self.tet_forces, &tet_bindings, tet_groups)
                    .map_err(gpu_err)?;
            }
            match ties {
                None => g
                    .dispatch(self.integrate, &node_bindings, node_groups)
                    .map_err(gpu_err)?,
                Some([ts, tl, us, ul]) => {
                    let forces = [
                        whole(bind::PARAMS, self.params),
                        whole(bind::FORCE, self.force),
                        whole(bind::START, self.start),
                        whole(bind::INCIDENT, self.incident),
                        whole(bind::V, self.v),
                        whole(bind::NODE, self.node),
                        whole(bind::FNODE, self.fnode),
                    ];
                    let tied = [
                        whole(bind::PARAMS, self.params),
                        whole(bind::U, self.u),
                        whole(bind::V, self.v),
                        whole(bind::NODE, self.node),
                        whole(bind::DRIVE, self.drive),
                        whole(bind::FNODE, self.fnode),
                        whole(bind::UNTIE_START, us),
                        whole(bind::UNTIE_LIST, ul),
                    ];
                    let tie = [
                        whole(bind::PARAMS, self.params),
                        whole(bind::U, self.u),
                        whole(bind::V, self.v),
                        whole(bind::DRIVE, self.drive),
                        whole(bind::TIE_START, ts),
                        whole(bind::TIE_LIST, tl),
                    ];
                    for (pipeline, b) in [
                        (self.node_forces, &forces[..]),
                        (self.integrate_tied, &tied[..]),
                        (self.tie_state, &tie[..]),
                    ] {
                        g.dispatch(pipeline, b, node_groups).map_err(gpu_err)?;
                    }
                }
            }
        }
        if let Some(buffers) = ties {
            for id in buffers {
                g.destroy_buffer(id);
            }
        }
        let mut out = vec![[0f32; 4]; self.nodes];
        let read =
            |id: BufferId, out: &mut [[f32; 4]], dst: &mut [DVec3]| -> Result<(), ModelError> {
                g.download(id, out).map_err(gpu_err)?;
                for (d, s) in dst.iter_mut().zip(out.iter()) {
                    *d = DVec3::new(s[0] as f64, s[1] as f64, s[2] as f64);
                }
                Ok(())
            };
        read(self.u, &mut out, &mut state.u)?;
        read(self.v, &mut out, &mut state.v)?;
        Ok(())
    }
}

impl Drop for GpuSprings {
    fn drop(&mut self) {
        for id in [
            self.params,
            self.table,
            self.ends,
            self.kc,
            self.force,
            self.start,
            self.incident,
            self.u,
            self.v,
            self.node,
            self.drive,
            self.fnode,
            self.tet_corners,
            self.tet_geom,
        ] {
            self.gpu.destroy_buffer(id);
        }
    }
}

#[cfg(test)]
#[path = "shader_tests.rs"]
mod shader_tests;
