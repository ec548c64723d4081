//! The host's one GPU context: [`WgpuService`] implements
//! [`voxflex_core::gpu::GpuService`] over a single wgpu instance, adapter,
//! device and queue.
//!
//! Everything GPU in voxflex — host services and plugins alike — goes through
//! this one device (docs/DESIGN.md, "The plugin boundary"): buffers are named by
//! opaque [`BufferId`]s, WGSL compute pipelines are compiled once per
//! `(source, entry point)` and named by [`PipelineId`]s, and every pipeline
//! uses one bind group (group 0) whose layout wgpu derives from the shader.
//!
//! # Adapter choice
//!
//! The instance reads wgpu's usual environment variables: `WGPU_BACKEND`
//! (e.g. `vulkan`, `gl`), `WGPU_ADAPTER_NAME` (a case-insensitive substring of
//! the adapter name) and `WGPU_POWER_PREF` (`low` | `high`). Without
//! `WGPU_ADAPTER_NAME` the best adapter wins: discrete, then integrated,
//! virtual, other and last software (CPU) adapters; native backends (Vulkan,
//! Metal, DX12) before GL. [`AdapterPolicy::HardwareOnly`] refuses software
//! rasterisers (lavapipe / llvmpipe / SwiftShader); adapters without compute
//! shaders are always refused. The device is opened with the **adapter's own
//! limits** (wgpu's defaults cap buffers at 256 MiB) and no optional features.
//! wgpu's check of indirect dispatch arguments is off unless
//! `WGPU_VALIDATION_INDIRECT_CALL` is set (see `without_indirect_validation`).
//!
//! # Errors instead of panics
//!
//! wgpu reports validation errors through error scopes; every call that can
//! fail validation (buffer creation, shader and pipeline creation, bind
//! groups, encoding, submission) runs inside validation, out-of-memory and
//! internal error scopes, and the captured message — for WGSL, naga's error
//! text with the offending source line — comes back as a [`GpuError`]. Errors
//! that escape every scope (none are expected) are logged through `tracing`
//! instead of wgpu's default panic.
//!
//! # Ordering and batching
//!
//! Dispatches are encoded and validated at once, one command buffer each, but
//! submitted in batches: the queued command buffers are submitted before any
//! `write_buffer` (wgpu applies queue writes at the *next* submission, so
//! this keeps writes after earlier dispatches), before any `read_buffer`
//! (together with the copy into the staging buffer), and whenever
//! [`MAX_QUEUED_DISPATCHES`] are waiting. Every call is therefore ordered
//! after all earlier calls, as the trait promises.

use std::collections::HashMap;
use std::fmt;
use std::hash::{Hash, Hasher};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, RwLock};

use voxflex_core::error::GpuError;
use voxflex_core::gpu::{BufferBinding, BufferId, GpuLimits, GpuService, PipelineId};

/// Dispatches queued (encoded but not yet submitted) before a submission is
/// forced.
pub const MAX_QUEUED_DISPATCHES: usize = 32;

/// Which adapters [`WgpuService::new`] accepts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum AdapterPolicy {
    /// Only hardware GPUs: software rasterisers (device type `Cpu`, or a name
    /// containing "llvmpipe", "lavapipe" or "SwiftShader") are refused. This
    /// is what `backend = "auto"` uses.
    HardwareOnly,
    /// Any adapter with compute shaders, software ones included (lavapipe is
    /// how CI checks every WGSL kernel). This is what `backend = "gpu"` uses.
    AnyAdapter,
}

impl fmt::Display for AdapterPolicy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::HardwareOnly => "a hardware GPU (software adapters refused)",
            Self::AnyAdapter => "any GPU adapter, software ones included",
        })
    }
}

/// Opening the GPU context failed.
#[derive(Debug, thiserror::Error)]
pub enum GpuContextError {
    /// wgpu enumerated no adapter at all.
    #[error(
        "no GPU adapter was found (wgpu backends searched: {backends}); install \
         mesa-vulkan-drivers for the software lavapipe adapter, or set WGPU_BACKEND"
    )]
    NoAdapter {
        /// The backends that were searched (from `WGPU_BACKEND`, else all).
        backends: String,
    },
    /// Adapters exist but the policy refused every one.
    #[error("no adapter is acceptable as {policy}; found: {refused}")]
    NoneSuitable {
        /// The policy that refused them.
        policy: AdapterPolicy,
        /// Each adapter found and why it was refused, `; `-separated.
        refused: String,
    },
    /// `WGPU_ADAPTER_NAME` is set but matches no adapter.
    #[error(
        "WGPU_ADAPTER_NAME={wanted:?} matches no adapter; available: {available} \
         (unset it, or give part of one of these names)"
    )]
    AdapterNameNotFound {
        /// The requested name.
        wanted: String,
        /// The adapters that exist.
        available: String,
    },
    /// The adapter named by `WGPU_ADAPTER_NAME` was refused by the policy.
    #[error("WGPU_ADAPTER_NAME={wanted:?} selects {adapter}, which is refused: {reason}")]
    NamedAdapterRefused {
        /// The requested name.
        wanted: String,
        /// The adapter it selected.
        adapter: String,
        /// Why the policy refused it.
        reason: String,
    },
    /// The adapter was chosen but opening a device on it failed.
    #[error("could not open a device on {adapter}: {source}")]
    RequestDevice {
        /// The adapter.
        adapter: String,
        /// wgpu's error.
        #[source]
        source: wgpu::RequestDeviceError,
    },
}

impl GpuContextError {
    /// Whether the error means "there is no usable adapter" (as opposed to an
    /// adapter that failed to open).
    pub fn is_no_adapter(&self) -> bool {
        matches!(self, Self::NoAdapter { .. } | Self::NoneSuitable { .. })
    }
}

/// What adapter a [`WgpuService`] runs on, for logs and reports.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct AdapterSummary {
    /// Adapter name, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)".
    pub name: String,
    /// wgpu backend, e.g. "vulkan".
    pub backend: String,
    /// Device type, e.g. "DiscreteGpu" or "Cpu".
    pub device_type: String,
    /// Driver name and version, e.g. "llvmpipe (Mesa 22.3.6)".
    pub driver: String,
    /// Whether this is a software rasteriser (lavapipe, llvmpipe, SwiftShader).
    pub software: bool,
}

impl AdapterSummary {
    /// The summary of wgpu's description of an adapter (`software` set as
    /// [`AdapterPolicy::HardwareOnly`] decides: device type `Cpu`, or a
    /// name or driver naming llvmpipe, lavapipe, SwiftShader or WARP).
    pub fn from_info(info: &wgpu::AdapterInfo) -> Self {
        let driver = match (info.driver.is_empty(), info.driver_info.is_empty()) {
            (false, false) => format!("{} ({})", info.driver, info.driver_info),
            (false, true) => info.driver.clone(),
            (true, false) => info.driver_info.clone(),
            (true, true) => String::from("unknown driver"),
        };
        Self {
            name: info.name.clone(),
            backend: info.backend.to_str().to_owned(),
            device_type: format!("{:?}", info.device_type),
            driver,
            software: software_reason(info).is_some(),
        }
    }
}

impl fmt::Display for AdapterSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} [{}, {}, {}]",
            self.name, self.backend, self.device_type, self.driver
        )
    }
}

/// Counters of a [`WgpuService`]'s device (shared by all its views).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct GpuStats {
    /// Buffers currently alive.
    pub live_buffers: u64,
    /// Bytes in buffers currently alive.
    pub live_bytes: u64,
    /// Compute pipelines compiled so far (cache misses).
    pub pipelines_compiled: u64,
    /// Dispatches encoded so far.
    pub dispatches: u64,
    /// Queue submissions so far.
    pub submissions: u64,
}

