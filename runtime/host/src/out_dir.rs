//! The output directory of a run: where outputs may go, the advisory lock
//! that serialises runs into one directory, and the clean-up of temporary
//! files a killed run left behind.
//!
//! Path rules: `[output] dir` (or `--out`) must not be empty or a file
//! system root; every file name a scene sets (`[output] nifti`,
//! `[render] file`, `[[roi]] name`) must be one plain name — no `/`, no
//! `..`, not absolute — so a run writes only inside its output directory.
//!
//! Lock: a run holds an exclusive advisory lock ([`std::fs::File::lock`],
//! `flock` on Unix) on `<dir>/.voxflex-lock` from before the up-to-date check
//! until it returns. A second run into the same directory says that it
//! waits, waits, then finds the outputs up to date instead of redoing the
//! work. The lock is released by the kernel when a run dies, however it
//! dies.
//!
//! Temporary files: writes go through
//! [`voxflex_io::write_atomically`], which names its temporary
//! `.<file>.voxflex-tmp-<pid>-<n>`. With the lock held, a run removes such
//! files in its directory whose process no longer exists.

use std::fs::File;
use std::path::{Component, Path};

/// Name of the lock file in the output directory.
pub const LOCK_FILE: &str = ".voxflex-lock";

/// Why `dir` may not be an output directory, if it may not.
pub fn check_dir(dir: &Path) -> Result<(), String> {
    if dir.as_os_str().is_empty() {
        return Err("is empty; name an output directory such as \"out\"".into());
    }
    let names_something = dir
        .components()
        .any(|c| matches!(c, Component::Normal(_) | Component::ParentDir));
    let rooted = dir.has_root();
    if rooted && !names_something {
        return Err(format!(
            "`{}` is a file system root; name an output directory of its own such as \"out\"",
            dir.display()
        ));
    }
    Ok(())
}

/// Why `name` may not be a file name inside the output directory, if it may
/// not: it must be one plain name, not a path.
pub fn check_file_name(name: &str) -> Result<(), String> {
    let p = Path::new(name);
    let plain = matches!(
        p.components().collect::<Vec<_>>().as_slice(),
        [Component::Normal(_)]
    );
    if name.is_empty() || !plain || name.contains('/') || name.contains('\\') {
        return Err(format!(
            "`{name}` must be a plain file name inside the output directory (no `/`, no `..`, \
             not absolute)"
        ));
    }
    Ok(())
}

/// An exclusive lock on an output directory, released on drop.
#[derive(Debug)]
pub struct OutDirLock {
    _file: File,
}

/// Takes the lock on `dir` (which must exist). When another run holds it,
/// logs a warning saying so and waits for it.
pub fn lock(dir: &Path) -> std::io::Result<OutDirLock> {
    let path = dir.join(LOCK_FILE);
    let file = File::options()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)?;
    match file.try_lock() {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) => {
            tracing::warn!(
                "{}: another voxflex run holds the lock on this output directory ({}); waiting \
                 for it to finish",
                dir.display(),
                path.display()
            );
            file.lock()?;
        }
        Err(std::fs::TryLockError::Error(e)) => return Err(e),
    }
    Ok(OutDirLock { _file: file })
}

/// The process id in a temporary file name of
/// [`voxflex_io::write_atomically`] (`.<file>.voxflex-tmp-<pid>-<n>`).
pub fn temp_file_pid(name: &str) -> Option<u32> {
    let rest = name.strip_prefix('.')?;
    let (_, tail) = rest.rsplit_once(".voxflex-tmp-")?;
    let (pid, n) = tail.split_once('-')?;
    n.parse::<u64>().ok()?;
    pid.parse().ok()
}

/// Whether process `pid` exists (on non-Unix platforms: assumed so).
fn process_alive(pid: u32) -> bool {
    if pid == std::process::id() {
        return true;
    }
    #[cfg(unix)]
    {
        let Ok(pid) = libc::pid_t::try_from(pid) else {
            return false;
        };
        // SAFETY: signal 0 only checks that the process exists.
        if unsafe { libc::kill(pid, 0) } == 0 {
            return true;
        }
        std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
    }
    #[cfg(not(unix))]
    {
        true
    }
}

/// Removes the temporary files in `dir` left by processes that no longer
/// exist; returns how many. Call with the directory's lock held.
pub fn remove_stale_temp_files(dir: &Path) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    let mut removed = 0;
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(pid) = name.to_str().and_then(temp_file_pid) else {
            continue;
        };
        if !process_alive(pid) && e.file_type().is_ok_and(|t| t.is_file()) {
            match std::fs::remove_file(e.path()) {
                Ok(()) => removed += 1,
                Err(err) => tracing::warn!(
                    "{}: could not remove a killed run's temporary file: {err}",
                    e.path().display()
                ),
            }
        }
    }
    if removed > 0 {
        tracing::info!(
            "{}: removed {removed} temporary file(s) of killed runs",
            dir.display()
        );
    }
    removed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roots_and_empty_dirs_are_refused() {
        for bad in ["", "/", "//", "/."] {
            assert!(check_dir(Path::new(bad)).is_err(), "{bad:?} accepted");
        }
        for good in ["out", "out/demo", "/tmp/x", "../sibling", "."] {
            assert_eq!(check_dir(Path::new(good)), Ok(()), "{good:?}");
        }
    }

    #[test]
    fn file_names_stay_inside_the_directory() {
        for bad in [
            "",
            "..",
            ".",
            "../x.nii",
            "/etc/x.png",
            "a/b.png",
            "a/../b.png",
            "a\\b.png",
        ] {
            assert!(check_file_name(bad).is_err(), "{bad:?} accepted");
        }
        for good in ["deformed.nii.gz", "render.png", "liver", "a..b.png"] {
            assert_eq!(check_file_name(good), Ok(()), "{good:?}");
        }
    }

    #[test]
    fn temp_names_parse() {
        assert_eq!(
            temp_file_pid(".deformed.nii.gz.voxflex-tmp-1234-7"),
            Some(1234)
        );
        assert_eq!(temp_file_pid("deformed.nii.gz"), None);
        assert_eq!(temp_file_pid(".x.voxflex-tmp-12"), None);
        assert_eq!(temp_file_pid(".x.voxflex-tmp-ab-1"), None);
    }

    #[test]
    fn only_dead_processes_lose_their_temp_files() {
        let dir = tempfile::tempdir().unwrap();
        // A process that has exited: its id is free (until reused).
        let mut child = std::process::Command::new(std::env::current_exe().unwrap())
            .arg("--list")
            .stdout(std::process::Stdio::null())
            .spawn()
            .unwrap();
        let dead = child.id();
        child.wait().unwrap();
        let stale = dir.path().join(format!(".a.nii.voxflex-tmp-{dead}-0"));
        let live = dir
            .path()
            .join(format!(".b.nii.voxflex-tmp-{}-0", std::process::id()));
        let other = dir.path().join("keep.nii");
        for p in [&stale, &live, &other] {
            std::fs::write(p, b"x").unwrap();
        }
        assert_eq!(remove_stale_temp_files(dir.path()), 1);
        assert!(!stale.exists() && live.exists() && other.exists());
    }

    #[test]
    fn a_held_lock_is_exclusive_and_released_on_drop() {
        let dir = tempfile::tempdir().unwrap();
        let held = lock(dir.path()).unwrap();
        let other = File::options()
            .write(true)
            .open(dir.path().join(LOCK_FILE))
            .unwrap();
        assert!(matches!(
            other.try_lock(),
            Err(std::fs::TryLockError::WouldBlock)
        ));
        drop(held);
        other.try_lock().unwrap();
    }
}
