//! [`StepReport`]: what one [`super::Session::step`] re-ran, and why.

use std::time::Duration;

/// One stage's part in a step.
#[derive(Clone, Debug, PartialEq)]
pub struct StageOutcome {
    /// Stage name as in `metrics.json`: `model`, `map`, `resample`, `roi`.
    pub stage: &'static str,
    /// True when the stage did work this step.
    pub ran: bool,
    /// Why it ran or was skipped (versions, convergence, not built).
    pub why: String,
    /// Wall time of the work, zero when skipped.
    pub wall: Duration,
    /// Voxels (or points, or ROI visits) the work touched; 0 when skipped.
    pub voxels: u64,
}

/// What one step did, stage by stage in pipeline order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StepReport {
    /// The frame number the model stepped (0 for the first step).
    pub frame: u64,
    /// The stages, in pipeline order.
    pub stages: Vec<StageOutcome>,
}

impl StepReport {
    /// The outcome of stage `name`, if the step reports it.
    pub fn stage(&self, name: &str) -> Option<&StageOutcome> {
        self.stages.iter().find(|s| s.stage == name)
    }

    /// True when stage `name` did work this step.
    pub fn ran(&self, name: &str) -> bool {
        self.stage(name).is_some_and(|s| s.ran)
    }

    pub(crate) fn push(
        &mut self,
        stage: &'static str,
        ran: bool,
        why: String,
        wall: Duration,
        voxels: u64,
    ) {
        self.stages.push(StageOutcome {
            stage,
            ran,
            why,
            wall,
            voxels,
        });
    }
}

impl std::fmt::Display for StepReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "frame {}:", self.frame)?;
        for s in &self.stages {
            let verb = if s.ran { "ran" } else { "skipped" };
            write!(f, " {} {verb} ({});", s.stage, s.why)?;
        }
        Ok(())
    }
}