/// Names an adapter for messages: "name [backend, type]".
fn describe(info: &wgpu::AdapterInfo) -> String {
    format!(
        "{} [{}, {:?}]",
        info.name,
        info.backend.to_str(),
        info.device_type
    )
}

/// Why an adapter counts as a software rasteriser, or `None` for hardware.
fn software_reason(info: &wgpu::AdapterInfo) -> Option<String> {
    if info.device_type == wgpu::DeviceType::Cpu {
        return Some("software rasteriser (device type Cpu)".to_owned());
    }
    let hay = format!("{} {} {}", info.name, info.driver, info.driver_info).to_lowercase();
    // WARP, Direct3D's rasteriser, is "Microsoft Basic Render Driver".
    [
        "llvmpipe",
        "lavapipe",
        "swiftshader",
        "microsoft basic render",
    ]
    .into_iter()
    .find(|s| hay.contains(s))
    .map(|s| format!("software rasteriser (name mentions {s})"))
}

/// Why `policy` refuses an adapter, or `None` when it is acceptable.
fn refusal(adapter: &wgpu::Adapter, policy: AdapterPolicy) -> Option<String> {
    let caps = adapter.get_downlevel_capabilities();
    if !caps.flags.contains(wgpu::DownlevelFlags::COMPUTE_SHADERS) {
        return Some("no compute shader support".to_owned());
    }
    match policy {
        AdapterPolicy::HardwareOnly => software_reason(&adapter.get_info()),
        AdapterPolicy::AnyAdapter => None,
    }
}

/// Ranks an adapter: lower is better.
fn rank(info: &wgpu::AdapterInfo, power: Option<wgpu::PowerPreference>) -> (u8, u8) {
    let low_power = power == Some(wgpu::PowerPreference::LowPower);
    let ty = match info.device_type {
        wgpu::DeviceType::DiscreteGpu if low_power => 1,
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu if low_power => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    };
    let ty = if ty < 4 && software_reason(info).is_some() {
        4
    } else {
        ty
    };
    let backend = match info.backend {
        wgpu::Backend::Vulkan | wgpu::Backend::Metal | wgpu::Backend::Dx12 => 0,
        wgpu::Backend::Gl => 1,
        _ => 2,
    };
    (ty, backend)
}

/// Picks the adapter per `WGPU_ADAPTER_NAME` / ranking and `policy`.
fn choose_adapter(
    instance: &wgpu::Instance,
    backends: wgpu::Backends,
    policy: AdapterPolicy,
) -> Result<wgpu::Adapter, GpuContextError> {
    let adapters = pollster::block_on(instance.enumerate_adapters(backends));
    if adapters.is_empty() {
        return Err(GpuContextError::NoAdapter {
            backends: format!("{backends:?}"),
        });
    }
    let list = |adapters: &[wgpu::Adapter]| {
        adapters
            .iter()
            .map(|a| describe(&a.get_info()))
            .collect::<Vec<_>>()
            .join("; ")
    };

    if let Some(wanted) = std::env::var("WGPU_ADAPTER_NAME")
        .ok()
        .filter(|w| !w.trim().is_empty())
    {
        let needle = wanted.to_lowercase();
        let mut matching: Vec<wgpu::Adapter> = adapters
            .iter()
            .filter(|a| a.get_info().name.to_lowercase().contains(&needle))
            .cloned()
            .collect();
        if matching.is_empty() {
            return Err(GpuContextError::AdapterNameNotFound {
                wanted,
                available: list(&adapters),
            });
        }
        let power = wgpu::PowerPreference::from_env();
        matching.sort_by_key(|a| rank(&a.get_info(), power));
        let mut first_refusal = None;
        for adapter in matching {
            match refusal(&adapter, policy) {
                None => return Ok(adapter),
                Some(reason) => {
                    first_refusal.get_or_insert((describe(&adapter.get_info()), reason));
                }
            }
        }
        let (adapter, reason) = first_refusal.unwrap_or_default();
        return Err(GpuContextError::NamedAdapterRefused {
            wanted,
            adapter,
            reason: format!("{reason}; {policy} is required"),
        });
    }

    let power = wgpu::PowerPreference::from_env();
    let mut refused = Vec::new();
    let mut ok = Vec::new();
    for adapter in adapters {
        match refusal(&adapter, policy) {
            None => ok.push(adapter),
            Some(reason) => refused.push(format!(
                "{} refused: {reason}",
                describe(&adapter.get_info())
            )),
        }
    }
    ok.sort_by_key(|a| rank(&a.get_info(), power));
    ok.into_iter()
        .next()
        .ok_or_else(|| GpuContextError::NoneSuitable {
            policy,
            refused: refused.join("; "),
        })
}

/// Turns a captured wgpu error into a [`GpuError`] naming the operation.
fn gpu_error(what: &str, error: wgpu::Error) -> GpuError {
    let detail = match &error {
        wgpu::Error::Validation { description, .. } | wgpu::Error::Internal { description, .. } => {
            description.clone()
        }
        wgpu::Error::OutOfMemory { source } => format!("out of GPU memory: {source}"),
    };
    GpuError(format!("{what}: {}", detail.trim_end()))
}

/// A compiled pipeline and its group-0 layout (absent when the entry point
/// binds nothing).
struct Pipeline {
    wgsl_hash: u64,
    wgsl: Box<str>,
    entry: Box<str>,
    pipeline: wgpu::ComputePipeline,
    layout: Option<wgpu::BindGroupLayout>,
}

/// State shared by every view of one device.
struct Shared {
    adapter_info: wgpu::AdapterInfo,
    summary: AdapterSummary,
    device_limits: wgpu::Limits,
    device: wgpu::Device,
    queue: wgpu::Queue,
    buffers: RwLock<HashMap<BufferId, wgpu::Buffer>>,
    pipelines: RwLock<HashMap<PipelineId, Arc<Pipeline>>>,
    /// `hash(wgsl, entry)` → pipelines with that hash (collisions resolved by
    /// comparing the source).
    pipeline_index: RwLock<HashMap<u64, Vec<PipelineId>>>,
    /// Encoded, validated, not yet submitted dispatches. Held while a write
    /// or a read-back submits, so calls from several threads stay ordered.
    queued: Mutex<Vec<wgpu::CommandBuffer>>,
    next_id: AtomicU64,
    live_bytes: AtomicU64,
    pipelines_compiled: AtomicU64,
    dispatches: AtomicU64,
    submissions: AtomicU64,
    /// Kept alive as long as the device (declared last: dropped last);
    /// `None` for a device opened by someone else ([`WgpuService::from_device`]),
    /// who keeps its instance.
    _instance: Option<wgpu::Instance>,
}

/// [`GpuService`] over one wgpu device: the host's GPU context.
///
/// Cheap to share (`Arc<WgpuService>` or [`WgpuService::clone`], which shares
/// the device, buffers and pipeline cache) and safe to call from any thread.
///
/// Buffers are created with usage `STORAGE | UNIFORM | COPY_SRC | COPY_DST`
/// and zero-filled; their size is rounded up to a multiple of 4 bytes (at
/// least 4). Reads and writes take byte offsets that are multiples of 4 and
/// any length.
#[derive(Clone)]
pub struct WgpuService {
    shared: Arc<Shared>,
    /// Pretended `max_storage_buffer_binding_size` (tests of slab splitting).
    binding_limit_override: Option<u64>,
}

impl fmt::Debug for WgpuService {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("WgpuService")
            .field("adapter", &self.shared.summary)
            .field("binding_limit_override", &self.binding_limit_override)
            .finish_non_exhaustive()
    }
}

