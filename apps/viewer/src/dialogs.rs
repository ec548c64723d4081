//! Native file dialogs (`rfd`, the XDG Desktop Portal on Linux) run on
//! their own thread, so the UI keeps drawing while one is open; the UI
//! polls [`Dialogs::poll`] each frame for the path chosen.

use std::path::PathBuf;
use std::sync::mpsc::{Receiver, TryRecvError, channel};

/// The file types File → Open offers: (filter name, extensions).
pub const OPEN_FILTERS: [(&str, &[&str]); 5] = [
    (
        "Volumes and scenes",
        &["nii", "nii.gz", "gz", "mha", "mhd", "nrrd", "nhdr", "toml"],
    ),
    ("NIfTI", &["nii", "nii.gz", "gz"]),
    ("MetaImage", &["mha", "mhd"]),
    ("NRRD", &["nrrd", "nhdr"]),
    ("Scene", &["toml"]),
];

/// What a dialog's answer is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DialogPurpose {
    /// File → Open: a volume or a scene.
    Open,
    /// File → Save scene's path.
    SaveScene,
    /// File → Save volume's path.
    SaveVolume,
    /// The ROI panel's folder for saved maps.
    MapsFolder,
}

/// The dialog in flight, if any (one at a time).
#[derive(Debug, Default)]
pub struct Dialogs {
    pending: Option<(DialogPurpose, Receiver<Option<PathBuf>>)>,
}

impl Dialogs {
    /// True while a dialog is open.
    pub fn busy(&self) -> bool {
        self.pending.is_some()
    }

    /// Opens the dialog for `purpose` on a new thread (`start`: the folder
    /// and file name it starts at, for the save dialogs); `wake` is called
    /// when it closes (e.g. to request a repaint). Does nothing while
    /// another dialog is open.
    pub fn open(
        &mut self,
        purpose: DialogPurpose,
        start: Option<PathBuf>,
        wake: impl Fn() + Send + 'static,
    ) {
        if self.busy() {
            return;
        }
        let (tx, rx) = channel();
        let spawned = std::thread::Builder::new()
            .name("voxflex-file-dialog".into())
            .spawn(move || {
                let _ = tx.send(run(purpose, start));
                wake();
            });
        match spawned {
            Ok(_) => self.pending = Some((purpose, rx)),
            Err(e) => tracing::warn!("could not start the file dialog: {e}"),
        }
    }

    /// The path chosen, once the dialog closed (`None` inside: cancelled).
    pub fn poll(&mut self) -> Option<(DialogPurpose, Option<PathBuf>)> {
        let (purpose, rx) = self.pending.as_ref()?;
        let answer = match rx.try_recv() {
            Ok(p) => p,
            Err(TryRecvError::Empty) => return None,
            Err(TryRecvError::Disconnected) => None,
        };
        let purpose = *purpose;
        self.pending = None;
        Some((purpose, answer))
    }
}

/// Shows the dialog (blocking this thread) and returns the path chosen.
fn run(purpose: DialogPurpose, start: Option<PathBuf>) -> Option<PathBuf> {
    let mut d = rfd::FileDialog::new();
    if let Some(dir) = start.as_deref().and_then(|p| {
        if p.is_dir() {
            Some(p.to_path_buf())
        } else {
            p.parent().map(|d| d.to_path_buf())
        }
    }) && dir.is_dir()
    {
        d = d.set_directory(dir);
    }
    let name = start
        .as_deref()
        .filter(|p| !p.is_dir())
        .and_then(|p| p.file_name())
        .map(|n| n.to_string_lossy().into_owned());
    if let Some(n) = name {
        d = d.set_file_name(n);
    }
    match purpose {
        DialogPurpose::Open => {
            for (what, ext) in OPEN_FILTERS {
                d = d.add_filter(what, ext);
            }
            d.set_title("Open a volume or a scene").pick_file()
        }
        DialogPurpose::SaveScene => d
            .add_filter("Scene", &["toml"])
            .set_title("Save the scene")
            .save_file(),
        DialogPurpose::SaveVolume => d
            .add_filter("NIfTI", &["nii.gz", "nii"])
            .set_title("Save the volume")
            .save_file(),
        DialogPurpose::MapsFolder => d.set_title("Folder for saved maps").pick_folder(),
    }
}
