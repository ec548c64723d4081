//! Backend selection: the scene's `backend = "cpu" | "gpu" | "auto"` turned
//! into an [`ExecutionBackend`] and, for the GPU, the host's one
//! [`WgpuService`].
//!
//! - `cpu` never touches wgpu (no instance, no adapter enumeration).
//! - `auto` takes a **hardware** GPU when one exists and the rayon path
//!   otherwise; a software adapter such as lavapipe counts as no GPU, and
//!   [`ResolvedBackend::reason`] says which adapters were found and why they
//!   were passed over.
//! - `gpu` takes any adapter, software ones included (that is how CI checks
//!   every WGSL kernel on lavapipe), and fails with what to install when
//!   there is none.

use std::fmt;
use std::str::FromStr;
use std::sync::Arc;

use voxflex_core::deformation::ExecutionBackend;
use voxflex_core::gpu::GpuService;

use crate::gpu_context::{AdapterPolicy, AdapterSummary, GpuContextError, WgpuService};

/// The scene file's `backend` key.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum BackendChoice {
    /// rayon on the CPU; the GPU is never initialised.
    Cpu,
    /// WGSL on any GPU adapter, software (lavapipe) included.
    Gpu,
    /// A hardware GPU if there is one, else the CPU. The default.
    #[default]
    Auto,
}

impl BackendChoice {
    /// The scene-file spelling: `"cpu"`, `"gpu"` or `"auto"`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Cpu => "cpu",
            Self::Gpu => "gpu",
            Self::Auto => "auto",
        }
    }
}

impl fmt::Display for BackendChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for BackendChoice {
    type Err = BackendError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "cpu" => Ok(Self::Cpu),
            "gpu" => Ok(Self::Gpu),
            "auto" => Ok(Self::Auto),
            _ => Err(BackendError::UnknownChoice(s.to_owned())),
        }
    }
}