/// `flags` without wgpu's validation of indirect dispatch arguments,
/// unless `WGPU_VALIDATION_INDIRECT_CALL` asks for it (set, not "0").
///
/// The validation turns each indirect dispatch into two (a pass that
/// checks the arguments first): measured on lavapipe, 119–134 µs per
/// indirect dispatch against 48–64 µs direct, and 58 µs without it
/// (`cargo run --release -p voxflex-runtime --example dispatch_cost`).
/// Every indirect dispatch voxflex makes reads counts its own kernels
/// wrote, clamped to the device's limit the way `workgroups_1d` folds
/// them (ChainMail's block lists, tested with a limit of 7), and its
/// kernels never read `num_workgroups` there (D3D12 does not report it
/// for unvalidated indirect dispatches). [`GpuService::dispatch_indirect`]
/// says counts past the limit are the writer's error.
fn without_indirect_validation(flags: wgpu::InstanceFlags) -> wgpu::InstanceFlags {
    let asked = std::env::var("WGPU_VALIDATION_INDIRECT_CALL").is_ok_and(|v| v != "0");
    if asked {
        flags | wgpu::InstanceFlags::VALIDATION_INDIRECT_CALL
    } else {
        flags - wgpu::InstanceFlags::VALIDATION_INDIRECT_CALL
    }
}

impl WgpuService {
    /// Opens the device on the best adapter `policy` accepts (see the
    /// module docs for the order and the environment variables obeyed).
    pub fn new(policy: AdapterPolicy) -> Result<Self, GpuContextError> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        desc.flags = without_indirect_validation(desc.flags);
        let backends = desc.backends;
        let instance = wgpu::Instance::new(desc);
        let adapter = choose_adapter(&instance, backends, policy)?;
        let adapter_info = adapter.get_info();
        let required_limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("voxflex"),
            required_features: wgpu::Features::empty(),
            required_limits: required_limits.clone(),
            ..Default::default()
        }))
        .map_err(|source| GpuContextError::RequestDevice {
            adapter: describe(&adapter_info),
            source,
        })?;
        device.on_uncaptured_error(Arc::new(|error: wgpu::Error| {
            tracing::error!(target: "voxflex::gpu", "uncaptured wgpu error: {error}");
        }));
        Ok(Self::assemble(adapter_info, device, queue, Some(instance)))
    }

    /// The service over a device and queue someone else opened — a desktop
    /// front end's (eframe's `RenderState`), so that voxflex's kernels and
    /// the UI's rendering share one device and images need no read-back.
    /// `adapter_info` describes the device's adapter. The device keeps the
    /// limits and the uncaptured-error handler its owner gave it (voxflex
    /// needs no optional feature; its calls run inside error scopes, so
    /// their errors still come back as [`GpuError`]s); the owner keeps the
    /// instance alive.
    pub fn from_device(
        adapter_info: wgpu::AdapterInfo,
        device: wgpu::Device,
        queue: wgpu::Queue,
    ) -> Self {
        Self::assemble(adapter_info, device, queue, None)
    }

    fn assemble(
        adapter_info: wgpu::AdapterInfo,
        device: wgpu::Device,
        queue: wgpu::Queue,
        instance: Option<wgpu::Instance>,
    ) -> Self {
        let summary = AdapterSummary::from_info(&adapter_info);
        let device_limits = device.limits();
        tracing::info!(
            target: "voxflex::gpu",
            adapter = %summary,
            max_storage_buffer_binding_size = device_limits.max_storage_buffer_binding_size,
            max_buffer_size = device_limits.max_buffer_size,
            shared = instance.is_none(),
            "GPU context opened"
        );
        Self {
            shared: Arc::new(Shared {
                adapter_info,
                summary,
                device_limits,
                device,
                queue,
                buffers: RwLock::default(),
                pipelines: RwLock::default(),
                pipeline_index: RwLock::default(),
                queued: Mutex::default(),
                next_id: AtomicU64::new(1),
                live_bytes: AtomicU64::new(0),
                pipelines_compiled: AtomicU64::new(0),
                dispatches: AtomicU64::new(0),
                submissions: AtomicU64::new(0),
                _instance: instance,
            }),
            binding_limit_override: None,
        }
    }

    /// A view of the same device (same buffers, same pipeline cache) that
    /// pretends `max_storage_buffer_binding_size` is `bytes` (when smaller
    /// than the real limit): [`GpuService::limits`] reports it and
    /// [`GpuService::dispatch`] refuses larger storage bindings. For testing
    /// slab-splitting code on adapters with large limits.
    pub fn with_binding_limit_override(&self, bytes: u64) -> Self {
        Self {
            shared: Arc::clone(&self.shared),
            binding_limit_override: Some(bytes),
        }
    }

    /// The adapter this service runs on.
    pub fn info(&self) -> AdapterSummary {
        self.shared.summary.clone()
    }

    /// wgpu's full description of the adapter.
    pub fn adapter_info(&self) -> &wgpu::AdapterInfo {
        &self.shared.adapter_info
    }

    /// The device's full wgpu limits (the adapter's own; no override applied).
    pub fn wgpu_limits(&self) -> &wgpu::Limits {
        &self.shared.device_limits
    }

    /// Counters of the device (shared by all views).
    pub fn stats(&self) -> GpuStats {
        let s = &self.shared;
        GpuStats {
            live_buffers: s.buffers.read().expect("buffer map poisoned").len() as u64,
            live_bytes: s.live_bytes.load(Ordering::Relaxed),
            pipelines_compiled: s.pipelines_compiled.load(Ordering::Relaxed),
            dispatches: s.dispatches.load(Ordering::Relaxed),
            submissions: s.submissions.load(Ordering::Relaxed),
        }
    }

    /// The wgpu buffer behind `id`, for the host's front ends only (the
    /// viewer copies a rendered image from it into the texture it draws;
    /// plugins see [`BufferId`]s and never the wgpu objects). The handle
    /// keeps the buffer alive after [`GpuService::destroy_buffer`]. Work on
    /// it submitted by the caller on this device's queue runs after every
    /// call to this service that returned before the submission, once
    /// [`Self::flush`] has submitted the queued dispatches.
    pub fn raw_buffer(&self, id: BufferId) -> Result<wgpu::Buffer, GpuError> {
        self.buffer(id)
    }

    /// Whether `other` is a view of the same device (so buffers of one are
    /// buffers of the other).
    pub fn same_device(&self, other: &WgpuService) -> bool {
        Arc::ptr_eq(&self.shared, &other.shared)
    }

    /// Submits every queued dispatch now (reads and writes do this anyway).
    pub fn flush(&self) -> Result<(), GpuError> {
        let mut queued = self.shared.queued.lock().expect("dispatch queue poisoned");
        self.submit_locked(&mut queued, None).map(|_| ())
    }

    /// Runs `f` inside validation, out-of-memory and internal error scopes
    /// and returns its result, or the first error captured, prefixed `what`.
    fn scoped<R>(
        &self,
        what: impl FnOnce() -> String,
        f: impl FnOnce() -> R,
    ) -> Result<R, GpuError> {
        let device = &self.shared.device;
        let internal = device.push_error_scope(wgpu::ErrorFilter::Internal);
        let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let out = f();
        let errors = [
            pollster::block_on(validation.pop()),
            pollster::block_on(oom.pop()),
            pollster::block_on(internal.pop()),
        ];
        match errors.into_iter().flatten().next() {
            None => Ok(out),
            Some(error) => Err(gpu_error(&what(), error)),
        }
    }

    /// Submits the queued command buffers plus `extra`, inside error scopes.
    /// The caller holds the queue lock.
    fn submit_locked(
        &self,
        queued: &mut Vec<wgpu::CommandBuffer>,
        extra: Option<wgpu::CommandBuffer>,
    ) -> Result<Option<wgpu::SubmissionIndex>, GpuError> {
        if queued.is_empty() && extra.is_none() {
            return Ok(None);
        }
        let n = queued.len();
        let buffers: Vec<_> = queued.drain(..).chain(extra).collect();
        self.shared.submissions.fetch_add(1, Ordering::Relaxed);
        self.scoped(
            || format!("submitting {n} queued dispatch(es)"),
            || self.shared.queue.submit(buffers),
        )
        .map(Some)
    }

    fn buffer(&self, id: BufferId) -> Result<wgpu::Buffer, GpuError> {
        self.shared
            .buffers
            .read()
            .expect("buffer map poisoned")
            .get(&id)
            .cloned()
            .ok_or_else(|| {
                GpuError(format!(
                    "unknown buffer id {} (never created on this device, or destroyed)",
                    id.0
                ))
            })
    }

    fn pipeline(&self, id: PipelineId) -> Result<Arc<Pipeline>, GpuError> {
        self.shared
            .pipelines
            .read()
            .expect("pipeline map poisoned")
            .get(&id)
            .cloned()
            .ok_or_else(|| GpuError(format!("unknown pipeline id {}", id.0)))
    }

    fn cached_pipeline(&self, hash: u64, wgsl: &str, entry: &str) -> Option<PipelineId> {
        let index = self
            .shared
            .pipeline_index
            .read()
            .expect("pipeline index poisoned");
        let pipelines = self.shared.pipelines.read().expect("pipeline map poisoned");
        index.get(&hash)?.iter().copied().find(|id| {
            pipelines
                .get(id)
                .is_some_and(|p| p.wgsl_hash == hash && &*p.wgsl == wgsl && &*p.entry == entry)
        })
    }

    /// Blocking read of `len` bytes (a multiple of 4) at `offset`.
    fn read_aligned(
        &self,
        buffer: &wgpu::Buffer,
        offset: u64,
        out: &mut [u8],
    ) -> Result<(), GpuError> {
        let device = &self.shared.device;
        let copy_len = (out.len() as u64).next_multiple_of(4);
        let staging = self.scoped(
            || format!("creating a {copy_len}-byte read-back staging buffer"),
            || {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("voxflex read-back"),
                    size: copy_len,
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            },
        )?;
        let copy = self.scoped(
            || "encoding the read-back copy".to_owned(),
            || {
                let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("voxflex read-back"),
                });
                encoder.copy_buffer_to_buffer(buffer, offset, &staging, 0, copy_len);
                encoder.finish()
            },
        )?;
        let submission = {
            let mut queued = self.shared.queued.lock().expect("dispatch queue poisoned");
            self.submit_locked(&mut queued, Some(copy))?
        };
        let (tx, rx) = std::sync::mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, .., move |result| {
            // The receiver only disappears if this call already returned.
            let _ = tx.send(result);
        });
        device
            .poll(wgpu::PollType::Wait {
                submission_index: submission,
                timeout: None,
            })
            .map_err(|e| GpuError(format!("waiting for the GPU: {e}")))?;
        // Another thread's poll may have run the callback; either way it has
        // run once our submission completed, or it will on the next poll.
        let result = match rx.try_recv() {
            Ok(r) => r,
            Err(_) => {
                device
                    .poll(wgpu::PollType::wait_indefinitely())
                    .map_err(|e| GpuError(format!("waiting for the GPU: {e}")))?;
                rx.recv()
                    .map_err(|_| GpuError("read-back mapping callback was dropped".to_owned()))?
            }
        };
        result.map_err(|e| GpuError(format!("mapping the read-back buffer failed: {e}")))?;
        {
            let view = staging
                .get_mapped_range(..)
                .map_err(|e| GpuError(format!("reading the mapped read-back buffer: {e}")))?;
            out.copy_from_slice(&view[..out.len()]);
        }
        staging.unmap();
        Ok(())
    }
}

