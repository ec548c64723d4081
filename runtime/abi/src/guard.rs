//! Panic containment and error transport shared by both sides of the boundary.

use crate::ffi::{ErrorBuf, STATUS_ERROR, STATUS_OK, STATUS_PANIC};
use std::panic::{AssertUnwindSafe, catch_unwind};

/// Runs `f`, catching panics, and turns the result into a status code,
/// writing any message into `err` (which may be null).
pub(crate) fn guard(err: *mut ErrorBuf, f: impl FnOnce() -> Result<(), String>) -> i32 {
    let (status, msg) = match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(())) => return STATUS_OK,
        Ok(Err(msg)) => (STATUS_ERROR, msg),
        Err(payload) => (
            STATUS_PANIC,
            format!("panicked: {}", panic_message(&*payload)),
        ),
    };
    if !err.is_null() {
        // SAFETY: the caller passes a valid ErrorBuf or null.
        unsafe { (*err).write(&msg) };
    }
    status
}

/// The text of a panic payload.
pub fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_owned()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "non-string panic payload".to_owned()
    }
}

/// A caller-side error buffer: allocate, pass [`ErrorSink::as_ffi`], then read
/// [`ErrorSink::message`].
pub struct ErrorSink {
    storage: Vec<u8>,
    buf: ErrorBuf,
}

impl Default for ErrorSink {
    fn default() -> Self {
        Self::new()
    }
}

impl ErrorSink {
    /// Capacity of every error message, bytes.
    pub const CAPACITY: usize = 4096;

    /// A fresh, empty sink.
    pub fn new() -> Self {
        let mut storage = vec![0u8; Self::CAPACITY];
        let buf = ErrorBuf {
            ptr: storage.as_mut_ptr(),
            cap: storage.len(),
            len: 0,
        };
        Self { storage, buf }
    }

    /// The pointer to hand to the callee.
    pub fn as_ffi(&mut self) -> *mut ErrorBuf {
        self.buf.len = 0;
        &mut self.buf
    }

    /// The message the callee wrote.
    pub fn message(&self) -> String {
        let n = self.buf.len.min(self.storage.len());
        String::from_utf8_lossy(&self.storage[..n]).into_owned()
    }

    /// `Ok` for [`STATUS_OK`], else the message (prefixed for panics).
    pub fn check(&self, status: i32) -> Result<(), String> {
        match status {
            STATUS_OK => Ok(()),
            STATUS_PANIC => Err(format!("plugin {}", self.message())),
            _ => Err(self.message()),
        }
    }
}
