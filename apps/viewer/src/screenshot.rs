//! `--screenshot out.png --exit-after-frames N`: after N frames (and once
//! the first images arrived, or an error), save the window as PNG and
//! close it.

use anyhow::Context;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Time after which the screenshot is taken even without images.
const PATIENCE: Duration = Duration::from_secs(120);

/// Where the screenshot mode stands.
#[derive(Debug)]
pub struct Screenshot {
    path: Option<PathBuf>,
    after_frames: u64,
    requested: bool,
    reported: bool,
    started: Instant,
    /// Set by the screenshot callback: the PNG written (or why not).
    done: Arc<Mutex<Option<Result<(), String>>>>,
}

impl Screenshot {
    /// A screenshot to `path` after `after_frames` frames; with no path,
    /// the window closes after `after_frames` frames if given.
    pub fn new(path: Option<PathBuf>, after_frames: Option<u64>) -> Self {
        Self {
            path,
            after_frames: after_frames.unwrap_or(0),
            requested: false,
            reported: false,
            started: Instant::now(),
            done: Arc::default(),
        }
    }

    /// The outcome the screenshot callback writes (`None` until then).
    pub fn outcome(&self) -> Arc<Mutex<Option<Result<(), String>>>> {
        self.done.clone()
    }

    /// True when the app runs in screenshot (or exit-after-frames) mode.
    pub fn active(&self) -> bool {
        self.path.is_some() || self.after_frames > 0
    }

    /// Called once per frame: asks for the screenshot once `frame` ≥ N and
    /// `ready` (or after two minutes without), closes the window once it is
    /// written. Returns the result once, when done.
    pub fn on_frame(
        &mut self,
        ctx: &egui::Context,
        frame: u64,
        ready: bool,
    ) -> Option<Result<(), String>> {
        if !self.active() || self.reported {
            return None;
        }
        ctx.request_repaint();
        let due = frame >= self.after_frames && (ready || self.started.elapsed() >= PATIENCE);
        match &self.path {
            None if due => {
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
                self.reported = true;
                Some(Ok(()))
            }
            None => None,
            Some(path) => {
                if due && !self.requested {
                    self.requested = true;
                    let (path, done) = (path.clone(), self.done.clone());
                    ctx.request_screenshot(move |image| {
                        let r = save_png(&path, &image).map_err(|e| format!("{e:#}"));
                        if let Ok(mut d) = done.lock() {
                            *d = Some(r);
                        }
                    });
                }
                let result = self.done.lock().ok()?.clone();
                if result.is_some() {
                    ctx.send_viewport_cmd(egui::ViewportCommand::Close);
                    self.reported = true;
                }
                result
            }
        }
    }
}

/// Writes `image` as an RGBA PNG at `path`.
pub fn save_png(path: &Path, image: &egui::ColorImage) -> anyhow::Result<()> {
    let [w, h] = image.size;
    let bytes: Vec<u8> = image.pixels.iter().flat_map(|c| c.to_array()).collect();
    image::save_buffer(
        path,
        &bytes,
        w as u32,
        h as u32,
        image::ExtendedColorType::Rgba8,
    )
    .with_context(|| format!("writing screenshot {}", path.display()))
}

/// Fewest distinct colours a screenshot showing the slices and the 3D
/// image has (gray ramps of the slices alone give hundreds; the UI's
/// chrome and text without images give far fewer).
pub const MIN_DISTINCT_COLOURS: usize = 200;

/// Checks the PNG at `path` shows images, not a blank or empty window:
/// at least [`MIN_DISTINCT_COLOURS`] colours. Returns how many it has.
pub fn check_not_blank(path: &Path) -> anyhow::Result<usize> {
    let img = image::open(path)
        .with_context(|| format!("reading screenshot {}", path.display()))?
        .to_rgba8();
    let mut colours: Vec<[u8; 4]> = img.pixels().map(|p| p.0).collect();
    colours.sort_unstable();
    colours.dedup();
    let n = colours.len();
    anyhow::ensure!(
        n >= MIN_DISTINCT_COLOURS,
        "{} looks blank: {n} distinct colours (a window showing the slices has at least {MIN_DISTINCT_COLOURS})",
        path.display()
    );
    Ok(n)
}