impl Drop for Shared {
    fn drop(&mut self) {
        let queued = std::mem::take(self.queued.get_mut().unwrap_or_else(|p| p.into_inner()));
        if !queued.is_empty() {
            self.queue.submit(queued);
        }
    }
}

impl WgpuService {
    /// Binds `bindings` for `pipe`, encodes one compute pass in which
    /// `run` records the dispatch, and queues it (`what` names the
    /// workgroup counts in errors).
    fn encode_dispatch(
        &self,
        pipe: &Pipeline,
        bindings: &[BufferBinding],
        what: &str,
        run: impl FnOnce(&mut wgpu::ComputePass<'_>),
    ) -> Result<(), GpuError> {
        let mut resolved = Vec::with_capacity(bindings.len());
        for b in bindings {
            let buffer = self.buffer(b.buffer)?;
            let total = buffer.size();
            let size = if b.size == 0 {
                total.saturating_sub(b.offset)
            } else {
                b.size
            };
            if b.offset.checked_add(size).is_none_or(|end| end > total) || size == 0 {
                return Err(GpuError(format!(
                    "`{}` @binding({}): range {}..{} does not fit buffer {} of {total} bytes",
                    pipe.entry,
                    b.binding,
                    b.offset,
                    b.offset.saturating_add(size),
                    b.buffer.0
                )));
            }
            if let Some(limit) = self.binding_limit_override
                && size > limit
            {
                return Err(GpuError(format!(
                    "`{}` @binding({}): binds {size} bytes but max_storage_buffer_binding_size is \
                     {limit} (override); split the data into slabs",
                    pipe.entry, b.binding
                )));
            }
            resolved.push((b.binding, buffer, b.offset, size));
        }

        let device = &self.shared.device;
        let bind_group = match (&pipe.layout, resolved.is_empty()) {
            (_, true) => None,
            (None, false) => {
                return Err(GpuError(format!(
                    "`{}` binds no resources, but {} binding(s) were given",
                    pipe.entry,
                    resolved.len()
                )));
            }
            (Some(layout), false) => Some(self.scoped(
                || format!("binding buffers for `{}`", pipe.entry),
                || {
                    let entries: Vec<wgpu::BindGroupEntry<'_>> = resolved
                        .iter()
                        .map(|(binding, buffer, offset, size)| wgpu::BindGroupEntry {
                            binding: *binding,
                            resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                                buffer,
                                offset: *offset,
                                size: wgpu::BufferSize::new(*size),
                            }),
                        })
                        .collect();
                    device.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some(&pipe.entry),
                        layout,
                        entries: &entries,
                    })
                },
            )?),
        };
        let commands = self.scoped(
            || format!("encoding a dispatch of `{}` {what}", pipe.entry),
            || {
                let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some(&pipe.entry),
                });
                {
                    let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                        label: Some(&pipe.entry),
                        timestamp_writes: None,
                    });
                    pass.set_pipeline(&pipe.pipeline);
                    if let Some(group) = &bind_group {
                        pass.set_bind_group(0, group, &[]);
                    }
                    run(&mut pass);
                }
                encoder.finish()
            },
        )?;
        self.shared.dispatches.fetch_add(1, Ordering::Relaxed);
        let mut queued = self.shared.queued.lock().expect("dispatch queue poisoned");
        queued.push(commands);
        if queued.len() >= MAX_QUEUED_DISPATCHES {
            self.submit_locked(&mut queued, None)?;
        }
        Ok(())
    }
}

impl GpuService for WgpuService {
    fn adapter_description(&self) -> String {
        self.shared.summary.to_string()
    }

    fn limits(&self) -> GpuLimits {
        let l = &self.shared.device_limits;
        let binding = match self.binding_limit_override {
            Some(b) => b.min(l.max_storage_buffer_binding_size),
            None => l.max_storage_buffer_binding_size,
        };
        GpuLimits {
            max_storage_buffer_binding_size: binding,
            max_buffer_size: l.max_buffer_size,
            max_compute_workgroups_per_dimension: l.max_compute_workgroups_per_dimension,
            min_storage_buffer_offset_alignment: l.min_storage_buffer_offset_alignment,
        }
    }

