//! The parts of [`ViewerApp`] that open files and grab on the 3D view:
//! File → Open / Open recent / drag-and-drop replacing the session, the
//! dialogs' answers, and the 3D view's grab in *Grab* mode.

use super::ViewerApp;
use crate::dialogs::DialogPurpose;
use crate::file_menu::FileAction;
use crate::grab3d::Grab3d;
use crate::model_panel::ModelPanel;
use crate::open::OpenRequest;
use crate::protocol::Command;
use crate::recent::RecentFiles;
use crate::slice_view::ClickMode;
use crate::view3d::image_rect;
use egui::Rect;
use voxflex_core::camera::Camera;
use voxflex_core::glam::DVec3;

impl ViewerApp {
    /// Keeps File → Open recent in `store` instead of the config folder's
    /// file (`None`: only for this run), read now.
    pub fn with_recent_store(mut self, store: Option<std::path::PathBuf>) -> Self {
        self.files.recent = RecentFiles::load(store);
        self
    }

    /// The point (world mm) the last press on the 3D view picked in
    /// *Grab* mode.
    pub fn last_3d_pick(&self) -> Option<DVec3> {
        self.grab3d.last_pick()
    }

    /// Where the 3D image was drawn last frame (screen points).
    pub fn view3d_rect(&self) -> Option<Rect> {
        self.view3d_rect
    }

    /// File → Open recent's files, newest first.
    pub fn recent(&self) -> &RecentFiles {
        &self.files.recent
    }

    /// Opens a volume or scene file, replacing the session (with the
    /// backend and plugin folders the viewer started with); errors come
    /// back as messages naming the file.
    pub fn open_file(&mut self, path: std::path::PathBuf) {
        self.messages.push(format!("opening {}…", path.display()));
        self.worker.send(Command::Open(OpenRequest {
            input: Some(path),
            ..self.req.clone()
        }));
    }

    /// Drops what the UI held of the previous session (a new one opened).
    pub(super) fn forget_session(&mut self) {
        self.slices = None;
        self.render = None;
        self.rois.clear();
        self.roi_panel.selected = None;
        self.roi_panel.styles.clear();
        self.roi_panel.bounds.clear();
        self.model_panel = ModelPanel::default();
        self.stages.clear();
        self.last_step = None;
        self.steps = 0;
        self.grab = None;
        self.cut = None;
        self.grab3d = Grab3d::default();
        self.sent = None;
    }

    /// Files dropped on the window (the first is opened) and the file
    /// dialogs' answers.
    pub(super) fn on_files(&mut self, ctx: &egui::Context) {
        let dropped = ctx.input(|i| i.raw.dropped_files.first().map(|f| f.path().to_path_buf()));
        if let Some(p) = dropped {
            self.open_file(p);
        }
        if self.roi_panel.browse_save_dir {
            self.roi_panel.browse_save_dir = false;
            let start = Some(std::path::PathBuf::from(&self.roi_panel.save_dir));
            self.files.dialog(ctx, DialogPurpose::MapsFolder, start);
        }
        if let Some(a) = self.files.poll() {
            self.on_file_action(a);
        }
    }

    pub(super) fn on_file_action(&mut self, a: FileAction) {
        match a {
            FileAction::Open(p) => self.open_file(p),
            FileAction::Send(c) => self.worker.send(c),
            FileAction::MapsFolder(p) => self.roi_panel.save_dir = p.display().to_string(),
            FileAction::Say(m) => self.messages.push(m),
        }
    }

    /// The session's answer to a 3D pick.
    pub(super) fn on_picked(&mut self, p: Option<[f64; 3]>) {
        if p.is_none() {
            self.messages
                .push("grab: nothing under the pointer in the 3D view".into());
        }
        if let Some(c) = self.grab3d.on_picked(p) {
            self.worker.send(c);
        }
    }

    /// The 3D view's grab in *Grab* mode, over what `view3d` did
    /// (`orbit`: its camera and whether it dragged): the camera after the
    /// pan or zoom of whichever took them, and whether a drag is under way.
    pub(super) fn grab_on_3d(
        &mut self,
        ui: &mut egui::Ui,
        avail: Rect,
        camera: Camera,
        orbit: (Camera, bool),
    ) -> (Camera, bool) {
        let image = image_rect(avail, &camera);
        self.view3d_rect = Some(image);
        if self.mode != ClickMode::Grab {
            return orbit;
        }
        let floor = self.window.level - 0.5 * self.window.width;
        let g = self.grab3d.input(ui, avail, image, &camera, floor);
        for cmd in g.commands {
            self.worker.send(cmd);
        }
        let c = if orbit.0 == camera { g.camera } else { orbit.0 };
        (c, orbit.1 || g.dragging)
    }
}
