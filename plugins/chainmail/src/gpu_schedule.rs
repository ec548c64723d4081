//! The active-block schedule kept on the device: the buffers and kernels of
//! `shaders/chainmail/schedule.wgsl` (the twin of [`Blocks::next_active`]),
//! and the loop that queues iterations in batches and reads back only a
//! few words per batch.
//!
//! Two list buffers take turns: iteration `i` runs the list in
//! `lists[i % 2]`, `schedule` builds the next one into the other, and
//! `retire` clears the de-duplication bits, empties the spent list and
//! writes the next list's indirect dispatch arguments (`args`), so every
//! launch has exactly one workgroup per listed block — none for an empty
//! list — whatever the lattice's size. Once a list is empty every later
//! iteration is empty too (its launches have no workgroups and count
//! nothing), so the host may queue a whole batch and
//! learn afterwards how many iterations did work. A run capped at
//! [`WHOLE_BATCH`] iterations or fewer (a frame's 10 + 10) is queued whole
//! and checked once; a longer one is checked after 2, 4, 8, 16, then every
//! 32 queued iterations (never past its cap): a run of `n` iterations costs
//! `~log₂ n + n / 32` read-backs of twelve words instead of `n` read-backs
//! of every listed block's results, plus, at its end, one read-back of the
//! per-block flags and one of the pending list.

use crate::blocks::Blocks;
use voxflex_core::error::ModelError;
use voxflex_core::gpu::{BufferBinding, BufferId, GpuService, GpuServiceExt, PipelineId};

/// The scheduling kernels.
pub const SCHEDULE_WGSL: &str = include_str!("../../../shaders/chainmail/schedule.wgsl");

/// Words of the run totals (`SCHED_WORDS` in the shader), and their places.
pub(crate) const SCHED_WORDS: usize = 12;
pub(crate) mod word {
    pub const VISITS: usize = 0;
    pub const UPDATES: usize = 2;
    pub const BLOCKS: usize = 4;
    pub const LAUNCHES: usize = 6;
    pub const LAST_MAX: usize = 8;
    pub const ANY_MAX: usize = 9;
    pub const PENDING: usize = 10;
}

/// Bits of the per-block flags (named as in the shader).
pub(crate) mod flag {
    pub const IN_NEXT: u32 = 1;
    pub const ACTIVATED: u32 = 2;
    pub const DIRTY: u32 = 4;
    pub const LISTED: u32 = 8;
}

/// Binding numbers of `schedule.wgsl`'s variables.
pub(crate) mod bind {
    pub const GRID: u32 = 0;
    pub const LIST: u32 = 1;
    pub const STATS: u32 = 2;
    pub const NEXT: u32 = 3;
    pub const FLAGS: u32 = 4;
    pub const SCHED: u32 = 5;
    pub const SPENT: u32 = 6;
    pub const ARGS: u32 = 7;
}

/// Invocations per workgroup of both kernels (`WG` in the shader).
pub(crate) const SCHEDULE_WORKGROUP: u32 = 64;
/// Words of a list's indirect arguments (`ARG_WORDS`): the block kernels'
/// workgroups, then `schedule`'s.
pub(crate) const ARG_WORDS: usize = 6;
/// Byte offset of `schedule`'s arguments in a list's.
const SCHEDULE_ARGS: u64 = 12;

/// Runs capped at this many iterations or fewer are queued whole: the
/// empty launches after their list empties cost less than read-backs.
const WHOLE_BATCH: u64 = 16;
/// Iterations queued before the first check of a longer run, doubling up
/// to [`LONGEST_BATCH`].
const FIRST_BATCH: u64 = 2;
/// Iterations queued between checks at most.
const LONGEST_BATCH: u64 = 32;

/// What a run of iterations did, summed over its nonempty launches.
#[derive(Debug, Default)]
pub struct RunReport {
    /// Iterations (propagation) or sweeps (relaxation) whose list was not
    /// empty.
    pub iterations: u64,
    /// Element visits (propagation).
    pub visits: u64,
    /// Elements that took a new displacement (propagation).
    pub updates: u64,
    /// Sum of the run lists' lengths.
    pub listed_blocks: u64,
    /// Largest element move of the last sweep, as a fraction of the
    /// element spacing (relaxation; 0 for propagation).
    pub last_max_move: f64,
    /// Largest element move of any sweep of the run, the same units.
    pub any_max_move: f64,
    /// The list the next iteration would run (ascending; empty when the
    /// run ended because nothing was left to do).
    pub next: Vec<u32>,
    /// Blocks with a nonzero face mask in some launch (ascending).
    pub dirty: Vec<u32>,
    /// Blocks that entered a built list (ascending).
    pub activated: Vec<u32>,
    /// Blocks that were in a list that ran (ascending).
    pub listed: Vec<u32>,
}