    fn create_buffer(&self, size_bytes: u64, label: &str) -> Result<BufferId, GpuError> {
        let size = size_bytes.max(4).next_multiple_of(4);
        let max = self.shared.device_limits.max_buffer_size;
        if size > max {
            return Err(GpuError(format!(
                "buffer {label:?} of {size_bytes} bytes exceeds the device's max_buffer_size \
                 of {max} bytes; split the data"
            )));
        }
        let buffer = self.scoped(
            || format!("creating buffer {label:?} of {size} bytes"),
            || {
                self.shared.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size,
                    usage: wgpu::BufferUsages::STORAGE
                        | wgpu::BufferUsages::UNIFORM
                        | wgpu::BufferUsages::COPY_SRC
                        | wgpu::BufferUsages::COPY_DST
                        | wgpu::BufferUsages::INDIRECT,
                    mapped_at_creation: false,
                })
            },
        )?;
        let id = BufferId(self.shared.next_id.fetch_add(1, Ordering::Relaxed));
        self.shared.live_bytes.fetch_add(size, Ordering::Relaxed);
        self.shared
            .buffers
            .write()
            .expect("buffer map poisoned")
            .insert(id, buffer);
        Ok(id)
    }

    fn destroy_buffer(&self, id: BufferId) {
        // Dropping our handle is enough: queued or in-flight command buffers
        // keep the buffer alive until they complete.
        let removed = self
            .shared
            .buffers
            .write()
            .expect("buffer map poisoned")
            .remove(&id);
        if let Some(buffer) = removed {
            self.shared
                .live_bytes
                .fetch_sub(buffer.size(), Ordering::Relaxed);
        }
    }

    fn buffer_size(&self, id: BufferId) -> Result<u64, GpuError> {
        Ok(self.buffer(id)?.size())
    }

    fn write_buffer(&self, id: BufferId, offset: u64, bytes: &[u8]) -> Result<(), GpuError> {
        let buffer = self.buffer(id)?;
        let len = bytes.len() as u64;
        if !offset.is_multiple_of(4) {
            return Err(GpuError(format!(
                "write to buffer {} at offset {offset}: offsets must be multiples of 4",
                id.0
            )));
        }
        if offset
            .checked_add(len)
            .is_none_or(|end| end > buffer.size())
        {
            return Err(GpuError(format!(
                "write of {len} bytes at offset {offset} overruns buffer {} of {} bytes",
                id.0,
                buffer.size()
            )));
        }
        if bytes.is_empty() {
            return Ok(());
        }
        let aligned = bytes.len() / 4 * 4;
        let tail = &bytes[aligned..];
        // wgpu writes whole 4-byte words: merge a ragged tail with the bytes
        // already in the buffer so nothing past `offset + len` changes.
        let tail_word = if tail.is_empty() {
            None
        } else {
            let mut word = [0u8; 4];
            self.read_aligned(&buffer, offset + aligned as u64, &mut word)?;
            word[..tail.len()].copy_from_slice(tail);
            Some(word)
        };
        let mut queued = self.shared.queued.lock().expect("dispatch queue poisoned");
        self.submit_locked(&mut queued, None)?;
        self.scoped(
            || format!("writing {len} bytes to buffer {} at offset {offset}", id.0),
            || {
                if aligned > 0 {
                    self.shared
                        .queue
                        .write_buffer(&buffer, offset, &bytes[..aligned]);
                }
                if let Some(word) = tail_word {
                    self.shared
                        .queue
                        .write_buffer(&buffer, offset + aligned as u64, &word);
                }
            },
        )
    }

    fn read_buffer(&self, id: BufferId, offset: u64, out: &mut [u8]) -> Result<(), GpuError> {
        let buffer = self.buffer(id)?;
        let len = out.len() as u64;
        if !offset.is_multiple_of(4) {
            return Err(GpuError(format!(
                "read from buffer {} at offset {offset}: offsets must be multiples of 4",
                id.0
            )));
        }
        if offset
            .checked_add(len)
            .is_none_or(|end| end > buffer.size())
        {
            return Err(GpuError(format!(
                "read of {len} bytes at offset {offset} overruns buffer {} of {} bytes",
                id.0,
                buffer.size()
            )));
        }
        if out.is_empty() {
            return Ok(());
        }
        self.read_aligned(&buffer, offset, out)
    }

    fn compile(&self, wgsl: &str, entry_point: &str) -> Result<PipelineId, GpuError> {
        let hash = {
            let mut h = std::collections::hash_map::DefaultHasher::new();
            (wgsl, entry_point).hash(&mut h);
            h.finish()
        };
        if let Some(id) = self.cached_pipeline(hash, wgsl, entry_point) {
            return Ok(id);
        }
        let device = &self.shared.device;
        let label = format!("voxflex {entry_point} {hash:016x}");
        let module = self.scoped(
            || format!("compiling WGSL (entry point `{entry_point}`)"),
            || {
                device.create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some(&label),
                    source: wgpu::ShaderSource::Wgsl(wgsl.into()),
                })
            },
        )?;
        let pipeline = self.scoped(
            || format!("creating the compute pipeline for entry point `{entry_point}`"),
            || {
                device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(&label),
                    layout: None,
                    module: &module,
                    entry_point: Some(entry_point),
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                    cache: None,
                })
            },
        )?;
        // An entry point that binds nothing has no group 0.
        let layout = self
            .scoped(String::new, || pipeline.get_bind_group_layout(0))
            .ok();
        self.shared
            .pipelines_compiled
            .fetch_add(1, Ordering::Relaxed);

        let mut index = self
            .shared
            .pipeline_index
            .write()
            .expect("pipeline index poisoned");
        // Another thread may have compiled the same source meanwhile.
        let mut pipelines = self
            .shared
            .pipelines
            .write()
            .expect("pipeline map poisoned");
        if let Some(id) = index.get(&hash).and_then(|ids| {
            ids.iter().copied().find(|id| {
                pipelines
                    .get(id)
                    .is_some_and(|p| &*p.wgsl == wgsl && &*p.entry == entry_point)
            })
        }) {
            return Ok(id);
        }
        let id = PipelineId(self.shared.next_id.fetch_add(1, Ordering::Relaxed));
        pipelines.insert(
            id,
            Arc::new(Pipeline {
                wgsl_hash: hash,
                wgsl: wgsl.into(),
                entry: entry_point.into(),
                pipeline,
                layout,
            }),
        );
        index.entry(hash).or_default().push(id);
        Ok(id)
    }

    fn dispatch(
        &self,
        pipeline: PipelineId,
        bindings: &[BufferBinding],
        workgroups: [u32; 3],
    ) -> Result<(), GpuError> {
        let pipe = self.pipeline(pipeline)?;
        let max_groups = self.limits().max_compute_workgroups_per_dimension;
        if workgroups.iter().any(|&n| n > max_groups) {
            return Err(GpuError(format!(
                "dispatch of `{}` with workgroups {workgroups:?}: each dimension is limited to \
                 {max_groups}; fold the work into 3-D (voxflex_core::gpu::workgroups_1d)",
                pipe.entry
            )));
        }
        self.encode_dispatch(&pipe, bindings, &format!("{workgroups:?}"), |pass| {
            pass.dispatch_workgroups(workgroups[0], workgroups[1], workgroups[2])
        })
    }

    fn dispatch_indirect(
        &self,
        pipeline: PipelineId,
        bindings: &[BufferBinding],
        args: BufferId,
        offset: u64,
    ) -> Result<(), GpuError> {
        let pipe = self.pipeline(pipeline)?;
        let buffer = self.buffer(args)?;
        if !offset.is_multiple_of(4) || offset.checked_add(12).is_none_or(|e| e > buffer.size()) {
            return Err(GpuError(format!(
                "indirect dispatch of `{}`: 12 bytes of arguments at offset {offset} do not fit \
                 buffer {} of {} bytes at a multiple of 4",
                pipe.entry,
                args.0,
                buffer.size()
            )));
        }
        let what = format!("indirect (buffer {} at {offset})", args.0);
        self.encode_dispatch(&pipe, bindings, &what, |pass| {
            pass.dispatch_workgroups_indirect(&buffer, offset)
        })
    }
}

