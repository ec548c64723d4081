//! File → Save view as PNG: the 3D view rendered again at full quality
//! (the camera's full size, the current renderer settings and shown maps)
//! and written as PNG through a temporary file renamed over the target.

use crate::protocol::Command;
use anyhow::Context;
use std::path::{Path, PathBuf};
use voxflex_core::camera::Camera;
use voxflex_runtime::session::{RenderParams, Session};
use voxflex_runtime::visualise::write_rgba_png;

/// Renders `camera` (full size) with `render` and writes the PNG to `path`
/// (a temporary file beside it, then renamed; errors name the path).
pub fn save_view_png(
    session: &mut Session,
    camera: &Camera,
    render: &RenderParams,
    path: &Path,
) -> anyhow::Result<()> {
    if path
        .extension()
        .is_none_or(|e| !e.eq_ignore_ascii_case("png"))
    {
        anyhow::bail!(
            "save view: `{}` must end in .png (the image is written as PNG)",
            path.display()
        );
    }
    let image = session.render(camera, render)?;
    write_rgba_png(path, &image).with_context(|| format!("save view: {}", path.display()))
}

/// The File menu's *Save view as PNG* row: the path field and the button;
/// the command when clicked.
pub fn menu_item(ui: &mut egui::Ui, path: &mut String) -> Option<Command> {
    ui.horizontal(|ui| {
        let label = ui.label("Save view as PNG to");
        ui.text_edit_singleline(path).labelled_by(label.id);
    });
    ui.button("Save view as PNG")
        .clicked()
        .then(|| Command::SaveViewPng(PathBuf::from(path.as_str())))
}
