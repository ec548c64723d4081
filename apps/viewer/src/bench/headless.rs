//! The viewer without a window: a [`ViewerApp`] driven by an egui
//! [`Context`] fed scripted [`RawInput`] at a steady frame rate, each
//! frame's UI-thread time measured (the app's update and egui's
//! tessellation — what the UI thread does before handing triangles and
//! textures to the GPU).

use crate::app::ViewerApp;
use crate::open::OpenRequest;
use crate::screenshot::Screenshot;
use egui::{Context, Event, Modifiers, PointerButton, Pos2, RawInput, Rect, Vec2};
use std::time::{Duration, Instant};
use voxflex_core::glam::DVec3;
use voxflex_runtime::session::SliceImage;

/// The window size the benchmarks draw (points), the viewer's default.
pub const WINDOW: Vec2 = Vec2::new(1280.0, 860.0);
/// One frame at 60 Hz.
pub const FRAME: Duration = Duration::from_nanos(16_666_667);

/// A headless viewer.
pub struct Headless {
    ctx: Context,
    /// The viewer.
    pub app: ViewerApp,
    started: Instant,
    next_frame: Instant,
    events: Vec<Event>,
}

impl Headless {
    /// Starts the viewer (its worker opens `req`).
    pub fn new(req: OpenRequest) -> anyhow::Result<Self> {
        let ctx = Context::default();
        let app = ViewerApp::new(&ctx, req, Screenshot::new(None, None))?;
        let now = Instant::now();
        Ok(Self {
            ctx,
            app,
            started: now,
            next_frame: now,
            events: vec![],
        })
    }

    /// Queues an input event for the next frame.
    pub fn event(&mut self, e: Event) {
        self.events.push(e);
    }

    /// Queues a primary-button press or release at `pos`.
    pub fn button(&mut self, pos: Pos2, pressed: bool) {
        self.event(Event::PointerMoved(pos));
        self.event(Event::PointerButton {
            pos,
            button: PointerButton::Primary,
            pressed,
            modifiers: Modifiers::NONE,
        });
    }

    /// Waits for the next 60 Hz tick, then runs one frame: the app's
    /// update on the queued events and the tessellation of its shapes.
    /// Returns the frame's UI-thread time.
    pub fn frame(&mut self) -> Duration {
        let now = Instant::now();
        if self.next_frame > now {
            std::thread::sleep(self.next_frame - now);
        }
        self.next_frame = self.next_frame.max(now) + FRAME;
        let input = RawInput {
            screen_rect: Some(Rect::from_min_size(Pos2::ZERO, WINDOW)),
            time: Some(self.started.elapsed().as_secs_f64()),
            predicted_dt: FRAME.as_secs_f32(),
            events: std::mem::take(&mut self.events),
            ..Default::default()
        };
        let t = Instant::now();
        let app = &mut self.app;
        let mut out = self.ctx.run_ui(input, |ui| app.show(ui));
        let primitives = self.ctx.tessellate(out.shapes, out.pixels_per_point);
        let wall = t.elapsed();
        drop(primitives);
        // No painter here: the texture uploads are dropped on purpose
        // (egui asserts that deltas are handled).
        out.textures_delta.clear();
        wall
    }

    /// Runs frames until `done` holds; fails after `patience` with the
    /// viewer's messages.
    pub fn wait_for(
        &mut self,
        what: &str,
        patience: Duration,
        mut done: impl FnMut(&ViewerApp) -> bool,
    ) -> anyhow::Result<()> {
        let t = Instant::now();
        while !done(&self.app) {
            if let Some(e) = self.app.messages().iter().find(|m| m.starts_with("error")) {
                anyhow::bail!("waiting for {what}: the viewer reported {e}");
            }
            anyhow::ensure!(
                t.elapsed() < patience,
                "timed out after {patience:?} waiting for {what}; viewer messages: {:?}",
                self.app.messages()
            );
            self.frame();
        }
        Ok(())
    }

    /// Where world point `p` (mm) lies on slice view `n` as drawn last
    /// frame, if drawn.
    pub fn screen_of(&self, n: usize, p: DVec3) -> Option<Pos2> {
        let slice = &self.app.slices()?[n].slice;
        let rect = self.app.slice_rect(n)?;
        Some(screen_on(slice, rect, p))
    }
}

/// Where world point `p` (mm) lies on `slice` drawn in `rect`.
pub fn screen_on(slice: &SliceImage, rect: Rect, p: DVec3) -> Pos2 {
    let [c, r] = slice.world_to_point(p);
    let img = &slice.image;
    Pos2::new(
        rect.min.x + ((c + 0.5) / img.width as f64) as f32 * rect.width(),
        rect.min.y + ((r + 0.5) / img.height as f64) as f32 * rect.height(),
    )
}