/// Shared GPU test policy for every crate of the workspace.
///
/// Not part of the stable API.
#[doc(hidden)]
pub mod testing {
    use super::{AdapterPolicy, WgpuService};
    use std::io::Write;
    use std::sync::{Arc, OnceLock};

    /// Whether this run is CI (`CI=true` or `CI=1`), where a missing GPU
    /// adapter is a failure instead of a skip.
    pub fn is_ci() -> bool {
        std::env::var("CI").is_ok_and(|v| v.eq_ignore_ascii_case("true") || v == "1")
    }

    /// The GPU for tests: one shared [`WgpuService`] on any adapter
    /// (lavapipe included), opened once per test process.
    ///
    /// When no adapter exists it prints `SKIPPED: no GPU adapter` to stderr
    /// and returns `None` — unless `CI=true`, where it panics, so CI can never
    /// pass GPU tests by skipping them. Sets `XDG_RUNTIME_DIR` to a private
    /// temporary directory first if it is unset (silences EGL/Wayland noise
    /// from the GL backend).
    #[track_caller]
    pub fn test_gpu() -> Option<Arc<WgpuService>> {
        static GPU: OnceLock<Result<Arc<WgpuService>, String>> = OnceLock::new();
        let gpu = GPU.get_or_init(|| {
            ensure_xdg_runtime_dir();
            WgpuService::new(AdapterPolicy::AnyAdapter)
                .map(Arc::new)
                .map_err(|e| e.to_string())
        });
        match gpu {
            Ok(gpu) => Some(Arc::clone(gpu)),
            Err(e) if is_ci() => panic!(
                "CI=true but no GPU adapter could be opened: {e}\n\
                 (CI must run the GPU tests; install mesa-vulkan-drivers and libvulkan1)"
            ),
            Err(e) => {
                // Straight to the process's stderr: libtest captures
                // `eprintln!` of passing tests, and a skip must be seen.
                let _ = writeln!(
                    std::io::stderr(),
                    "\n*** SKIPPED: no GPU adapter ({}): {e} ***\n",
                    std::panic::Location::caller()
                );
                None
            }
        }
    }

    /// [`test_gpu`] viewed through
    /// [`WgpuService::with_binding_limit_override`]`(bytes)`.
    #[track_caller]
    pub fn test_gpu_with_binding_limit(bytes: u64) -> Option<Arc<WgpuService>> {
        test_gpu().map(|g| Arc::new(g.with_binding_limit_override(bytes)))
    }

    /// The directory [`ensure_xdg_runtime_dir`] made, removed at exit.
    static XDG_DIR: OnceLock<std::path::PathBuf> = OnceLock::new();

    #[cfg(unix)]
    extern "C" fn remove_xdg_dir() {
        if let Some(d) = XDG_DIR.get() {
            let _ = std::fs::remove_dir_all(d);
        }
    }

    /// Points `XDG_RUNTIME_DIR` at a new private 0700 directory with an
    /// unpredictable name when it is unset; the directory is removed when
    /// the process exits normally.
    pub fn ensure_xdg_runtime_dir() {
        static DONE: OnceLock<()> = OnceLock::new();
        DONE.get_or_init(|| {
            if std::env::var_os("XDG_RUNTIME_DIR").is_some() {
                return;
            }
            use std::hash::BuildHasher as _;
            let random =
                std::collections::hash_map::RandomState::new().hash_one(std::process::id());
            let dir = std::env::temp_dir().join(format!("voxflex-xdg-test-{random:016x}"));
            // Not recursive: creating fails if the name exists, so nobody
            // can have prepared it.
            let mut builder = std::fs::DirBuilder::new();
            #[cfg(unix)]
            std::os::unix::fs::DirBuilderExt::mode(&mut builder, 0o700);
            if builder.create(&dir).is_ok() {
                let dir = XDG_DIR.get_or_init(|| dir);
                // SAFETY: registers a plain function that only removes the
                // directory; atexit handlers run once at normal exit.
                #[cfg(unix)]
                unsafe {
                    libc::atexit(remove_xdg_dir);
                }
                // SAFETY: test-only; runs once, before any wgpu instance of
                // this process exists, while the other GPU tests wait on the
                // `OnceLock` in `test_gpu`. Rust's own env accesses are
                // serialised by std; no C library of ours reads the
                // environment concurrently at this point.
                unsafe { std::env::set_var("XDG_RUNTIME_DIR", dir) };
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::testing::test_gpu;
    use super::*;
    use voxflex_core::gpu::{GpuServiceExt, workgroups_1d};

    const AFFINE: &str = r#"
struct Params { n: u32, _pad0: u32, _pad1: u32, _pad2: u32 }
@group(0) @binding(0) var<storage, read> x: array<f32>;
@group(0) @binding(1) var<storage, read_write> y: array<f32>;
@group(0) @binding(2) var<uniform> params: Params;

@compute @workgroup_size(64)
fn affine(@builtin(global_invocation_id) gid: vec3<u32>,
          @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * (nwg.x * 64u) + gid.z * (nwg.x * 64u * nwg.y);
    if (i >= params.n) { return; }
    y[i] = 2.0 * x[i] + 1.0;
}
"#;

    #[test]
    fn adapter_is_described() {
        let Some(gpu) = test_gpu() else { return };
        let info = gpu.info();
        let limits = gpu.limits();
        eprintln!(
            "adapter: {info}; max_storage_buffer_binding_size {} B, max_buffer_size {} B, \
             max_compute_workgroups_per_dimension {}, min_storage_buffer_offset_alignment {}",
            limits.max_storage_buffer_binding_size,
            limits.max_buffer_size,
            limits.max_compute_workgroups_per_dimension,
            limits.min_storage_buffer_offset_alignment
        );
        assert!(!info.name.is_empty());
        assert!(gpu.adapter_description().contains(&info.name));
        // The device was opened with the adapter's limits, not wgpu's defaults.
        assert!(limits.max_storage_buffer_binding_size >= 128 << 20);
        assert!(limits.max_compute_workgroups_per_dimension >= 65535);
    }

    #[test]
    fn buffer_round_trip() {
        let Some(gpu) = test_gpu() else { return };
        let data: Vec<u32> = (0..10_000u32)
            .map(|i| i.wrapping_mul(2_654_435_761))
            .collect();
        let id = gpu.upload(&data, "round trip").unwrap();
        assert_eq!(gpu.buffer_size(id).unwrap(), 40_000);
        let mut back = vec![0u32; data.len()];
        gpu.download(id, &mut back).unwrap();
        assert_eq!(back, data);

        // Partial write and read at offsets, ragged lengths included.
        gpu.write_buffer(id, 8, &[1, 2, 3, 4, 5, 6]).unwrap();
        let mut part = [0u8; 11];
        gpu.read_buffer(id, 4, &mut part).unwrap();
        let mut want = [0u8; 11];
        want[..4].copy_from_slice(&data[1].to_ne_bytes());
        want[4..10].copy_from_slice(&[1, 2, 3, 4, 5, 6]);
        want[10] = data[3].to_ne_bytes()[2];
        assert_eq!(part, want, "bytes past a ragged write must be kept");

        // New buffers are zero-filled.
        let z = gpu.create_buffer(1024, "zeros").unwrap();
        let mut zeros = [1u32; 256];
        gpu.download(z, &mut zeros).unwrap();
        assert!(zeros.iter().all(|&v| v == 0));

        assert!(gpu.read_buffer(id, 2, &mut [0u8; 4]).is_err());
        assert!(gpu.read_buffer(id, 39_996, &mut [0u8; 8]).is_err());
        assert!(gpu.write_buffer(id, 40_000, &[0u8; 4]).is_err());
        gpu.destroy_buffer(id);
        gpu.destroy_buffer(z);
    }

    #[test]
    fn unknown_ids_are_errors() {
        let Some(gpu) = test_gpu() else { return };
        let bogus = BufferId(u64::MAX);
        let err = gpu.read_buffer(bogus, 0, &mut [0u8; 4]).unwrap_err();
        assert!(err.0.contains("unknown buffer"), "{err}");
        assert!(gpu.buffer_size(bogus).is_err());
        assert!(gpu.write_buffer(bogus, 0, &[0u8; 4]).is_err());
        gpu.destroy_buffer(bogus); // ignored
        let id = gpu.create_buffer(16, "destroyed").unwrap();
        gpu.destroy_buffer(id);
        assert!(gpu.read_buffer(id, 0, &mut [0u8; 4]).is_err());
        assert!(gpu.dispatch(PipelineId(u64::MAX), &[], [1, 1, 1]).is_err());
    }

    /// A device opened outside the service (as eframe opens its own) runs
    /// voxflex's kernels through `from_device` like one the service opened.
    #[test]
    fn a_device_opened_elsewhere_runs_the_kernels() {
        let Some(own) = test_gpu() else { return };
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()))
            .into_iter()
            .find(|a| a.get_info().name == own.adapter_info().name)
            .expect("the test adapter enumerates again");
        let (device, queue) =
            pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor::default())).unwrap();
        let gpu = WgpuService::from_device(adapter.get_info(), device, queue);
        assert_eq!(gpu.info(), own.info());
        let x: Vec<f32> = (0..1000).map(|i| i as f32).collect();
        let xb = gpu.upload(&x, "x").unwrap();
        let yb = gpu.create_buffer(4000, "y").unwrap();
        let pb = gpu.upload(&[1000u32, 0, 0, 0], "params").unwrap();
        let pipe = gpu.compile(AFFINE, "affine").unwrap();
        let bindings = [
            BufferBinding::whole(0, xb),
            BufferBinding::whole(1, yb),
            BufferBinding::whole(2, pb),
        ];
        gpu.dispatch(pipe, &bindings, gpu.workgroups_for(1000, 64).unwrap())
            .unwrap();
        let mut y = vec![0f32; 1000];
        gpu.download(yb, &mut y).unwrap();
        assert!(x.iter().zip(&y).all(|(a, b)| *b == 2.0 * a + 1.0));
        let bad = AFFINE.replace("y[i] = 2.0 * x[i] + 1.0;", "y[i] = 2.0 * x[i] +;");
        assert!(
            gpu.compile(&bad, "affine").is_err(),
            "errors still come back"
        );
        drop(instance);
    }

