//! Run reports: per-stage wall time, runs and skips, voxels touched —
//! written as `metrics.json` beside a scene's outputs.

use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Duration;

/// Counters of one pipeline stage over a run.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct StageMetrics {
    /// Times the stage did work.
    pub runs: u64,
    /// Times the stage was due but skipped because no input changed.
    pub skipped: u64,
    /// Total wall time spent working, milliseconds.
    pub wall_ms: f64,
    /// Voxels (or points) the stage read or wrote, summed over runs.
    pub voxels_touched: u64,
    /// Stage-specific notes (e.g. "dirty region" sizes, useful fraction).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub notes: BTreeMap<String, serde_json::Value>,
}

impl StageMetrics {
    /// Records one run of `elapsed` touching `voxels`.
    pub fn record_run(&mut self, elapsed: Duration, voxels: u64) {
        self.runs += 1;
        self.wall_ms += elapsed.as_secs_f64() * 1e3;
        self.voxels_touched += voxels;
    }
}

/// The whole run's report.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct RunMetrics {
    /// Scene name.
    pub scene: String,
    /// voxflex version.
    pub voxflex_version: String,
    /// Path that ran: `cpu`, `gpu`, or `none` when nothing ran.
    pub backend: String,
    /// Why that backend was chosen (adapter found or refused).
    pub backend_reason: String,
    /// Frames simulated.
    pub frames: u64,
    /// True when the outputs were already up to date and nothing ran. Only
    /// the caller sees it true: an up-to-date run writes no `metrics.json`
    /// (the file keeps the report of the run that made the outputs).
    pub up_to_date: bool,
    /// Deformation plugin name, version and file, if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plugin: Option<PluginReport>,
    /// Stage name → counters, in pipeline order names (`source`, `model`,
    /// `map`, `resample`, `output`).
    pub stages: BTreeMap<String, StageMetrics>,
    /// Stages the scene does not ask for, never built.
    pub stages_not_built: Vec<String>,
    /// Source volume dims.
    pub source_dims: [usize; 3],
    /// Output grid dims (after growth to the deformed bounding box).
    pub output_dims: [usize; 3],
    /// Extra memory of the resampling stage beyond input and output volumes,
    /// bytes per source voxel.
    pub resample_extra_bytes_per_voxel: f64,
    /// Files written, relative to the output directory.
    pub outputs: Vec<String>,
    /// Every warning (and error) the host and the plugins raised during the
    /// run, in order (see [`crate::warnings`]); empty when the front end did
    /// not install [`crate::warnings::WarningLayer`] or nothing was wrong.
    pub warnings: Vec<String>,
    /// Total wall time, milliseconds.
    pub total_wall_ms: f64,
    /// The actuation stage (scenes with `[[actuator]]`): per actuator
    /// its effort and measure per frame, per effector its distance to the
    /// target.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub actuation: Option<crate::actuation::ActuationReport>,
}

/// Which plugin ran.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct PluginReport {
    /// Declared name.
    pub name: String,
    /// Declared semver.
    pub version: String,
    /// Library file.
    pub path: String,
}

impl RunMetrics {
    /// The counters of stage `name`, created on first use.
    pub fn stage(&mut self, name: &str) -> &mut StageMetrics {
        self.stages.entry(name.to_owned()).or_default()
    }

    /// Pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
    }
}
