//! The File menu: Open… (a native dialog), Open recent, and Save scene /
//! Save volume, each to a typed path or one chosen in a Save dialog; and
//! the answers of those dialogs as [`FileAction`]s for the app.

use crate::dialogs::{DialogPurpose, Dialogs};
use crate::protocol::Command;
use crate::recent::RecentFiles;
use egui::{Button, Color32, RichText};
use std::path::{Path, PathBuf};

/// What the File menu or a dialog asks the app to do.
#[derive(Clone, Debug)]
pub enum FileAction {
    /// Open this volume or scene, replacing the session.
    Open(PathBuf),
    /// Send this command to the session (a save).
    Send(Command),
    /// Set the ROI panel's folder for saved maps.
    MapsFolder(PathBuf),
    /// A line for the status bar.
    Say(String),
}

/// The File menu's state: the save paths, the recent files and the
/// dialog in flight.
#[derive(Debug)]
pub struct FileMenu {
    /// File → Save scene's path.
    pub save_scene_path: String,
    /// File → Save volume's path.
    pub save_volume_path: String,
    /// File → Open recent.
    pub recent: RecentFiles,
    dialogs: Dialogs,
}

impl FileMenu {
    /// The menu with `recent` as its recent files.
    pub fn new(recent: RecentFiles) -> Self {
        Self {
            save_scene_path: "viewer-scene.toml".into(),
            save_volume_path: "viewer-volume.nii.gz".into(),
            recent,
            dialogs: Dialogs::default(),
        }
    }

    /// Opens a dialog for `purpose` (the UI is repainted when it closes).
    pub fn dialog(&mut self, ctx: &egui::Context, purpose: DialogPurpose, start: Option<PathBuf>) {
        let waker = ctx.clone();
        self.dialogs
            .open(purpose, start, move || waker.request_repaint());
    }

    /// What a dialog closed since the last call asks for.
    pub fn poll(&mut self) -> Option<FileAction> {
        let (purpose, path) = self.dialogs.poll()?;
        let path = path?;
        Some(match purpose {
            DialogPurpose::Open => FileAction::Open(path),
            DialogPurpose::SaveScene => {
                self.save_scene_path = path.display().to_string();
                FileAction::Send(Command::SaveScene(path))
            }
            DialogPurpose::SaveVolume => {
                self.save_volume_path = path.display().to_string();
                FileAction::Send(Command::SaveVolume(path))
            }
            DialogPurpose::MapsFolder => FileAction::MapsFolder(path),
        })
    }

    /// Draws the menu's contents; returns what was chosen.
    pub fn ui(&mut self, ui: &mut egui::Ui) -> Vec<FileAction> {
        let mut out = vec![];
        let ctx = ui.ctx().clone();
        if ui
            .add_enabled(!self.dialogs.busy(), Button::new("Open…"))
            .clicked()
        {
            self.dialog(&ctx, DialogPurpose::Open, None);
            ui.close();
        }
        ui.menu_button("Open recent", |ui| self.recent_ui(ui, &mut out));
        ui.separator();
        for purpose in [DialogPurpose::SaveScene, DialogPurpose::SaveVolume] {
            self.save_ui(ui, purpose, &mut out);
        }
        out
    }

    fn recent_ui(&mut self, ui: &mut egui::Ui, out: &mut Vec<FileAction>) {
        if self.recent.files().is_empty() {
            ui.label(RichText::new("(none yet)").color(Color32::GRAY));
            return;
        }
        let mut missing = vec![];
        for path in self.recent.files() {
            let name = short_name(path);
            if path.exists() {
                if ui
                    .button(&name)
                    .on_hover_text(path.display().to_string())
                    .clicked()
                {
                    out.push(FileAction::Open(path.clone()));
                    ui.close();
                }
            } else {
                ui.add_enabled(false, Button::new(format!("{name} (missing)")))
                    .on_disabled_hover_text(format!("{} no longer exists", path.display()));
                missing.push(path.clone());
            }
        }
        if !missing.is_empty() && ui.button("Forget missing files").clicked() {
            for p in &missing {
                if let Err(e) = self.recent.remove(p) {
                    out.push(FileAction::Say(format!(
                        "error: updating the recent files: {e}"
                    )));
                }
            }
            out.push(FileAction::Say(format!(
                "removed {} missing file(s) from Open recent",
                missing.len()
            )));
        }
    }

    fn save_ui(&mut self, ui: &mut egui::Ui, purpose: DialogPurpose, out: &mut Vec<FileAction>) {
        let busy = self.dialogs.busy();
        let (what, path) = match purpose {
            DialogPurpose::SaveScene => ("Save scene", &mut self.save_scene_path),
            _ => ("Save volume", &mut self.save_volume_path),
        };
        ui.horizontal(|ui| {
            let label = ui.label(format!("{what} to"));
            ui.text_edit_singleline(path).labelled_by(label.id);
        });
        let typed = PathBuf::from(path.as_str());
        let (save, save_as) = ui
            .horizontal(|ui| {
                let save = ui.button(what).clicked();
                let save_as = ui
                    .add_enabled(!busy, Button::new(format!("{what} as…")))
                    .clicked();
                (save, save_as)
            })
            .inner;
        if save {
            out.push(FileAction::Send(match purpose {
                DialogPurpose::SaveScene => Command::SaveScene(typed),
                _ => Command::SaveVolume(typed),
            }));
            ui.close();
        } else if save_as {
            let ctx = ui.ctx().clone();
            self.dialog(&ctx, purpose, Some(typed));
            ui.close();
        }
    }
}

/// `name — folder` for a menu entry.
fn short_name(path: &Path) -> String {
    let name = path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    match path.parent().and_then(|p| p.file_name()) {
        Some(dir) => format!("{name} — {}", dir.to_string_lossy()),
        None => name,
    }
}