    #[test]
    fn affine_kernel_over_3d_folded_dispatch() {
        let Some(gpu) = test_gpu() else { return };
        let n: u32 = 70_000 * 64;
        let x: Vec<f32> = (0..n).map(|i| i as f32).collect();
        let xb = gpu.upload(&x, "x").unwrap();
        let yb = gpu.create_buffer(n as u64 * 4, "y").unwrap();
        let pb = gpu.upload(&[n, 0, 0, 0], "params").unwrap();
        let pipe = gpu.compile(AFFINE, "affine").unwrap();
        let wg = gpu.workgroups_for(n as u64, 64).unwrap();
        assert!(
            wg[1] > 1,
            "70000 groups must fold past one dimension: {wg:?}"
        );
        let bindings = [
            BufferBinding::whole(0, xb),
            BufferBinding::whole(1, yb),
            BufferBinding::whole(2, pb),
        ];
        gpu.dispatch(pipe, &bindings, wg).unwrap();
        let mut y = vec![0f32; n as usize];
        gpu.download(yb, &mut y).unwrap();
        for (i, (&xi, &yi)) in x.iter().zip(&y).enumerate() {
            assert_eq!(yi, 2.0 * xi + 1.0, "element {i}");
        }
        for b in [xb, yb, pb] {
            gpu.destroy_buffer(b);
        }
    }

    #[test]
    fn pipeline_cache_hits() {
        if test_gpu().is_none() {
            return;
        }
        // A private device, so parallel tests cannot move the counter.
        let gpu = WgpuService::new(AdapterPolicy::AnyAdapter).unwrap();
        let a = gpu.compile(AFFINE, "affine").unwrap();
        let b = gpu.compile(AFFINE, "affine").unwrap();
        assert_eq!(a, b);
        assert_eq!(gpu.stats().pipelines_compiled, 1);
        let other = AFFINE.replace("2.0 * x[i]", "3.0 * x[i]");
        let c = gpu.compile(&other, "affine").unwrap();
        assert_ne!(a, c);
        assert_eq!(gpu.stats().pipelines_compiled, 2);
    }

    #[test]
    fn wgsl_errors_come_back_as_gpu_errors() {
        let Some(gpu) = test_gpu() else { return };
        let bad = AFFINE.replace("y[i] = 2.0 * x[i] + 1.0;", "y[i] = 2.0 * x[i] +;");
        let err = gpu.compile(&bad, "affine").unwrap_err();
        eprintln!("{err}");
        assert!(err.0.contains("compiling WGSL"), "{err}");
        assert!(
            err.0.contains("expected"),
            "naga's message is missing: {err}"
        );
        let err = gpu.compile(AFFINE, "no_such_entry").unwrap_err();
        assert!(err.0.contains("no_such_entry"), "{err}");
        // Validation of a type error (not just syntax).
        let bad = AFFINE.replace("y[i] = 2.0 * x[i] + 1.0;", "y[i] = x;");
        let err = gpu.compile(&bad, "affine").unwrap_err();
        eprintln!("{err}");
    }

    #[test]
    fn invalid_dispatches_are_errors_not_panics() {
        let Some(gpu) = test_gpu() else { return };
        let pipe = gpu.compile(AFFINE, "affine").unwrap();
        let xb = gpu.create_buffer(256, "x").unwrap();
        // Missing bindings 1 and 2.
        let err = gpu
            .dispatch(pipe, &[BufferBinding::whole(0, xb)], [1, 1, 1])
            .unwrap_err();
        eprintln!("{err}");
        // Too many workgroups in one dimension.
        let max = gpu.limits().max_compute_workgroups_per_dimension;
        assert!(gpu.dispatch(pipe, &[], [max + 1, 1, 1]).is_err());
        // An entry point without bindings runs with none and refuses some.
        let noop = gpu
            .compile("@compute @workgroup_size(1) fn noop() {}", "noop")
            .unwrap();
        gpu.dispatch(noop, &[], [1, 1, 1]).unwrap();
        let err = gpu
            .dispatch(noop, &[BufferBinding::whole(0, xb)], [1, 1, 1])
            .unwrap_err();
        assert!(err.0.contains("noop"), "{err}");
        // The device still works afterwards.
        gpu.write_buffer(xb, 0, &[7u8; 8]).unwrap();
        let mut back = [0u8; 8];
        gpu.read_buffer(xb, 0, &mut back).unwrap();
        assert_eq!(back, [7u8; 8]);
        gpu.destroy_buffer(xb);
    }

