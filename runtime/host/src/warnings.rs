//! Warnings of a run, collected for `metrics.json`.
//!
//! Every warning a run prints — the host's own, and each plugin's (plugins
//! log through the host's `tracing` subscriber, see
//! `voxflex_abi::host_side`) — is also kept, so a run that stopped a solve
//! above tolerance, lost tissue or clamped a value says so in its report,
//! not only on a terminal nobody read. A front end adds [`WarningLayer`] to
//! its subscriber; [`capture`] then collects the WARN and ERROR events of
//! every thread until the returned guard is dropped.
//!
//! The layer serves the whole process, so two captures active at once in one
//! process each receive every warning raised while both are active; the CLI
//! runs one scene per process.

use std::fmt::Write as _;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use tracing::field::{Field, Visit};
use tracing::{Event, Level, Subscriber};
use tracing_subscriber::layer::{Context, Layer};

/// At most this many warnings are kept per run; later ones are counted only.
pub const MAX_KEPT: usize = 200;

/// The captures in progress, by id.
static CAPTURES: Mutex<Vec<(u64, Captured)>> = Mutex::new(Vec::new());
/// The next capture's id.
static NEXT_ID: AtomicU64 = AtomicU64::new(0);

#[derive(Default)]
struct Captured {
    kept: Vec<String>,
    dropped: usize,
}

/// A `tracing` layer that copies WARN and ERROR events into the capture in
/// progress, if any. Add it beside the terminal formatter; it keeps nothing
/// when no [`capture`] is active.
#[derive(Clone, Copy, Debug, Default)]
pub struct WarningLayer;

impl<S: Subscriber> Layer<S> for WarningLayer {
    fn on_event(&self, event: &Event<'_>, _ctx: Context<'_, S>) {
        let level = *event.metadata().level();
        if level > Level::WARN {
            return;
        }
        let Ok(mut captures) = CAPTURES.lock() else {
            return;
        };
        if captures.is_empty() {
            return;
        }
        let mut text = Message::default();
        event.record(&mut text);
        let prefix = if level == Level::ERROR { "error: " } else { "" };
        let line = format!("{prefix}{}", text.finish());
        for (_, c) in captures.iter_mut() {
            if c.kept.len() >= MAX_KEPT {
                c.dropped += 1;
            } else {
                c.kept.push(line.clone());
            }
        }
    }
}

/// Renders an event as `message (field=value, …)`, plugin target first.
#[derive(Default)]
struct Message {
    message: String,
    plugin: Option<String>,
    fields: String,
}

impl Message {
    fn finish(self) -> String {
        let mut s = match self.plugin {
            Some(p) => format!("{p}: {}", self.message),
            None => self.message,
        };
        if !self.fields.is_empty() {
            let _ = write!(s, " ({})", self.fields);
        }
        s
    }
}

impl Visit for Message {
    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        match field.name() {
            "message" => self.message = format!("{value:?}"),
            "plugin_target" => self.plugin = Some(format!("{value:?}")),
            name => {
                if !self.fields.is_empty() {
                    self.fields.push_str(", ");
                }
                let _ = write!(self.fields, "{name}={value:?}");
            }
        }
    }

    fn record_str(&mut self, field: &Field, value: &str) {
        match field.name() {
            "message" => self.message = value.to_owned(),
            "plugin_target" => self.plugin = Some(value.to_owned()),
            _ => self.record_debug(field, &value),
        }
    }
}

/// Starts collecting warnings; [`WarningCapture::finish`] returns them.
pub fn capture() -> WarningCapture {
    let id = NEXT_ID.fetch_add(1, Ordering::Relaxed);
    if let Ok(mut g) = CAPTURES.lock() {
        g.push((id, Captured::default()));
    }
    WarningCapture { id }
}

/// An active capture; dropping it ends it (what it collected is returned by
/// [`finish`](Self::finish) only).
#[derive(Debug)]
pub struct WarningCapture {
    id: u64,
}

impl WarningCapture {
    /// The warnings so far, in the order they were raised, without ending
    /// the capture. When more than [`MAX_KEPT`] were raised, the last entry
    /// says how many more were not kept.
    pub fn snapshot(&self) -> Vec<String> {
        let Ok(g) = CAPTURES.lock() else {
            return Vec::new();
        };
        match g.iter().find(|(id, _)| *id == self.id).map(|(_, c)| c) {
            Some(c) => {
                let mut v = c.kept.clone();
                if c.dropped > 0 {
                    v.push(format!("… and {} more warnings not kept", c.dropped));
                }
                v
            }
            None => Vec::new(),
        }
    }

    /// Ends the capture and returns its warnings (see [`snapshot`](Self::snapshot)).
    pub fn finish(self) -> Vec<String> {
        self.snapshot()
    }
}

impl Drop for WarningCapture {
    fn drop(&mut self) {
        if let Ok(mut g) = CAPTURES.lock() {
            g.retain(|(id, _)| *id != self.id);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tracing_subscriber::layer::SubscriberExt;

    #[test]
    fn warnings_and_errors_are_captured_with_their_fields_and_infos_are_not() {
        let subscriber = tracing_subscriber::registry().with(WarningLayer);
        tracing::subscriber::with_default(subscriber, || {
            tracing::warn!("before the capture");
            let cap = capture();
            tracing::info!("not a warning");
            tracing::warn!(residual = 0.5, "solve stopped above tolerance");
            tracing::error!(plugin_target = "fem", "boom");
            let got = cap.finish();
            assert_eq!(
                got,
                vec![
                    "solve stopped above tolerance (residual=0.5)".to_string(),
                    "error: fem: boom".to_string(),
                ]
            );
            let later = capture();
            tracing::warn!("after the first capture");
            assert_eq!(later.finish(), vec!["after the first capture".to_string()]);
        });
    }

    #[test]
    fn a_flood_is_capped_and_counted() {
        let subscriber = tracing_subscriber::registry().with(WarningLayer);
        tracing::subscriber::with_default(subscriber, || {
            let cap = capture();
            for i in 0..MAX_KEPT + 5 {
                tracing::warn!("w{i}");
            }
            let got = cap.finish();
            assert_eq!(got.len(), MAX_KEPT + 1);
            assert_eq!(got.last().unwrap(), "… and 5 more warnings not kept");
        });
    }
}