/// The schedule's buffers and kernels on the device.
pub(crate) struct DeviceSchedule {
    blocks: usize,
    grid: BufferId,
    lists: [BufferId; 2],
    /// Each list's indirect dispatch arguments.
    args: [BufferId; 2],
    flags: BufferId,
    sched: BufferId,
    schedule: PipelineId,
    retire: PipelineId,
}

fn gpu_err(e: impl std::fmt::Display) -> ModelError {
    ModelError(format!("chainmail (GPU schedule): {e}"))
}

impl DeviceSchedule {
    /// Buffers for `blocks`' lists and flags (zeroed) and the kernels.
    pub(crate) fn new(gpu: &dyn GpuService, blocks: &Blocks) -> Result<Self, ModelError> {
        let n = blocks.len().max(1);
        let grid: [u32; 4] = [
            blocks.count[0] as u32,
            blocks.count[1] as u32,
            blocks.count[2] as u32,
            gpu.limits().max_compute_workgroups_per_dimension,
        ];
        let args_bytes = 4 * ARG_WORDS as u64;
        let list_bytes = 4 * (1 + n as u64);
        let buffer = |bytes: u64, label: &str| gpu.create_buffer(bytes, label).map_err(gpu_err);
        Ok(Self {
            blocks: n,
            grid: gpu.upload(&grid, "chainmail block grid").map_err(gpu_err)?,
            lists: [
                buffer(list_bytes, "chainmail block list A")?,
                buffer(list_bytes, "chainmail block list B")?,
            ],
            args: [
                buffer(args_bytes, "chainmail list A dispatch")?,
                buffer(args_bytes, "chainmail list B dispatch")?,
            ],
            flags: buffer(4 * n as u64, "chainmail block flags")?,
            sched: buffer(4 * SCHED_WORDS as u64, "chainmail run totals")?,
            schedule: gpu.compile(SCHEDULE_WGSL, "schedule").map_err(gpu_err)?,
            retire: gpu.compile(SCHEDULE_WGSL, "retire").map_err(gpu_err)?,
        })
    }

    /// The list iteration `i` runs, bound at `binding`.
    pub(crate) fn list(&self, i: u64, binding: u32) -> BufferBinding {
        BufferBinding::whole(binding, self.lists[(i % 2) as usize])
    }

    /// Queues `pipeline` over the list of iteration `i`, one workgroup per
    /// listed block (indirect: the count is on the device).
    pub(crate) fn dispatch_over_list(
        &self,
        gpu: &dyn GpuService,
        pipeline: PipelineId,
        bindings: &[BufferBinding],
        i: u64,
    ) -> Result<(), ModelError> {
        gpu.dispatch_indirect(pipeline, bindings, self.args[(i % 2) as usize], 0)
            .map_err(gpu_err)
    }

    /// Writes `list` (block indices) and its dispatch arguments as the
    /// list iteration 0 runs.
    pub(crate) fn write_list(&self, gpu: &dyn GpuService, list: &[u32]) -> Result<(), ModelError> {
        let mut words = Vec::with_capacity(1 + list.len());
        words.push(list.len() as u32);
        words.extend_from_slice(list);
        gpu.write_buffer(self.lists[0], 0, bytemuck::cast_slice(&words))
            .map_err(gpu_err)?;
        let mut args = [0u32; ARG_WORDS];
        if !list.is_empty() {
            let n = list.len() as u64;
            let fold = |per| gpu.workgroups_for(n, per).map_err(gpu_err);
            args[..3].copy_from_slice(&fold(1)?);
            args[3..].copy_from_slice(&fold(SCHEDULE_WORKGROUP)?);
        }
        gpu.write_buffer(self.args[0], 0, bytemuck::cast_slice(&args))
            .map_err(gpu_err)
    }