    #[test]
    fn binding_limit_override_forces_slabs() {
        let Some(base) = test_gpu() else { return };
        let limit = 64 * 1024;
        let gpu = base.with_binding_limit_override(limit);
        assert_eq!(gpu.limits().max_storage_buffer_binding_size, limit);
        let n: u32 = 3 * 16 * 1024 + 100; // 3 slabs of 64 KiB and a bit
        let x: Vec<f32> = (0..n).map(|i| i as f32 * 0.5).collect();
        let xb = gpu.upload(&x, "x").unwrap();
        let yb = gpu.create_buffer(n as u64 * 4, "y").unwrap();
        let pipe = gpu.compile(AFFINE, "affine").unwrap();
        let whole = [BufferBinding::whole(0, xb), BufferBinding::whole(1, yb)];
        let err = gpu.dispatch(pipe, &whole, [1, 1, 1]).unwrap_err();
        assert!(err.0.contains("slabs"), "{err}");

        let align = gpu.limits().min_storage_buffer_offset_alignment as u64;
        let slab_elems = (limit / 4 / align * align) as u32; // elements per slab
        let mut start = 0u32;
        while start < n {
            let count = slab_elems.min(n - start);
            let pb = gpu.upload(&[count, 0, 0, 0], "params").unwrap();
            let bytes = count as u64 * 4;
            let bind = |binding, buffer| BufferBinding {
                binding,
                buffer,
                offset: start as u64 * 4,
                size: bytes,
            };
            let wg = workgroups_1d(
                count as u64,
                64,
                gpu.limits().max_compute_workgroups_per_dimension,
            )
            .unwrap();
            gpu.dispatch(
                pipe,
                &[bind(0, xb), bind(1, yb), BufferBinding::whole(2, pb)],
                wg,
            )
            .unwrap();
            gpu.destroy_buffer(pb);
            start += count;
        }
        let mut y = vec![0f32; n as usize];
        gpu.download(yb, &mut y).unwrap();
        assert!(x.iter().zip(&y).all(|(&a, &b)| b == 2.0 * a + 1.0));
        // The override is a view: the base service still binds the real limit.
        assert!(base.limits().max_storage_buffer_binding_size > limit);
        gpu.destroy_buffer(xb);
        gpu.destroy_buffer(yb);
    }

    #[test]
    fn many_dispatches_stay_ordered() {
        let Some(gpu) = test_gpu() else { return };
        const INC: &str = r#"
@group(0) @binding(0) var<storage, read_write> v: array<u32>;
@compute @workgroup_size(64)
fn inc(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x < arrayLength(&v)) { v[gid.x] = v[gid.x] * 2u + 1u; }
}
"#;
        let pipe = gpu.compile(INC, "inc").unwrap();
        let vb = gpu.upload(&[0u32; 128], "v").unwrap();
        let reps = MAX_QUEUED_DISPATCHES + 5;
        for r in 0..reps {
            if r == 10 {
                // A write between queued dispatches must land after them.
                gpu.write_buffer(vb, 0, bytemuck::cast_slice(&[1000u32]))
                    .unwrap();
            }
            gpu.dispatch(pipe, &[BufferBinding::whole(0, vb)], [2, 1, 1])
                .unwrap();
        }
        let mut v = [0u32; 128];
        gpu.download(vb, &mut v).unwrap();
        let expect = |mut x: u32, steps: usize| {
            for _ in 0..steps {
                x = x.wrapping_mul(2).wrapping_add(1);
            }
            x
        };
        assert_eq!(v[1], expect(0, reps));
        assert_eq!(v[0], expect(1000, reps - 10));
        gpu.destroy_buffer(vb);
    }

    /// A kernel sizes the next dispatch on the device: `size` writes the
    /// workgroup counts that `mark` then runs with, in the same queue, with
    /// no read-back between; bad argument ranges are errors.
    #[test]
    fn indirect_dispatches_take_counts_written_by_an_earlier_kernel() {
        let Some(gpu) = test_gpu() else { return };
        const KERNELS: &str = r#"
@group(0) @binding(0) var<storage, read_write> args: array<u32>;
@group(0) @binding(1) var<storage, read_write> v: array<u32>;
@compute @workgroup_size(1)
fn size() { args[1] = 3u; args[2] = 2u; args[3] = 1u; }
@compute @workgroup_size(4)
fn mark(@builtin(global_invocation_id) gid: vec3<u32>) {
    v[gid.x + 12u * gid.y] = 1u;
}
"#;
        let (size, mark) = (
            gpu.compile(KERNELS, "size").unwrap(),
            gpu.compile(KERNELS, "mark").unwrap(),
        );
        let args = gpu.upload(&[0u32; 4], "args").unwrap();
        let v = gpu.upload(&[0u32; 32], "v").unwrap();
        gpu.dispatch(size, &[BufferBinding::whole(0, args)], [1, 1, 1])
            .unwrap();
        gpu.dispatch_indirect(mark, &[BufferBinding::whole(1, v)], args, 4)
            .unwrap();
        let mut got = [0u32; 32];
        gpu.download(v, &mut got).unwrap();
        // 3 × 2 workgroups of 4 invocations: 24 marks.
        assert_eq!(got.iter().sum::<u32>(), 24, "{got:?}");
        assert_eq!(&got[24..], &[0; 8]);
        for offset in [2, 8] {
            let e = gpu
                .dispatch_indirect(mark, &[BufferBinding::whole(1, v)], args, offset)
                .unwrap_err()
                .to_string();
            assert!(e.contains("do not fit"), "{e}");
        }
        gpu.destroy_buffer(args);
        gpu.destroy_buffer(v);
    }

    #[test]
    fn concurrent_use_from_threads() {
        let Some(gpu) = test_gpu() else { return };
        let pipe = gpu.compile(AFFINE, "affine").unwrap();
        std::thread::scope(|s| {
            for t in 0..4u32 {
                let gpu = &gpu;
                s.spawn(move || {
                    let n = 1000 + t * 37;
                    let x: Vec<f32> = (0..n).map(|i| (i + t) as f32).collect();
                    let xb = gpu.upload(&x, "x").unwrap();
                    let yb = gpu.create_buffer(n as u64 * 4, "y").unwrap();
                    let pb = gpu.upload(&[n, 0, 0, 0], "params").unwrap();
                    for _ in 0..10 {
                        let b = [
                            BufferBinding::whole(0, xb),
                            BufferBinding::whole(1, yb),
                            BufferBinding::whole(2, pb),
                        ];
                        gpu.dispatch(pipe, &b, gpu.workgroups_for(n as u64, 64).unwrap())
                            .unwrap();
                        // Errors stay on the thread that caused them.
                        assert!(gpu.compile("fn broken(", "broken").is_err());
                    }
                    let mut y = vec![0f32; n as usize];
                    gpu.download(yb, &mut y).unwrap();
                    assert!(x.iter().zip(&y).all(|(&a, &b)| b == 2.0 * a + 1.0));
                    for b in [xb, yb, pb] {
                        gpu.destroy_buffer(b);
                    }
                });
            }
        });
    }

    #[test]
    fn software_adapters_are_recognised() {
        let info = wgpu::AdapterInfo {
            name: "llvmpipe (LLVM 15.0.6, 256 bits)".into(),
            vendor: 0x10005,
            device: 0,
            device_type: wgpu::DeviceType::Cpu,
            device_pci_bus_id: String::new(),
            driver: "llvmpipe".into(),
            driver_info: "Mesa 22.3.6".into(),
            backend: wgpu::Backend::Vulkan,
            subgroup_min_size: 4,
            subgroup_max_size: 4,
            transient_saves_memory: None,
            limit_bucket: None,
        };
        assert!(software_reason(&info).is_some());
        let hw = wgpu::AdapterInfo {
            name: "NVIDIA GeForce RTX 4090".into(),
            device_type: wgpu::DeviceType::DiscreteGpu,
            driver: "NVIDIA".into(),
            driver_info: "550".into(),
            ..info.clone()
        };
        assert!(software_reason(&hw).is_none());
        let swiftshader = wgpu::AdapterInfo {
            name: "SwiftShader Device (Subzero)".into(),
            device_type: wgpu::DeviceType::IntegratedGpu,
            ..hw.clone()
        };
        assert!(software_reason(&swiftshader).is_some());
        let warp = wgpu::AdapterInfo {
            name: "Microsoft Basic Render Driver".into(),
            device_type: wgpu::DeviceType::Other,
            backend: wgpu::Backend::Dx12,
            ..hw.clone()
        };
        assert!(AdapterSummary::from_info(&warp).software);
        assert!(!AdapterSummary::from_info(&hw).software);
        assert!(rank(&hw, None) < rank(&info, None));
        assert!(rank(&swiftshader, None) > rank(&hw, None));
    }
}
