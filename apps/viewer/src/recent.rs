//! File → Open recent: the last [`MAX_RECENT`] files opened, newest
//! first, kept across runs in a small text file (one absolute path a line)
//! in the platform's config folder ([`default_store`]).

use std::path::{Path, PathBuf};

/// Files the list keeps.
pub const MAX_RECENT: usize = 8;

/// The list file's name inside the config folder.
const FILE_NAME: &str = "voxflex/viewer-recent.txt";

/// Where the list lives by default: `$XDG_CONFIG_HOME/voxflex/…`, else
/// `$HOME/.config/voxflex/…` (Linux and the BSDs), `%APPDATA%\voxflex\…`
/// (Windows); `None` when none of these is set (the list then lives only
/// for the run).
pub fn default_store() -> Option<PathBuf> {
    let var = |k: &str| {
        std::env::var_os(k)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    let dir = var("XDG_CONFIG_HOME")
        .or_else(|| var("HOME").map(|h| h.join(".config")))
        .or_else(|| var("APPDATA"))?;
    Some(dir.join(FILE_NAME))
}

/// The recent files, newest first, and the file they are kept in.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RecentFiles {
    files: Vec<PathBuf>,
    store: Option<PathBuf>,
}

impl RecentFiles {
    /// The list kept in `store` (read now; a missing or unreadable file is
    /// an empty list), or a list for this run only with `None`.
    pub fn load(store: Option<PathBuf>) -> Self {
        let files = store
            .as_deref()
            .and_then(|p| std::fs::read_to_string(p).ok())
            .map(|text| {
                text.lines()
                    .filter(|l| !l.trim().is_empty())
                    .map(PathBuf::from)
                    .take(MAX_RECENT)
                    .collect()
            })
            .unwrap_or_default();
        Self { files, store }
    }

    /// The files, newest first.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    /// Puts `path` (made absolute) first, drops an older entry of it and
    /// the oldest beyond [`MAX_RECENT`], and writes the list.
    pub fn push(&mut self, path: &Path) -> std::io::Result<()> {
        let path = std::path::absolute(path)?;
        self.files.retain(|p| p != &path);
        self.files.insert(0, path);
        self.files.truncate(MAX_RECENT);
        self.save()
    }

    /// Removes `path` from the list and writes it; false when it was not
    /// there.
    pub fn remove(&mut self, path: &Path) -> std::io::Result<bool> {
        let before = self.files.len();
        self.files.retain(|p| p != path);
        if self.files.len() == before {
            return Ok(false);
        }
        self.save().map(|_| true)
    }

    /// Writes the list to its file (nothing without one), creating the
    /// folder; the file is replaced atomically (written beside under a
    /// name of its own, renamed).
    fn save(&self) -> std::io::Result<()> {
        let Some(store) = &self.store else {
            return Ok(());
        };
        if let Some(dir) = store.parent() {
            std::fs::create_dir_all(dir)?;
        }
        let mut text = String::new();
        for p in &self.files {
            text += &p.to_string_lossy();
            text.push('\n');
        }
        // A temporary file of its own (several viewers may save at once).
        voxflex_io::write_atomically(store, |w| w.write_all(text.as_bytes()))
            .map_err(std::io::Error::other)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_list_keeps_the_newest_eight_once_each_across_loads() {
        let dir = tempfile::tempdir().unwrap();
        let store = dir.path().join("cfg/voxflex/recent.txt");
        let mut r = RecentFiles::load(Some(store.clone()));
        assert!(r.files().is_empty());
        for n in 0..10 {
            r.push(&dir.path().join(format!("v{n}.nii"))).unwrap();
        }
        r.push(&dir.path().join("v5.nii")).unwrap();
        let again = RecentFiles::load(Some(store));
        let names: Vec<_> = again
            .files()
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(
            names,
            [
                "v5.nii", "v9.nii", "v8.nii", "v7.nii", "v6.nii", "v4.nii", "v3.nii", "v2.nii"
            ]
        );
        let mut again = again;
        assert!(again.remove(&dir.path().join("v9.nii")).unwrap());
        assert!(!again.remove(&dir.path().join("v9.nii")).unwrap());
        assert_eq!(again.files().len(), 7);
    }
}
