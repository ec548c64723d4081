//! Whether a scene's outputs are up to date: the fingerprint of everything
//! they depend on, and the stamp a completed run leaves beside them.
//!
//! The fingerprint is an XXH3-128 hash over
//!
//! - the voxflex version and the plugin ABI (version and layout hash);
//! - the **bytes** of the running `voxflex` executable, so a rebuilt
//!   resampler or writer never leaves old outputs looking current;
//! - the output directory as given and the scene text;
//! - the **bytes** of every plugin library the scene loads;
//! - the **bytes** of the source volume file and, for a MetaImage `.mhd` or
//!   NRRD `.nhdr` header, of the detached data file it names
//!   ([`voxflex_io::volume_files`]). A phantom source is covered by
//!   the scene text.
//!
//! Content hashes, not size and modification time: a same-size file copied
//! over the source with its mtime kept (`cp -p`) changes the fingerprint.
//! XXH3 hashes at memory speed; the cost is one read of the inputs per
//! run, up to date or not (docs/GUIDE.md, *Up to date*, has the
//! measured time of an up-to-date run).
//!
//! The [`Stamp`] records the fingerprint and the size of every file the run
//! wrote (`metrics.json` included). A later run is up to date only when the
//! fingerprint is equal **and** every recorded file is still a regular file
//! of its recorded, non-zero size. Output *contents* are not hashed: a file
//! edited in place to the same size is not noticed (use `--force`).

use serde::{Deserialize, Serialize};
use std::io::Read;
use std::path::{Path, PathBuf};
use voxflex_io::{file_kind, volume_files};
use xxhash_rust::xxh3::Xxh3;

/// Name of the stamp file in the output directory.
pub const STAMP_FILE: &str = ".voxflex-stamp";

/// XXH3-128 of a file's bytes with its length, or why it has none
/// (`missing`, `a FIFO`, …). Only regular files are read, so a source path
/// naming `/dev/zero` or a FIFO never blocks the fingerprint.
pub fn file_identity(path: &Path) -> String {
    let meta = match std::fs::metadata(path) {
        Ok(m) => m,
        Err(e) => return format!("unreadable ({})", e.kind()),
    };
    if !meta.is_file() {
        return format!("not a regular file ({})", file_kind(&meta));
    }
    let Ok(mut f) = std::fs::File::open(path) else {
        return "unreadable".into();
    };
    let mut hasher = Xxh3::new();
    let mut buf = vec![0u8; 1 << 20];
    let mut len = 0u64;
    loop {
        match f.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => {
                hasher.update(&buf[..n]);
                len += n as u64;
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return format!("unreadable ({})", e.kind()),
        }
    }
    format!("{len} bytes xxh3 {:032x}", hasher.digest128())
}

/// Identity of the running executable: the bytes of the image this process
/// runs (on Linux `/proc/self/exe`, which still reads the old image when the
/// file was rebuilt under it).
pub fn host_identity() -> String {
    #[cfg(target_os = "linux")]
    {
        let p = Path::new("/proc/self/exe");
        if p.is_file() {
            return file_identity(p);
        }
    }
    match std::env::current_exe() {
        Ok(p) => file_identity(&p),
        Err(e) => format!("unknown ({e})"),
    }
}

/// What a run's outputs depend on (see the module docs).
pub struct Inputs<'a> {
    /// The scene file's text.
    pub scene_text: &'a str,
    /// The output directory as the run resolved it.
    pub out_dir: &'a Path,
    /// Plugin libraries the scene loads.
    pub plugins: &'a [&'a Path],
    /// The source volume file, if the source is not a phantom.
    pub source: Option<PathBuf>,
    /// Identity of the host executable ([`host_identity`]).
    pub host: String,
}

/// The fingerprint of `inputs`: 32 hex digits.
pub fn fingerprint(inputs: &Inputs<'_>) -> String {
    let mut parts = vec![
        format!("voxflex {}", env!("CARGO_PKG_VERSION")),
        format!(
            "abi {} {:016x}",
            voxflex_abi::ABI_VERSION,
            voxflex_abi::LAYOUT_HASH
        ),
        format!("host {}", inputs.host),
        format!("out {}", inputs.out_dir.display()),
        format!("scene {}", inputs.scene_text),
    ];
    for p in inputs.plugins {
        parts.push(format!("plugin {} {}", p.display(), file_identity(p)));
    }
    if let Some(source) = &inputs.source {
        match volume_files(source) {
            Ok(files) => {
                for f in files {
                    parts.push(format!("source {} {}", f.display(), file_identity(&f)));
                }
            }
            // The run itself will refuse the source with a full message.
            Err(e) => parts.push(format!("source {} unusable: {e}", source.display())),
        }
    }
    format!(
        "{:032x}",
        xxhash_rust::xxh3::xxh3_128(parts.join("\n").as_bytes())
    )
}

/// One file a run wrote, relative to the output directory.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct OutputFile {
    /// Path relative to the output directory.
    pub file: String,
    /// Size in bytes when the run finished.
    pub bytes: u64,
}

/// What a completed run leaves in [`STAMP_FILE`].
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Stamp {
    /// [`fingerprint`] of the run's inputs.
    pub fingerprint: String,
    /// Every file the run wrote, with its size.
    pub outputs: Vec<OutputFile>,
}

impl Stamp {
    /// A stamp for `files` (relative to `out_dir`) as they are now on disk;
    /// a file that is missing is recorded with 0 bytes (never up to date).
    pub fn record(fingerprint: String, out_dir: &Path, files: &[String]) -> Stamp {
        let outputs = files
            .iter()
            .map(|f| OutputFile {
                file: f.clone(),
                bytes: std::fs::metadata(out_dir.join(f)).map_or(0, |m| m.len()),
            })
            .collect();
        Stamp {
            fingerprint,
            outputs,
        }
    }

