//! [`ChainMail`]: the lattice, the state, the interactions and the per-frame
//! schedule (interleaved propagation and relaxation).

use crate::blocks::{Blocks, FaceMask};
use crate::conflicts::{self, Conflicts, Violation};
use crate::gpu::GpuChainMail;
use crate::lattice::{ABSENT, ElementLattice, FIXED, HELD};
use crate::params::{Algorithm, ChainMailParams, InteractionSpec, Schedule};
use crate::propagate::{frontier_iteration, gibson, jacobi_iteration, next_frontier};
use crate::relax::sweep_scalar;
use crate::relax_passes::{SweepScratch, sweep_runs};
use crate::removal::{carve_tets, cut_tets};
use crate::run_log::RunLog;
use crate::state::{MAX_WAVE, State, key};

mod repair;
use rayon::prelude::*;
use std::sync::Arc;
use voxflex_core::cut_polygon::CutPolygon;
use voxflex_core::error::ModelError;
use voxflex_core::glam::DVec3;
use voxflex_core::gpu::{BufferId, GpuService};
use voxflex_core::interaction::{CarveRegion, FarGrabs, GrabMotion};
use voxflex_core::volume::VolumeView;
use voxflex_resample::{tets_at_vertex, tets_on_edge};

/// A grab in progress: an element moved along a straight path.
#[derive(Clone, Debug)]
struct Grab {
    element: usize,
    /// Rest position of the element, world mm.
    rest: DVec3,
    /// Where the element goes, world mm.
    motion: GrabMotion,
}

/// Counts since the model was built (or the last [`ChainMail::reset_counts`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Counts {
    /// Propagation iterations (parallel) or deformations (sequential).
    pub propagation_iterations: u64,
    /// Relaxation sweeps.
    pub relaxation_iterations: u64,
    /// Element evaluations in propagation.
    pub visits: u64,
    /// Element moves in propagation.
    pub updates: u64,
    /// Repair waves started ([`ChainMail::start_repair_wave`]).
    pub repair_waves: u64,
}

/// What [`ChainMail::settle`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SettleReport {
    /// Propagation iterations until no block was active.
    pub propagation_iterations: u64,
    /// Relaxation sweeps until no element moved by the tolerance.
    pub relaxation_iterations: u64,
    /// True when both stages converged within the caps.
    pub at_rest: bool,
}

/// What one frame ([`ChainMail::step`]) did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameStats {
    /// Wall time of the frame's model work, ms.
    pub ms: f64,
    /// Blocks visited by propagation, summed over the frame's iterations.
    pub propagation_blocks: u64,
    /// Blocks visited by relaxation, summed over the frame's sweeps.
    pub relaxation_blocks: u64,
    /// Relaxation sweeps run.
    pub sweeps: u64,
    /// Largest element move of the frame's last sweep, fraction of the
    /// element spacing.
    pub max_move: f64,
    /// The step reported a change (downstream re-maps).
    pub changed: bool,
}

/// A heterogeneous ChainMail model over a volume.
pub struct ChainMail {
    params: ChainMailParams,
    lat: ElementLattice,
    state: State,
    blocks: Blocks,
    /// Blocks the next propagation iteration visits (block schedule),
    /// ascending, no repeats (the passes' one-writer-per-row rule needs it).
    active: Vec<u32>,
    /// Elements the next propagation iteration visits (frontier schedule).
    frontier: Vec<u32>,
    /// Blocks the next relaxation sweep visits, ascending, no repeats.
    relax: Vec<u32>,
    /// Scratch flags for building block lists.
    seen: Vec<bool>,
    /// Buffers the relaxation sweeps reuse.
    sweep_scratch: SweepScratch,
    /// Storage for merging block lists.
    merge_scratch: Vec<u32>,
    /// Blocks changed since the last `take_dirty`.
    dirty: Vec<bool>,
    /// Blocks changed in the current copy only (by relaxation and the
    /// CPU's block propagation) since the two copies were last made equal,
    /// with their flags.
    unsynced: Vec<u32>,
    unsynced_flag: Vec<bool>,
    wave: u32,
    /// Repair waves this deformation may still start
    /// ([`Self::start_repair_wave`]).
    repairs_left: u32,
    /// Largest move of the last relaxation sweep, fraction of the spacing.
    last_max_move: f64,
    /// Link violations per block, for the conflict check.
    conflicts: Conflicts,
    /// Propagation ran (or a grab moved) since the last conflict check.
    propagated_since_check: bool,
    /// Frames so far, for the notes.
    log: RunLog,
    grabs: Vec<Grab>,
    /// Grabs whose point lay beyond one cell from every element.
    far_grabs: FarGrabs,
    counts: Counts,
    /// Sampling-mesh tetrahedra the cuts and carving removed (one byte per
    /// cell of the source volume's mesh, 5 bits); empty until the first.
    removed_tets: Vec<u8>,
    /// `removed_tets` gained bits since they were last reported.
    removed_unreported: bool,
    /// A cut or carve since the last step: the next step reports a change.
    topology_changed: bool,
    /// The WGSL path, when the model runs on the GPU.
    gpu: Option<GpuChainMail>,
    /// The GPU has iterated since the CPU copy of the state was last
    /// downloaded ([`Self::pull`]).
    cpu_stale: bool,
    /// The first GPU error; later GPU work is skipped until it is taken.
    gpu_error: Option<ModelError>,
}