/// Resolving a [`BackendChoice`] failed.
#[derive(Debug, thiserror::Error)]
pub enum BackendError {
    /// `backend = "gpu"` but no adapter exists.
    #[error(
        "backend = \"gpu\" but no GPU adapter was found; install mesa-vulkan-drivers for the \
         software lavapipe adapter, or use backend = \"cpu\" ({0})"
    )]
    NoGpuAdapter(#[source] GpuContextError),
    /// `backend = "gpu"`: an adapter exists but the GPU context could not be
    /// opened on it.
    #[error("backend = \"gpu\": {0}")]
    Gpu(#[source] GpuContextError),
    /// Not `cpu`, `gpu` or `auto`.
    #[error("unknown backend {0:?}; use \"cpu\", \"gpu\" or \"auto\"")]
    UnknownChoice(String),
}

/// The outcome of [`resolve`]: where the scene computes, and why.
#[derive(Clone, Debug)]
pub struct ResolvedBackend {
    /// The path every stage runs.
    pub backend: ExecutionBackend,
    /// The GPU context, exactly when `backend` is [`ExecutionBackend::Gpu`].
    pub gpu: Option<Arc<WgpuService>>,
    /// One line for logs and reports: the choice, the adapter or why the CPU
    /// was taken.
    pub reason: String,
}

impl ResolvedBackend {
    /// The GPU context as the trait object that algorithms and plugins are
    /// written against.
    pub fn gpu_service(&self) -> Option<Arc<dyn GpuService>> {
        self.gpu.clone().map(|g| g as Arc<dyn GpuService>)
    }
}

/// The warning `backend = "gpu"` gives when the only adapter it found is a
/// software rasteriser (llvmpipe, lavapipe, SwiftShader): the WGSL kernels
/// then run on the CPU through an emulated GPU, many times slower than
/// voxflex's own rayon path.
pub fn software_adapter_warning(info: &AdapterSummary) -> Option<String> {
    info.software.then(|| {
        format!(
            "backend = \"gpu\" runs on {info}, a software rasteriser: the results are correct \
             but it is much slower than backend = \"cpu\" (rayon); use backend = \"cpu\" or \
             \"auto\" (which skips software adapters) unless you are testing the GPU path"
        )
    })
}

/// Resolves the scene's backend choice (see the module docs).
pub fn resolve(choice: BackendChoice) -> Result<ResolvedBackend, BackendError> {
    resolve_on(choice, None)
}

/// [`resolve`], computing on `offered` — a device a front end opened (the
/// viewer's, so its images need no read-back) — instead of opening one:
/// `gpu` takes it whatever it is, `auto` takes it when it is a hardware
/// adapter and runs on the CPU otherwise, `cpu` ignores it.
pub fn resolve_on(
    choice: BackendChoice,
    offered: Option<&Arc<WgpuService>>,
) -> Result<ResolvedBackend, BackendError> {
    let resolved = match choice {
        BackendChoice::Cpu => ResolvedBackend {
            backend: ExecutionBackend::Cpu,
            gpu: None,
            reason: "backend = \"cpu\": rayon on the CPU; the GPU is not initialised".to_owned(),
        },
        BackendChoice::Gpu => {
            let gpu = match offered {
                Some(gpu) => Arc::clone(gpu),
                None => match WgpuService::new(AdapterPolicy::AnyAdapter) {
                    Ok(gpu) => Arc::new(gpu),
                    Err(e) if e.is_no_adapter() => return Err(BackendError::NoGpuAdapter(e)),
                    Err(e) => return Err(BackendError::Gpu(e)),
                },
            };
            let info = gpu.info();
            let note = if info.software {
                " (a software adapter: correct, but slower than the CPU path)"
            } else {
                ""
            };
            if let Some(w) = software_adapter_warning(&info) {
                tracing::warn!(target: "voxflex::backend", "{w}");
            }
            ResolvedBackend {
                backend: ExecutionBackend::Gpu,
                reason: format!("backend = \"gpu\": {info}{note}"),
                gpu: Some(gpu),
            }
        }
        BackendChoice::Auto => {
            let gpu = match offered {
                Some(gpu) if !gpu.info().software => Ok(Arc::clone(gpu)),
                Some(gpu) => Err(format!(
                    "the offered device, {}, is a software adapter",
                    gpu.info()
                )),
                None => WgpuService::new(AdapterPolicy::HardwareOnly)
                    .map(Arc::new)
                    .map_err(|e| e.to_string()),
            };
            match gpu {
                Ok(gpu) => ResolvedBackend {
                    backend: ExecutionBackend::Gpu,
                    reason: format!("backend = \"auto\": hardware GPU {}", gpu.info()),
                    gpu: Some(gpu),
                },
                Err(e) => ResolvedBackend {
                    backend: ExecutionBackend::Cpu,
                    gpu: None,
                    reason: format!(
                        "backend = \"auto\": no hardware GPU, using rayon on the CPU \
                         (software adapters such as lavapipe count as none; \
                         backend = \"gpu\" would take them): {e}"
                    ),
                },
            }
        }
    };
    tracing::info!(target: "voxflex::backend", "{}", resolved.reason);
    Ok(resolved)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu_context::testing::test_gpu;

    #[derive(serde::Deserialize)]
    struct Scene {
        backend: BackendChoice,
    }

    #[test]
    fn choice_parses_from_toml_and_strings() {
        for (text, want) in [
            ("cpu", BackendChoice::Cpu),
            ("gpu", BackendChoice::Gpu),
            ("auto", BackendChoice::Auto),
        ] {
            let scene: Scene = toml::from_str(&format!("backend = \"{text}\"")).unwrap();
            assert_eq!(scene.backend, want);
            assert_eq!(text.parse::<BackendChoice>().unwrap(), want);
            assert_eq!(want.to_string(), text);
        }
        assert!(toml::from_str::<Scene>("backend = \"cuda\"").is_err());
        let err = "cuda".parse::<BackendChoice>().unwrap_err().to_string();
        assert!(err.contains("\"cpu\", \"gpu\" or \"auto\""), "{err}");
        assert_eq!(BackendChoice::default(), BackendChoice::Auto);
    }

    #[test]
    fn cpu_never_opens_a_gpu() {
        let r = resolve(BackendChoice::Cpu).unwrap();
        assert_eq!(r.backend, ExecutionBackend::Cpu);
        assert!(r.gpu.is_none() && r.gpu_service().is_none());
        assert!(r.reason.contains("cpu"));
    }

    #[test]
    fn auto_takes_only_hardware() {
        crate::gpu_context::testing::ensure_xdg_runtime_dir();
        let r = resolve(BackendChoice::Auto).unwrap();
        eprintln!("{}", r.reason);
        match (&r.backend, &r.gpu) {
            (ExecutionBackend::Gpu, Some(gpu)) => assert!(!gpu.info().software),
            (ExecutionBackend::Cpu, None) => assert!(r.reason.contains("no hardware GPU")),
            other => panic!("inconsistent resolution {other:?}"),
        }
    }

    #[test]
    fn gpu_takes_any_adapter() {
        // Same CI policy as every GPU test: a missing adapter fails under CI.
        if test_gpu().is_none() {
            let err = resolve(BackendChoice::Gpu).unwrap_err().to_string();
            assert!(err.starts_with("backend = \"gpu\""), "{err}");
            return;
        }
        let r = resolve(BackendChoice::Gpu).unwrap();
        eprintln!("{}", r.reason);
        assert_eq!(r.backend, ExecutionBackend::Gpu);
        let gpu = r.gpu_service().unwrap();
        assert!(r.reason.contains(&r.gpu.as_ref().unwrap().info().name));
        assert!(gpu.limits().max_buffer_size > 0);
    }

    #[test]
    fn software_adapters_are_warned_about() {
        let lavapipe = AdapterSummary {
            name: "llvmpipe (LLVM 15.0.6, 256 bits)".into(),
            backend: "vulkan".into(),
            device_type: "Cpu".into(),
            driver: "llvmpipe (Mesa 22.3.6)".into(),
            software: true,
        };
        let w = software_adapter_warning(&lavapipe).unwrap();
        assert!(
            w.contains("llvmpipe") && w.contains("software rasteriser"),
            "{w}"
        );
        let hw = AdapterSummary {
            name: "NVIDIA H200".into(),
            device_type: "DiscreteGpu".into(),
            software: false,
            ..lavapipe
        };
        assert_eq!(software_adapter_warning(&hw), None);
    }

    #[test]
    fn no_adapter_message_says_what_to_do() {
        let e = BackendError::NoGpuAdapter(GpuContextError::NoAdapter {
            backends: "VULKAN".into(),
        });
        let msg = e.to_string();
        assert!(msg.starts_with(
            "backend = \"gpu\" but no GPU adapter was found; install mesa-vulkan-drivers for the \
             software lavapipe adapter, or use backend = \"cpu\""
        ));
    }
}