    /// The stamp in `out_dir`, if there is a readable one.
    pub fn read(out_dir: &Path) -> Option<Stamp> {
        let text = std::fs::read_to_string(out_dir.join(STAMP_FILE)).ok()?;
        serde_json::from_str(&text).ok()
    }

    /// The stamp as JSON text.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// `Ok` when the outputs in `out_dir` are up to date for `fingerprint`,
    /// else why not (for the debug log).
    pub fn check(&self, out_dir: &Path, fingerprint: &str) -> Result<(), String> {
        if self.fingerprint != fingerprint {
            return Err("an input changed (scene, source, plugin or voxflex itself)".into());
        }
        if self.outputs.is_empty() {
            return Err("the last run recorded no outputs".into());
        }
        for o in &self.outputs {
            let path = out_dir.join(&o.file);
            match std::fs::metadata(&path) {
                Ok(m) if m.is_file() && m.len() == o.bytes && o.bytes > 0 => {}
                Ok(m) if m.is_file() => {
                    return Err(format!(
                        "{} is {} bytes, the last run wrote {}",
                        path.display(),
                        m.len(),
                        o.bytes
                    ));
                }
                _ => return Err(format!("{} is gone", path.display())),
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Fixture {
        dir: tempfile::TempDir,
    }

    impl Fixture {
        fn new() -> Self {
            Self {
                dir: tempfile::tempdir().unwrap(),
            }
        }
        fn path(&self, name: &str) -> PathBuf {
            self.dir.path().join(name)
        }
        fn print(&self, plugin: &Path, source: &Path, host: &str) -> String {
            fingerprint(&Inputs {
                scene_text: "[scene]\n",
                out_dir: &self.path("out"),
                plugins: &[plugin],
                source: Some(source.to_path_buf()),
                host: host.into(),
            })
        }
    }

    #[test]
    fn same_size_content_changes_are_seen_even_with_the_mtime_kept() {
        let f = Fixture::new();
        let (plugin, src) = (f.path("libvoxflex_p.so"), f.path("v.nii"));
        std::fs::write(&plugin, b"plugin-a").unwrap();
        std::fs::write(&src, b"voxels-a").unwrap();
        let before = f.print(&plugin, &src, "host-1");
        assert_eq!(before, f.print(&plugin, &src, "host-1"), "deterministic");
        let mtime = std::fs::metadata(&src).unwrap().modified().unwrap();
        std::fs::write(&src, b"voxels-b").unwrap();
        std::fs::File::options()
            .write(true)
            .open(&src)
            .unwrap()
            .set_modified(mtime)
            .unwrap();
        assert_ne!(before, f.print(&plugin, &src, "host-1"), "source bytes");
        std::fs::write(&src, b"voxels-a").unwrap();
        assert_eq!(before, f.print(&plugin, &src, "host-1"));
        std::fs::write(&plugin, b"plugin-b").unwrap();
        assert_ne!(before, f.print(&plugin, &src, "host-1"), "plugin bytes");
        std::fs::write(&plugin, b"plugin-a").unwrap();
        assert_ne!(before, f.print(&plugin, &src, "host-2"), "host binary");
    }

    #[test]
    fn the_detached_data_file_of_a_header_is_hashed() {
        let f = Fixture::new();
        let plugin = f.path("p.so");
        std::fs::write(&plugin, b"p").unwrap();
        let mhd = f.path("v.mhd");
        std::fs::write(
            &mhd,
            "NDims = 3\nDimSize = 2 1 1\nElementType = MET_UCHAR\nElementDataFile = v.raw\n",
        )
        .unwrap();
        std::fs::write(f.path("v.raw"), [1u8, 2]).unwrap();
        let before = f.print(&plugin, &mhd, "h");
        std::fs::write(f.path("v.raw"), [1u8, 3]).unwrap();
        assert_ne!(before, f.print(&plugin, &mhd, "h"));
    }

    #[cfg(unix)]
    #[test]
    fn devices_are_never_read() {
        // Reading /dev/zero would never end.
        let id = file_identity(Path::new("/dev/zero"));
        assert!(id.contains("not a regular file"), "{id}");
    }

    #[test]
    fn outputs_must_keep_their_recorded_non_zero_size() {
        let f = Fixture::new();
        let out = f.path("out");
        std::fs::create_dir(&out).unwrap();
        std::fs::write(out.join("a.png"), b"png").unwrap();
        std::fs::write(out.join("empty.nii"), b"").unwrap();
        let s = Stamp::record("fp".into(), &out, &["a.png".into()]);
        assert_eq!(s.check(&out, "fp"), Ok(()));
        assert!(s.check(&out, "other").is_err());
        std::fs::write(out.join("a.png"), b"").unwrap();
        let e = s.check(&out, "fp").unwrap_err();
        assert!(e.contains("0 bytes, the last run wrote 3"), "{e}");
        std::fs::remove_file(out.join("a.png")).unwrap();
        assert!(s.check(&out, "fp").unwrap_err().contains("gone"));
        // A file that was empty when recorded is never current.
        let s = Stamp::record("fp".into(), &out, &["empty.nii".into()]);
        assert!(s.check(&out, "fp").is_err());
        // Round trip through the file.
        let s = Stamp::record("fp".into(), &out, &["empty.nii".into()]);
        std::fs::write(out.join(STAMP_FILE), s.to_json()).unwrap();
        assert_eq!(Stamp::read(&out), Some(s));
    }
}
