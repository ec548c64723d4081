//! Routes a plugin library's own copy of `tracing` into the host's
//! subscriber: a plugin's `tracing` statics are separate from the host's, so
//! without this bridge its events would go nowhere.

use crate::ffi::{StrRef, log_level};
use std::fmt::Write as _;
use tracing::field::{Field, Visit};
use tracing::span::{Attributes, Id, Record};
use tracing::{Event, Level, Metadata, Subscriber};

/// The host's log function (see [`crate::ffi::HostApi::log`]).
pub type HostLogFn = unsafe extern "C" fn(*mut std::ffi::c_void, u32, StrRef, StrRef);

/// A `tracing` subscriber that forwards events (not spans) to the host.
///
/// It is installed once per plugin library and outlives every instance, so
/// it keeps only the host's `log` function — code of the host executable,
/// valid for the whole process — and calls it with a null context, as the
/// [`crate::ffi::HostApi::log`] contract allows. It never keeps the
/// per-instance `HostApi` table, which dies with its instance.
pub struct HostLogSubscriber {
    log: HostLogFn,
}

impl HostLogSubscriber {
    /// A subscriber forwarding to the host's `log` function.
    pub fn new(log: HostLogFn) -> Self {
        Self { log }
    }
}

struct MessageVisitor(String);

impl Visit for MessageVisitor {
    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            let _ = write!(self.0, "{value:?}");
        } else {
            let _ = write!(self.0, " {}={value:?}", field.name());
        }
    }
    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "message" {
            self.0.push_str(value);
        } else {
            let _ = write!(self.0, " {}={value}", field.name());
        }
    }
}

fn level_code(level: &Level) -> u32 {
    match *level {
        Level::ERROR => log_level::ERROR,
        Level::WARN => log_level::WARN,
        Level::INFO => log_level::INFO,
        Level::DEBUG => log_level::DEBUG,
        _ => log_level::TRACE,
    }
}

impl Subscriber for HostLogSubscriber {
    fn enabled(&self, _: &Metadata<'_>) -> bool {
        true
    }
    fn new_span(&self, _: &Attributes<'_>) -> Id {
        Id::from_u64(1)
    }
    fn record(&self, _: &Id, _: &Record<'_>) {}
    fn record_follows_from(&self, _: &Id, _: &Id) {}
    fn event(&self, event: &Event<'_>) {
        thread_local! {
            static FORWARDING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
        }
        // When plugin and host share one `tracing` (a plugin used in-process
        // through its vtable), the host's log call lands here again: drop it
        // instead of recursing.
        if FORWARDING.with(|f| f.replace(true)) {
            return;
        }
        let mut v = MessageVisitor(String::new());
        event.record(&mut v);
        let meta = event.metadata();
        // SAFETY: `log` is a host function that ignores its context (HostApi contract).
        unsafe {
            (self.log)(
                std::ptr::null_mut(),
                level_code(meta.level()),
                StrRef::new(meta.target()),
                StrRef::new(&v.0),
            )
        };
        FORWARDING.with(|f| f.set(false));
    }
    fn enter(&self, _: &Id) {}
    fn exit(&self, _: &Id) {}
}
