//! [`Versions`]: the version numbers that decide which pipeline stage
//! re-runs. Each stage's output carries a version; a stage runs when the
//! version of its input moved past the one it last consumed.

/// One stage's version bookkeeping: the version of its own output and the
/// version of its input it last consumed (`None`: never ran, or told to
/// run again in full).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StageVersion {
    /// Version of this stage's output; moves by one every time it runs.
    pub version: u64,
    /// Input version consumed by the last run; `None` before the first.
    pub consumed: Option<u64>,
}

impl StageVersion {
    /// True when `input` (the upstream stage's version) differs from the
    /// one this stage last consumed.
    pub fn is_due(&self, input: u64) -> bool {
        self.consumed != Some(input)
    }

    /// Records a run on `input`: consumed, and a new output version.
    pub fn ran_on(&mut self, input: u64) {
        self.consumed = Some(input);
        self.version += 1;
    }

    /// Forgets what was consumed, so the next check is due whatever the
    /// input (a new model, backend or output stage to feed).
    pub fn invalidate(&mut self) {
        self.consumed = None;
    }

    /// Why the stage is due on `input` (or why not), for step reports.
    pub fn reason(&self, upstream: &str, input: u64) -> String {
        match self.consumed {
            None => format!("first run on {upstream} version {input}"),
            Some(c) if c != input => format!("{upstream} version {input} ≠ consumed {c}"),
            Some(c) => format!("{upstream} unchanged since version {c}"),
        }
    }
}

/// The versions of every stage of a [`super::Session`], in pipeline order:
/// source → model → map → resample → roi → render → output.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Versions {
    /// The source volume: moves when a new one is loaded (never, today).
    pub source: u64,
    /// The model: moves each step whose model reported a change.
    pub model: u64,
    /// The displacement field mapped from the model; input: `model`.
    pub map: StageVersion,
    /// The resampled volume; input: `map`.
    pub resample: StageVersion,
    /// The session's ROI maps, re-grown on a new volume; input: `resample`.
    pub roi: StageVersion,
    /// The last rendered image; input: `resample` (the volume shown).
    pub render: StageVersion,
    /// Files written by a scene run; input: `resample`.
    pub output: StageVersion,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stage_is_due_until_it_consumed_its_input() {
        let mut s = StageVersion::default();
        assert!(s.is_due(0), "never ran");
        assert!(s.reason("model", 0).starts_with("first run"));
        s.ran_on(0);
        assert_eq!(s.version, 1);
        assert!(!s.is_due(0));
        assert_eq!(s.reason("model", 0), "model unchanged since version 0");
        assert!(s.is_due(1));
        assert_eq!(s.reason("model", 1), "model version 1 ≠ consumed 0");
        s.ran_on(1);
        s.invalidate();
        assert!(s.is_due(1), "invalidated");
        assert_eq!(s.version, 2, "invalidating keeps the output version");
    }
}