impl ChainMail {
    /// Builds the model of a volume (all elements at rest).
    pub fn new(volume: VolumeView<'_>, params: ChainMailParams) -> Result<Self, ModelError> {
        let lat = ElementLattice::new(volume, &params)?;
        let blocks = Blocks::new(lat.dims, params.block);
        let n = lat.len();
        tracing::debug!(
            dims = ?lat.dims,
            elements = lat.element_count(),
            blocks = blocks.len(),
            "chainmail model built"
        );
        Ok(Self {
            state: State::new(n),
            seen: vec![false; blocks.len()],
            sweep_scratch: SweepScratch::default(),
            merge_scratch: Vec::new(),
            dirty: vec![false; blocks.len()],
            unsynced: Vec::new(),
            unsynced_flag: vec![false; blocks.len()],
            blocks,
            lat,
            params,
            active: Vec::new(),
            frontier: Vec::new(),
            relax: Vec::new(),
            wave: 0,
            repairs_left: 0,
            last_max_move: 0.0,
            conflicts: Conflicts::new(&blocks),
            propagated_since_check: false,
            log: RunLog::default(),
            grabs: Vec::new(),
            far_grabs: FarGrabs::default(),
            counts: Counts::default(),
            removed_tets: Vec::new(),
            removed_unreported: false,
            topology_changed: false,
            gpu: None,
            cpu_stale: false,
            gpu_error: None,
        })
    }

    /// Moves the model onto the GPU: from now on propagation and
    /// relaxation run the WGSL kernels on the device's copy of the state.
    /// Only the parallel algorithm with the block schedule has a GPU path.
    pub fn use_gpu(&mut self, service: Arc<dyn GpuService>) -> Result<(), ModelError> {
        if self.params.algorithm != Algorithm::Parallel {
            return Err(ModelError::new(
                "chainmail: algorithm = \"sequential\" (the baseline) runs on the CPU only; \
                 use backend = \"cpu\" or algorithm = \"parallel\"",
            ));
        }
        if self.params.schedule != Schedule::Blocks {
            return Err(ModelError::new(
                "chainmail: schedule = \"frontier\" runs on the CPU only; use backend = \"cpu\" \
                 or schedule = \"blocks\"",
            ));
        }
        self.sync_copies();
        self.gpu = Some(GpuChainMail::new(
            service,
            &self.lat,
            &self.state,
            &self.blocks,
        )?);
        Ok(())
    }

    /// True when the model runs on the GPU.
    pub fn on_gpu(&self) -> bool {
        self.gpu.is_some()
    }

    /// Brings the CPU copy of the state up to date with the GPU's (a no-op
    /// on the CPU path). [`Self::displacement`] and [`Self::position`] read
    /// the CPU copy.
    pub fn pull(&mut self) -> Result<(), ModelError> {
        self.check_gpu()?;
        if let Some(g) = &self.gpu
            && self.cpu_stale
        {
            g.download_state(&self.state)?;
            self.cpu_stale = false;
        }
        Ok(())
    }

    /// The first GPU error since the last call (GPU work stops at an error).
    pub fn take_gpu_error(&mut self) -> Option<ModelError> {
        self.gpu_error.take()
    }