    /// Runs up to `max` iterations starting from `list`: `launch(i)` queues
    /// iteration `i`'s kernels over [`Self::list`]`(i, ..)`, which must
    /// write the per-slot results into `stats`. An empty list or `max = 0`
    /// runs nothing and hands `list` back as the next.
    pub(crate) fn run(
        &self,
        gpu: &dyn GpuService,
        list: &[u32],
        max: u64,
        stats: BufferId,
        mut launch: impl FnMut(u64) -> Result<(), ModelError>,
    ) -> Result<RunReport, ModelError> {
        if list.is_empty() || max == 0 {
            return Ok(RunReport {
                next: list.to_vec(),
                ..RunReport::default()
            });
        }
        self.write_list(gpu, list)?;
        gpu.write_buffer(self.lists[1], 0, &0u32.to_le_bytes())
            .map_err(gpu_err)?;
        gpu.write_buffer(self.sched, 0, &[0u8; 4 * SCHED_WORDS])
            .map_err(gpu_err)?;
        let groups = gpu
            .workgroups_for(self.blocks as u64, SCHEDULE_WORKGROUP)
            .map_err(gpu_err)?;
        let first = if max <= WHOLE_BATCH { max } else { FIRST_BATCH };
        let (mut queued, mut batch) = (0u64, first);
        let totals = loop {
            let end = queued.saturating_add(batch).min(max);
            for i in queued..end {
                launch(i)?;
                self.queue_schedule(gpu, i, stats, groups)?;
            }
            queued = end;
            batch = (2 * batch).min(LONGEST_BATCH);
            let mut totals = [0u32; SCHED_WORDS];
            gpu.download(self.sched, &mut totals).map_err(gpu_err)?;
            if totals[word::PENDING] == 0 || queued == max {
                break totals;
            }
        };
        self.report(gpu, &totals)
    }

    /// Queues `schedule` (over the list that ran) and `retire` (over every
    /// block: the new list's length is known only on the device) after
    /// iteration `i`.
    fn queue_schedule(
        &self,
        gpu: &dyn GpuService,
        i: u64,
        stats: BufferId,
        groups: [u32; 3],
    ) -> Result<(), ModelError> {
        let (ran, built) = (
            self.lists[(i % 2) as usize],
            self.lists[((i + 1) % 2) as usize],
        );
        let (ran_args, built_args) = (
            self.args[(i % 2) as usize],
            self.args[((i + 1) % 2) as usize],
        );
        let common = [
            BufferBinding::whole(bind::GRID, self.grid),
            BufferBinding::whole(bind::FLAGS, self.flags),
            BufferBinding::whole(bind::SCHED, self.sched),
        ];
        let mut with = common.to_vec();
        with.extend([
            BufferBinding::whole(bind::LIST, ran),
            BufferBinding::whole(bind::STATS, stats),
            BufferBinding::whole(bind::NEXT, built),
        ]);
        gpu.dispatch_indirect(self.schedule, &with, ran_args, SCHEDULE_ARGS)
            .map_err(gpu_err)?;
        let mut with = common.to_vec();
        with.extend([
            BufferBinding::whole(bind::NEXT, built),
            BufferBinding::whole(bind::SPENT, ran),
            BufferBinding::whole(bind::ARGS, built_args),
        ]);
        gpu.dispatch(self.retire, &with, groups).map_err(gpu_err)
    }

    /// The run's report from its totals, the pending list and the flags
    /// (which are zeroed for the next run).
    fn report(
        &self,
        gpu: &dyn GpuService,
        t: &[u32; SCHED_WORDS],
    ) -> Result<RunReport, ModelError> {
        let wide = |at: usize| t[at] as u64 | (t[at + 1] as u64) << 32;
        let iterations = t[word::LAUNCHES] as u64;
        let pending = t[word::PENDING] as usize;
        let mut next = Vec::new();
        if pending > 0 {
            let mut words = vec![0u32; 1 + pending];
            let built = self.lists[(iterations % 2) as usize];
            gpu.download(built, &mut words).map_err(gpu_err)?;
            next = words.split_off(1);
            next.sort_unstable();
        }
        let mut flags = vec![0u32; self.blocks];
        gpu.download(self.flags, &mut flags).map_err(gpu_err)?;
        // `retire` clears every de-duplication bit it set.
        debug_assert!(flags.iter().all(|f| f & flag::IN_NEXT == 0));
        gpu.write_buffer(self.flags, 0, &vec![0u8; 4 * self.blocks])
            .map_err(gpu_err)?;
        let with = |bit: u32| -> Vec<u32> {
            (0..self.blocks as u32)
                .filter(|&b| flags[b as usize] & bit != 0)
                .collect()
        };
        Ok(RunReport {
            iterations,
            visits: wide(word::VISITS),
            updates: wide(word::UPDATES),
            listed_blocks: wide(word::BLOCKS),
            last_max_move: f32::from_bits(t[word::LAST_MAX]) as f64,
            any_max_move: f32::from_bits(t[word::ANY_MAX]) as f64,
            dirty: with(flag::DIRTY),
            activated: with(flag::ACTIVATED),
            listed: with(flag::LISTED),
            next,
        })
    }

    /// Frees the buffers.
    pub(crate) fn destroy(&self, gpu: &dyn GpuService) {
        let [a, b] = self.lists;
        let [c, d] = self.args;
        for id in [self.grid, a, b, c, d, self.flags, self.sched] {
            gpu.destroy_buffer(id);
        }
    }
}