    fn check_gpu(&mut self) -> Result<(), ModelError> {
        match self.gpu_error.take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    /// Runs `f` on the GPU path, keeping its first error.
    fn on_device<T: Default>(
        &mut self,
        f: impl FnOnce(&GpuChainMail, &State) -> Result<T, ModelError>,
    ) -> T {
        let (Some(g), None) = (&self.gpu, &self.gpu_error) else {
            return T::default();
        };
        match f(g, &self.state) {
            Ok(v) => v,
            Err(e) => {
                self.gpu_error = Some(e);
                T::default()
            }
        }
    }

    /// Re-uploads the material, flag and cut bytes after an interaction.
    fn push_sites(&mut self) {
        let lat = &self.lat;
        if let Some(g) = &self.gpu
            && self.gpu_error.is_none()
            && let Err(e) = g.upload_sites(lat)
        {
            self.gpu_error = Some(e);
        }
    }

    /// The identity map on the GPU: the current displacements in voxel order
    /// into `out` (x, y, z buffers).
    pub fn map_identity_gpu(&mut self, out: [BufferId; 3]) -> Result<(), ModelError> {
        self.check_gpu()?;
        let voxels = self.lat.dims.iter().product();
        let cur = self.state.cur;
        match &self.gpu {
            Some(g) => g.map_identity(cur, voxels, out),
            None => Err(ModelError::new("chainmail: the model is not on the GPU")),
        }
    }

    /// The element lattice.
    pub fn lattice(&self) -> &ElementLattice {
        &self.lat
    }

    /// The state (both copies; [`State::cur`] is current).
    pub fn state(&self) -> &State {
        &self.state
    }

    /// The parameters.
    pub fn params(&self) -> &ChainMailParams {
        &self.params
    }

    /// Counts so far.
    pub fn counts(&self) -> Counts {
        self.counts
    }

    /// Zeroes the counts.
    pub fn reset_counts(&mut self) {
        self.counts = Counts::default();
    }

    /// Current displacement of element `n`, mm (on the GPU path: as of
    /// the last [`Self::pull`]).
    pub fn displacement(&self, n: usize) -> [f32; 3] {
        self.state.get(self.state.cur, n)
    }

    /// Bytes of model state per lattice site, counted from the arrays
    /// themselves (both Jacobi copies, keys, and the lattice's material,
    /// cut-link and interior bytes; block lists excluded).
    pub fn bytes_per_element(&self) -> f64 {
        let lattice = self.lat.cells.len() + self.lat.cut.len() + self.lat.interior().len();
        (self.state.bytes() + lattice) as f64 / self.lat.len().max(1) as f64
    }

    /// Applies one interaction.
    pub fn interact(&mut self, spec: &InteractionSpec) -> Result<(), ModelError> {
        // Interactions read current positions and change flags and links.
        self.pull()?;
        self.apply(spec)?;
        self.push_sites();
        self.check_gpu()
    }

    fn apply(&mut self, spec: &InteractionSpec) -> Result<(), ModelError> {
        match *spec {
            InteractionSpec::Grab { point, .. } => {
                let p = DVec3::from_array(point);
                let element = self.lat.nearest(p).ok_or_else(|| {
                    ModelError::new("chainmail grab: the model has no element to grab")
                })?;
                let rest = self.lat.world(self.lat.coords(element));
                // `nearest` measures rest positions: one cell's diagonal is
                // as far as a point inside the body can be from its element.
                let reach = DVec3::from(self.lat.spacing).length();
                self.far_grabs.check("chainmail", p, rest, reach);
                let u = self.displacement(element).map(f64::from);
                let motion = GrabMotion::new(spec, rest + DVec3::from_array(u))
                    .expect("a grab has a motion");
                self.grabs.retain(|g| g.element != element);
                self.lat.cells[element] |= HELD;
                self.grabs.push(Grab {
                    element,
                    rest,
                    motion,
                });
            }
            InteractionSpec::Fix {
                min,
                max,
                ref material,
            } => {
                let boxed = min
                    .zip(max)
                    .map(|(a, b)| (DVec3::from_array(a), DVec3::from_array(b)));
                let mat = match material {
                    Some(name) => Some(
                        self.params
                            .materials
                            .iter()
                            .position(|m| m.name.as_deref() == Some(name.as_str()))
                            .ok_or_else(|| {
                                ModelError(format!("chainmail fix: no material is named `{name}`"))
                            })? as u8,
                    ),
                    None => None,
                };
                let mut fixed = 0usize;
                for n in 0..self.lat.len() {
                    let m = self.lat.cells[n] & ABSENT;
                    if m == ABSENT || mat.is_some_and(|k| k != m) {
                        continue;
                    }
                    if let Some((lo, hi)) = boxed {
                        let p = self.lat.world(self.lat.coords(n));
                        if !(p.cmpge(lo).all() && p.cmple(hi).all()) {
                            continue;
                        }
                    }
                    self.lat.cells[n] |= FIXED;
                    fixed += 1;
                }
                tracing::debug!(fixed, "chainmail: elements fixed");
            }
            InteractionSpec::Cut { ref polygon } => {
                let cut = self.cut(polygon);
                if cut == 0 {
                    tracing::warn!("chainmail cut: the polygon crosses no link of the lattice");
                }
                self.topology_changed |= cut > 0;
                tracing::debug!(links = cut, "chainmail: links cut");
            }
            InteractionSpec::Carve { .. } => {
                let region = CarveRegion::of(spec).expect("a carve validated on parsing");
                let inside = |p: DVec3| region.contains(p);
                let (mut present, mut hit) = (0usize, 0usize);
                for n in (0..self.lat.len()).filter(|&n| self.lat.present(n)) {
                    present += 1;
                    hit += inside(self.position(n)) as usize;
                }
                if hit > 0 && hit == present {
                    return Err(ModelError(format!(
                        "chainmail carve: {region:?} (mm) holds every element of the model; \
                         carve a smaller region"
                    )));
                }
                let mut source_tets = 0;
                if !self.elements_are_voxels() {
                    let region = region.bounds();
                    let tets = carve_tets(&self.lat, &self.state, region, inside);
                    source_tets = tets.len();
                    self.remove_source_tets(tets);
                }
                if hit == 0 && source_tets == 0 {
                    tracing::warn!("chainmail carve: no element lies in {region:?} (mm)");
                }
                let mut removed = 0usize;
                for n in 0..self.lat.len() {
                    if self.lat.present(n) && inside(self.position(n)) {
                        self.lat.remove(n);
                        let v = self.lat.coords(n);
                        self.remove_tets(tets_at_vertex(self.mesh_cell_dims(), v));
                        self.grabs.retain(|g| g.element != n);
                        self.touch(n);
                        removed += 1;
                    }
                }
                self.topology_changed |= removed > 0;
                tracing::debug!(removed, "chainmail: elements carved");
            }
            InteractionSpec::Load { .. } => {
                return Err(ModelError::new(
                    "chainmail load: ChainMail has no forces; move the tissue with a `grab` instead",
                ));
            }
            InteractionSpec::Release => {
                for g in self.grabs.drain(..) {
                    self.lat.cells[g.element] &= !HELD;
                    let b = self.blocks.of(self.lat.coords(g.element));
                    insert_sorted(&mut self.relax, b as u32);
                }
            }
        }
        Ok(())
    }

    /// Current world position (mm) of element `n`.
    pub fn position(&self, n: usize) -> DVec3 {
        let u = self.displacement(n);
        self.lat.world(self.lat.coords(n)) + DVec3::new(u[0] as f64, u[1] as f64, u[2] as f64)
    }

    /// Cells of the sampling mesh whose vertices are the elements (one
    /// fewer than elements per axis).
    fn mesh_cell_dims(&self) -> [usize; 3] {
        self.lat.dims.map(|d| d.saturating_sub(1))
    }

    /// True when the elements are the source's voxels one for one, so
    /// removed links and elements map onto sampling-mesh tetrahedra.
    fn elements_are_voxels(&self) -> bool {
        self.lat.downsample == 1
            && self.lat.first_voxel == [0; 3]
            && self.lat.dims == self.lat.source.dims
    }

    /// Removes the tetrahedra of cut links or carved elements when the
    /// elements are the mesh vertices (otherwise [`crate::removal`] finds
    /// them on the mesh itself).
    fn remove_tets(&mut self, tets: Vec<(usize, u8)>) {
        if self.elements_are_voxels() {
            self.remove_source_tets(tets);
        }
    }

    /// ORs `(cell, bits)` of the source's sampling mesh into the removed
    /// tetrahedra.
    fn remove_source_tets(&mut self, tets: Vec<(usize, u8)>) {
        if tets.is_empty() {
            return;
        }
        if self.removed_tets.is_empty() {
            let [cx, cy, cz] = self.lat.source.dims.map(|d| d.saturating_sub(1));
            self.removed_tets = vec![0; cx * cy * cz];
        }
        for (cell, bits) in tets {
            self.removed_unreported |= self.removed_tets[cell] | bits != self.removed_tets[cell];
            self.removed_tets[cell] |= bits;
        }
    }

    /// ORs the removed tetrahedra into `cell_bits` (the source mesh's cells)
    /// when some were removed since the last report; returns true when a
    /// new bit was set. An empty `cell_bits` asks whether any were removed.
    /// The host keeps its array between calls, so a frame without a new cut
    /// costs nothing here.
    pub fn removed_tetrahedra(&mut self, cell_bits: &mut [u8]) -> bool {
        if cell_bits.is_empty() {
            return !self.removed_tets.is_empty();
        }
        if !self.removed_unreported || self.removed_tets.len() != cell_bits.len() {
            return false;
        }
        self.removed_unreported = false;
        let mut changed = false;
        for (o, &b) in cell_bits.iter_mut().zip(&self.removed_tets) {
            if *o | b != *o {
                *o |= b;
                changed = true;
            }
        }
        changed
    }

    /// Marks element `n`'s block dirty and due for relaxation.
    fn touch(&mut self, n: usize) {
        let b = self.blocks.of(self.lat.coords(n));
        self.mark_changed(b);
        insert_sorted(&mut self.relax, b as u32);
    }

    /// Block `b` changed: the map must re-read it and its links must be
    /// measured again.
    #[inline]
    fn mark_changed(&mut self, b: usize) {
        self.dirty[b] = true;
        self.conflicts.mark(b);
    }

    /// Cuts the links crossing `polygon` (fanned from its first corner);
    /// returns how many.
    fn cut(&mut self, polygon: &[[f64; 3]]) -> usize {
        let cut = CutPolygon::new(polygon);
        let (lo, hi) = (cut.lo, cut.hi);
        if !self.elements_are_voxels() {
            let tets = cut_tets(&self.lat, &self.state, &cut);
            self.remove_source_tets(tets);
        }
        let reach = DVec3::from(self.lat.spacing) * 2.0;
        let (lo, hi) = (lo - reach, hi + reach);
        let mut count = 0;
        for n in 0..self.lat.len() {
            if !self.lat.present(n) {
                continue;
            }
            let a = self.position(n);
            if !(a.cmpge(lo).all() && a.cmple(hi).all()) {
                continue;
            }
            let c = self.lat.coords(n);
            // +x, +y, +z links: each link once.
            for l in [0, 2, 4] {
                let Some(e) = self.lat.neighbour(n, c, l) else {
                    continue;
                };
                if !self.lat.present(e) {
                    continue;
                }
                let b = self.position(e);
                if cut.crosses(a, b) {
                    self.lat.cut_link(n, l);
                    // +x/+y/+z links start at `n`.
                    self.remove_tets(tets_on_edge(self.mesh_cell_dims(), c, l / 2));
                    self.touch(n);
                    self.touch(e);
                    count += 1;
                }
            }
        }
        count
    }

    /// Moves the grabs one frame along their paths; starts one wave for all
    /// grabs that moved. Returns the moved elements.
    fn advance_grabs(&mut self) -> Vec<usize> {
        let mut targets = Vec::new();
        for g in &mut self.grabs {
            if let Some(target) = g.motion.advance() {
                let u = target - g.rest;
                targets.push((g.element, [u.x as f32, u.y as f32, u.z as f32]));
            }
        }
        if targets.is_empty() {
            return Vec::new();
        }
        self.repairs_left = repair::MAX_REPAIR_WAVES;
        self.start_wave(&targets);
        targets.into_iter().map(|(e, _)| e).collect()
    }

    /// Starts a new wave from `seeds` (element, its new displacement in mm):
    /// each seed takes the displacement with the wave's first key, and the
    /// propagation schedule, relaxation and change tracking take in its
    /// block.
    fn start_wave(&mut self, seeds: &[(usize, [f32; 3])]) {
        // Seed the parallel propagation's work (the sequential algorithm
        // propagates in one pass from the moved elements instead): the
        // seeds and their neighbours, which may lie across a block face —
        // a seed is set, not moved by an iteration, so no iteration flags
        // its faces.
        let parallel = self.params.algorithm == Algorithm::Parallel;
        let ids: Vec<u32> = seeds.iter().map(|t| t.0 as u32).collect();
        let reached = next_frontier(&self.lat, &ids);
        if parallel && self.params.schedule == Schedule::Blocks {
            for &n in &reached {
                let b = self.blocks.of(self.lat.coords(n as usize));
                insert_sorted(&mut self.active, b as u32);
            }
        }
        if parallel && self.params.schedule == Schedule::Frontier {
            self.frontier.extend(reached);
        }
        if self.wave >= MAX_WAVE {
            self.wave = self.state.rebase(self.wave, 16);
        }
        self.wave += 1;
        let k = key(self.wave, 0);
        self.propagated_since_check = true;
        for &(e, u) in seeds {
            self.state.set_both(e, u, k);
            self.on_device(|g, _| g.write_element(e, u, k));
            let b = self.blocks.of(self.lat.coords(e));
            insert_sorted(&mut self.relax, b as u32);
            self.mark_changed(b);
        }
    }

    /// One frame: the grabs move, then (parallel) up to
    /// `propagation_iterations` propagation iterations and
    /// `relaxation_iterations` relaxation sweeps, or (sequential) one full
    /// Gibson pass and the sweeps. Returns true when anything moved.
    pub fn step(&mut self) -> bool {
        self.step_stats().changed
    }

    /// [`Self::step`], with what the frame did.
    pub fn step_stats(&mut self) -> FrameStats {
        let t = std::time::Instant::now();
        let mut stats = FrameStats::default();
        let moved = self.advance_grabs();
        let mut changed = !moved.is_empty() || std::mem::take(&mut self.topology_changed);
        match self.params.algorithm {
            Algorithm::Parallel => {
                let mut left = self.params.propagation_iterations as u64;
                while left > 0 && (self.propagating() || self.start_repair_wave()) {
                    let run = self.propagate_some(left);
                    stats.propagation_blocks += run.blocks;
                    changed |= run.moved;
                    left -= run.iterations.max(1);
                }
            }
            Algorithm::Sequential => {
                if !moved.is_empty() {
                    self.sequential_pass(&moved);
                }
            }
        }
        let mut left = self.params.relaxation_iterations as u64;
        while left > 0 && !self.relax.is_empty() {
            let run = self.relax_some(left);
            stats.relaxation_blocks += run.blocks;
            stats.sweeps += run.iterations;
            changed |= run.moved;
            stats.max_move = self.last_max_move;
            left -= run.iterations.max(1);
        }
        stats.changed = changed;
        if self.propagated_since_check && !self.propagating() {
            self.check_conflicts();
        }
        stats.ms = t.elapsed().as_secs_f64() * 1e3;
        self.log.frame(&stats, self.at_rest());
        stats
    }

    /// Measures the link violations left now that propagation has settled
    /// (see [`crate::conflicts`]), logs them, and warns when the largest
    /// exceeds the tolerance and a quarter more than the last warning.
    fn check_conflicts(&mut self) {
        if let Err(e) = self.pull() {
            self.gpu_error.get_or_insert(e);
            return;
        }
        self.propagated_since_check = false;
        let spacing = self.lat.smallest_spacing();
        let tol_mm = (conflicts::TOLERANCE * spacing) as f32;
        let mut v = self
            .conflicts
            .check(&self.lat, &self.state, &self.blocks, tol_mm);
        if v.count > 0 && !self.grabs.is_empty() {
            // The grabs are what pulled the links apart.
            v.kinds |= conflicts::HELD_END;
        }
        self.log.conflict(v);
        if v.count > 0 && v.mm > 1.25 * self.log.last_warned_mm {
            self.log.last_warned_mm = v.mm;
            self.warn_conflict(v, spacing);
        }
    }

    fn warn_conflict(&self, v: Violation, spacing: f64) {
        tracing::warn!("{}", self.conflict_message(v, spacing));
    }

    /// The warning about the worst conflict measured so far, if any.
    pub fn conflict_warning(&self) -> Option<String> {
        let spacing = self.lat.smallest_spacing();
        let (v, _) = self.log.worst?;
        Some(self.conflict_message(v, spacing))
    }

    fn conflict_message(&self, v: Violation, spacing: f64) -> String {
        let at = |n: u32| {
            let p = self.lat.world(self.lat.coords(n as usize));
            format!("[{:.1}, {:.1}, {:.1}]", p.x, p.y, p.z)
        };
        format!(
            "chainmail: {} link constraints cannot hold ({}): the largest violation is \
             {:.3} mm ({:.2} element spacings) on the link between the elements at {} and {} mm \
             (rest positions, world LPS); propagation never moves fixed or held elements, so \
             the tissue between them tears. Move the `fix` box or the grab's `point` apart, \
             shorten its `by`/`to`, or raise the materials' `constraint` (violations up to {} \
             of the spacing are ignored)",
            v.count,
            conflicts::describe(v.kinds),
            v.mm,
            v.mm as f64 / spacing,
            at(v.link.0),
            at(v.link.1),
            conflicts::TOLERANCE
        )
    }

    /// What the model reports about its run (see [`RunLog::notes`]), plus
    /// the iteration counts, the `downsample` in force and the sampling-mesh
    /// tetrahedra removed by cuts and carving.
    pub fn notes(&self) -> voxflex_core::deformation::ModelNotes {
        let mut notes = voxflex_core::deformation::ModelNotes::new();
        self.log.notes(&mut notes);
        let c = self.counts;
        notes.insert(
            "propagation_iterations".into(),
            c.propagation_iterations as f64,
        );
        notes.insert("relaxation_sweeps".into(), c.relaxation_iterations as f64);
        notes.insert("repair_waves".into(), c.repair_waves as f64);
        // Source voxels per element along each axis (the `downsample` in
        // force, the default when the params leave it out).
        notes.insert("downsample".into(), self.lat.downsample as f64);
        // Sampling-mesh tetrahedra the cuts and carving removed so far
        // (tissue the renderer no longer draws).
        let removed: u32 = self.removed_tets.iter().map(|b| b.count_ones()).sum();
        notes.insert("removed_tetrahedra".into(), removed as f64);
        self.far_grabs.add_notes(&mut notes);
        notes
    }

    /// Warns when work is still pending (call after a run's last frame):
    /// the model has not come to rest and the last frames were not final.
    pub fn warn_if_not_at_rest(&self) {
        if self.at_rest() {
            return;
        }
        tracing::warn!(
            "chainmail: not at rest after {} frames: {} blocks still propagating, {} relaxing \
             (last sweep moved an element by {:.1e} of the spacing; rest below \
             `rest_tolerance` = {:.1e}); add frames or raise `relaxation_iterations` \
             (now {}) or `rest_tolerance`",
            self.log.frames,
            self.active.len() + self.frontier.len(),
            self.relax.len(),
            self.last_max_move,
            self.params.rest_tolerance,
            self.params.relaxation_iterations
        );
    }

    /// The run so far (frames, rest, conflicts).
    pub fn run_log(&self) -> &RunLog {
        &self.log
    }

    /// Runs propagation, then relaxation, until nothing moves (or the caps
    /// are hit), without rendering in between: the papers' benchmark.
    pub fn settle(&mut self, max_propagation: u64, max_relaxation: u64) -> SettleReport {
        let propagation_iterations = self.propagate(max_propagation);
        let relaxation_iterations = self.relax(max_relaxation);
        SettleReport {
            propagation_iterations,
            relaxation_iterations,
            at_rest: self.at_rest(),
        }
    }

    /// Applies the grabs' next positions and settles: a deformation run to
    /// rest. Returns the settle report.
    pub fn deform_to_rest(&mut self, max_propagation: u64, max_relaxation: u64) -> SettleReport {
        self.start_deformation();
        self.settle(max_propagation, max_relaxation)
    }

    fn sequential_pass(&mut self, moved: &[usize]) {
        self.sync_copies();
        let updates = gibson(&self.lat, &self.state, moved, self.wave);
        self.propagated_since_check = true;
        self.counts.propagation_iterations += 1;
        self.counts.updates += updates;
        self.counts.visits += updates;
        // Relax wherever the pass reached: every block is a candidate.
        self.relax = (0..self.blocks.len() as u32).collect();
        for b in 0..self.blocks.len() {
            self.mark_changed(b);
        }
    }

    /// Relaxation only, until at rest (or `max` sweeps); returns the sweeps.
    pub fn relax(&mut self, max: u64) -> u64 {
        let mut it = 0;
        while !self.relax.is_empty() && it < max {
            it += self.relax_some(max - it).iterations.max(1);
        }
        it
    }

    /// Moves the grabs to their next positions and, for the sequential
    /// algorithm, runs its propagation pass (the parallel one propagates in
    /// [`Self::propagate`]).
    pub fn start_deformation(&mut self) {
        let moved = self.advance_grabs();
        if let Algorithm::Sequential = self.params.algorithm
            && !moved.is_empty()
        {
            self.sequential_pass(&moved);
        }
    }

    /// Propagation only, until no block is active (or `max` iterations).
    pub fn propagate(&mut self, max: u64) -> u64 {
        let mut it = 0;
        while it < max && (self.propagating() || self.start_repair_wave()) {
            it += self.propagate_some(max - it).iterations.max(1);
        }
        it
    }

    /// True when propagation has work left.
    fn propagating(&self) -> bool {
        match self.params.schedule {
            Schedule::Blocks => !self.active.is_empty(),
            Schedule::Frontier => !self.frontier.is_empty(),
        }
    }

    /// Up to `max` (≥ 1) propagation iterations: on the GPU, one device
    /// run (the device builds each next list); on the CPU, one iteration.
    fn propagate_some(&mut self, max: u64) -> Run {
        if self.gpu.is_none() || self.params.schedule == Schedule::Frontier {
            let blocks = self.active.len() as u64;
            let moved = self.propagate_once();
            return Run {
                iterations: 1,
                blocks,
                moved,
            };
        }
        self.sync_copies();
        let (cur, active) = (self.state.cur, std::mem::take(&mut self.active));
        let run = self.on_device(|g, _| g.propagate(cur, &active, max));
        self.state.cur = cur ^ (run.iterations & 1) as usize;
        self.cpu_stale = true;
        self.counts.propagation_iterations += run.iterations;
        self.counts.visits += run.visits;
        self.counts.updates += run.updates;
        self.propagated_since_check = true;
        self.mark_all_changed(&run.dirty);
        merge_sorted(&mut self.relax, &run.activated, &mut self.merge_scratch);
        self.active = run.next;
        Run {
            iterations: run.iterations,
            blocks: run.listed_blocks,
            moved: run.updates > 0,
        }
    }

    /// One propagation iteration on the CPU.
    fn propagate_once(&mut self) -> bool {
        if self.params.schedule == Schedule::Frontier {
            self.sync_copies();
            return self.propagate_frontier_once();
        }
        // The current copy only: the other falls behind where elements
        // move, as after relaxation.
        let rep = jacobi_iteration(&self.lat, &self.state, &self.blocks, &self.active);
        self.counts.propagation_iterations += 1;
        self.counts.visits += rep.visits;
        self.counts.updates += rep.updates;
        self.propagated_since_check = true;
        self.mark_unsynced(rep.blocks.iter().filter(|b| b.1 != 0).map(|b| b.0));
        self.note_changes(&rep.blocks);
        self.active = self.blocks.next_active(&rep.blocks, &mut self.seen);
        merge_sorted(&mut self.relax, &self.active, &mut self.merge_scratch);
        rep.updates > 0
    }

    fn propagate_frontier_once(&mut self) -> bool {
        self.frontier.sort_unstable();
        self.frontier.dedup();
        let rep = frontier_iteration(&self.lat, &mut self.state, &self.frontier);
        self.propagated_since_check = true;
        self.counts.propagation_iterations += 1;
        self.counts.visits += rep.visits;
        self.counts.updates += rep.updated.len() as u64;
        let mut touched: Vec<u32> = rep
            .updated
            .iter()
            .map(|&n| self.blocks.of(self.lat.coords(n as usize)) as u32)
            .collect();
        touched.sort_unstable();
        touched.dedup();
        for &b in &touched {
            self.mark_changed(b as usize);
        }
        merge_sorted(&mut self.relax, &touched, &mut self.merge_scratch);
        self.frontier = next_frontier(&self.lat, &rep.updated);
        !rep.updated.is_empty()
    }

    /// Up to `max` (≥ 1) relaxation sweeps: on the GPU, one device run;
    /// on the CPU, one sweep.
    fn relax_some(&mut self, max: u64) -> Run {
        if self.gpu.is_none() {
            let blocks = self.relax.len() as u64;
            let moved = self.relax_once();
            return Run {
                iterations: 1,
                blocks,
                moved,
            };
        }
        let tol = self.params.rest_tolerance;
        let (cur, set) = (self.state.cur, std::mem::take(&mut self.relax));
        self.cpu_stale = true;
        let run = self.on_device(|g, _| g.relax(cur, &set, tol, max));
        self.counts.relaxation_iterations += run.iterations;
        self.last_max_move = run.last_max_move;
        self.mark_unsynced(run.listed.iter().copied());
        self.mark_all_changed(&run.dirty);
        self.relax = run.next;
        Run {
            iterations: run.iterations,
            blocks: run.listed_blocks,
            moved: run.any_max_move > 0.0,
        }
    }

    /// One relaxation sweep on the CPU.
    fn relax_once(&mut self) -> bool {
        // The sequential baseline sweeps every element, one by one, as
        // Gibson's relaxation does; the parallel model only the active
        // blocks, in parallel and 8 at a time.
        let sequential = self.params.algorithm == Algorithm::Sequential;
        let tol = self.params.rest_tolerance;
        let rep = if sequential {
            let all: Vec<u32> = (0..self.blocks.len() as u32).collect();
            sweep_scalar(&self.lat, &self.state, &self.blocks, &all, tol)
        } else {
            sweep_runs(
                &self.lat,
                &self.state,
                &self.blocks,
                &self.relax,
                tol,
                &mut self.sweep_scratch,
            )
        };
        self.counts.relaxation_iterations += 1;
        self.last_max_move = rep.max_move;
        self.mark_unsynced(rep.blocks.iter().map(|&(b, _)| b));
        self.note_changes(&rep.blocks);
        self.relax = if sequential {
            if rep.max_move >= tol {
                (0..self.blocks.len() as u32).collect()
            } else {
                Vec::new()
            }
        } else {
            self.blocks.next_active(&rep.blocks, &mut self.seen)
        };
        rep.max_move > 0.0
    }

    /// Copies the displacements and keys of the blocks changed in the
    /// current copy only (by relaxation, and by the CPU's block
    /// propagation) into the other copy, so that both agree outside the
    /// blocks a two-copy propagation visits (its invariant: the GPU's, and
    /// the frontier schedule's).
    fn sync_copies(&mut self) {
        if self.unsynced.is_empty() {
            return;
        }
        if self.gpu.is_some() {
            let (cur, list) = (self.state.cur, std::mem::take(&mut self.unsynced));
            self.on_device(|g, _| g.sync(cur, &list));
            for b in list {
                self.unsynced_flag[b as usize] = false;
            }
            return;
        }
        let (lat, state, blocks) = (&self.lat, &self.state, &self.blocks);
        self.unsynced.par_iter().for_each(|&b| {
            let (lo, hi) = blocks.range(b as usize);
            for k in lo[2]..hi[2] {
                for j in lo[1]..hi[1] {
                    for i in lo[0]..hi[0] {
                        state.carry(state.cur, lat.linear([i, j, k]));
                    }
                }
            }
        });
        for b in self.unsynced.drain(..) {
            self.unsynced_flag[b as usize] = false;
        }
    }

    /// Blocks changed in the current Jacobi copy only: to be synced.
    fn mark_unsynced(&mut self, blocks: impl Iterator<Item = u32>) {
        for b in blocks {
            if !std::mem::replace(&mut self.unsynced_flag[b as usize], true) {
                self.unsynced.push(b);
            }
        }
    }

    /// Blocks that changed (see [`Self::mark_changed`]).
    fn mark_all_changed(&mut self, blocks: &[u32]) {
        for &b in blocks {
            self.mark_changed(b as usize);
        }
    }

    fn note_changes(&mut self, results: &[(u32, FaceMask)]) {
        for &(b, m) in results {
            if m != 0 {
                self.mark_changed(b as usize);
            }
        }
    }

    /// The rest-space box (mm) of the blocks changed since the last call,
    /// grown by one element spacing; `None` when nothing changed.
    pub fn take_dirty(&mut self) -> Option<(DVec3, DVec3)> {
        let mut lo = [usize::MAX; 3];
        let mut hi = [0usize; 3];
        let mut any = false;
        for (b, d) in self.dirty.iter_mut().enumerate() {
            if std::mem::take(d) {
                any = true;
                let (l, h) = self.blocks.range(b);
                for a in 0..3 {
                    lo[a] = lo[a].min(l[a]);
                    hi[a] = hi[a].max(h[a] - 1);
                }
            }
        }
        any.then(|| {
            let sp = DVec3::from(self.lat.spacing);
            (self.lat.world(lo) - sp, self.lat.world(hi) + sp)
        })
    }

    /// True when no propagation or relaxation work is pending.
    pub fn at_rest(&self) -> bool {
        !self.propagating() && self.relax.is_empty()
    }
}

/// What a stretch of propagation iterations or relaxation sweeps did.
struct Run {
    /// Iterations or sweeps whose block list was not empty.
    iterations: u64,
    /// Sum of their lists' lengths.
    blocks: u64,
    /// Something moved.
    moved: bool,
}

/// `list` (ascending, no repeats) merged with `more` (the same), in
/// linear time; `scratch` is reused storage.
fn merge_sorted(list: &mut Vec<u32>, more: &[u32], scratch: &mut Vec<u32>) {
    scratch.clear();
    scratch.reserve(list.len() + more.len());
    let (mut i, mut j) = (0, 0);
    while i < list.len() && j < more.len() {
        let (a, b) = (list[i], more[j]);
        scratch.push(a.min(b));
        i += usize::from(a <= b);
        j += usize::from(b <= a);
    }
    scratch.extend_from_slice(&list[i..]);
    scratch.extend_from_slice(&more[j..]);
    std::mem::swap(list, scratch);
}

/// Inserts block `b` into `list` (ascending, no repeats), keeping it so.
fn insert_sorted(list: &mut Vec<u32>, b: u32) {
    if let Err(at) = list.binary_search(&b) {
        list.insert(at, b);
    }
}

#[cfg(test)]
mod merge_tests {
    use super::{insert_sorted, merge_sorted};

    #[test]
    fn merging_sorted_block_lists_keeps_them_sorted_and_unique() {
        let mut scratch = Vec::new();
        for (a, b, want) in [
            (vec![], vec![], vec![]),
            (vec![1, 4, 9], vec![], vec![1, 4, 9]),
            (vec![], vec![2, 3], vec![2, 3]),
            (vec![1, 4, 9], vec![0, 4, 5, 9, 12], vec![0, 1, 4, 5, 9, 12]),
        ] {
            let mut list = a;
            merge_sorted(&mut list, &b, &mut scratch);
            assert_eq!(list, want);
        }
        let mut list = vec![];
        for b in [7, 2, 9, 2, 0, 7] {
            insert_sorted(&mut list, b);
        }
        assert_eq!(list, vec![0, 2, 7, 9]);
    }
}
