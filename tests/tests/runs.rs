//! Runs across time, through the real CLI: when outputs count as up to
//! date, two runs into one directory, the leftovers of killed runs, where
//! outputs may go, and the files and processes `voxflex` touches.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use voxflex_integration_tests::*;

fn up_to_date(o: &Output) -> bool {
    assert!(o.status.success(), "{}", text(o));
    stdout(o).contains("up to date")
}

/// A scene without a model: the source written back as slices and NIfTI.
fn copy_scene(source: &str, out: &Path) -> String {
    format!(
        "[scene]\nname = \"copy\"\nbackend = \"cpu\"\n\n[volume]\nsource = \"{source}\"\n\n\
         [output]\ndir = \"{}\"\nnifti = \"copy.nii.gz\"\n",
        out.display()
    )
}

/// Writes an 8×6×4 u8 MetaImage `vol.mhd` + `vol.raw` into `dir`.
fn write_mhd(dir: &Path, seed: u8) {
    std::fs::write(
        dir.join("vol.mhd"),
        "NDims = 3\nDimSize = 8 6 4\nElementSpacing = 1 1 1\nElementType = MET_UCHAR\n\
         ElementDataFile = vol.raw\n",
    )
    .unwrap();
    let data: Vec<u8> = (0..8 * 6 * 4)
        .map(|i| (i as u8).wrapping_mul(seed))
        .collect();
    std::fs::write(dir.join("vol.raw"), data).unwrap();
}

/// Rewrites `path` with `bytes` and puts its modification time back, as
/// `cp -p` of a same-size file does.
fn rewrite_keeping_mtime(path: &Path, bytes: &[u8]) {
    let mtime = std::fs::metadata(path).unwrap().modified().unwrap();
    std::fs::write(path, bytes).unwrap();
    std::fs::File::options()
        .write(true)
        .open(path)
        .unwrap()
        .set_modified(mtime)
        .unwrap();
}

#[test]
fn a_deleted_or_truncated_output_is_rebuilt_and_up_to_date_runs_write_nothing() {
    plugin_dir(&["affine"]);
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    std::fs::write(
        tmp.path().join("s.toml"),
        scene(
            "cpu",
            "cube",
            16,
            2,
            "affine",
            "field = \"twist\"\nangle_deg = 20",
            &out,
        ),
    )
    .unwrap();
    let run = || voxflex(&["run", "s.toml"], tmp.path());
    assert!(!up_to_date(&run()));
    let report = std::fs::read(out.join("metrics.json")).unwrap();
    assert!(up_to_date(&run()));
    assert_eq!(
        std::fs::read(out.join("metrics.json")).unwrap(),
        report,
        "an up-to-date run leaves the real run's metrics.json alone"
    );
    // The old main rewrote metrics.json with no outputs here, so this and
    // every later deletion went unnoticed.
    assert!(up_to_date(&run()));
    std::fs::remove_file(out.join("deformed.nii.gz")).unwrap();
    let o = run();
    assert!(!up_to_date(&o), "{}", text(&o));
    assert!(out.join("deformed.nii.gz").is_file());
    assert!(up_to_date(&run()));
    // A zero-byte output (a full disk, a truncation) is not an output.
    std::fs::write(out.join("axial.png"), b"").unwrap();
    assert!(!up_to_date(&run()));
    assert!(std::fs::metadata(out.join("axial.png")).unwrap().len() > 0);
    // Nor is a deleted report.
    std::fs::remove_file(out.join("metrics.json")).unwrap();
    assert!(!up_to_date(&run()));
    assert_eq!(metrics(&out)["up_to_date"], false);
}

#[test]
fn detached_data_and_same_size_copies_with_kept_mtimes_are_seen() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    write_mhd(tmp.path(), 3);
    std::fs::write(tmp.path().join("s.toml"), copy_scene("vol.mhd", &out)).unwrap();
    let run = || voxflex(&["run", "s.toml"], tmp.path());
    assert!(!up_to_date(&run()));
    assert!(up_to_date(&run()));
    // The voxels change in the data file; the header does not.
    let mut raw = std::fs::read(tmp.path().join("vol.raw")).unwrap();
    raw[5] ^= 0x40;
    rewrite_keeping_mtime(&tmp.path().join("vol.raw"), &raw);
    let o = run();
    assert!(
        !up_to_date(&o),
        "a changed vol.raw went unnoticed\n{}",
        text(&o)
    );
    assert!(up_to_date(&run()));

    // A same-size NIfTI copied over the source with its mtime kept.
    let nii = tmp.path().join("src.nii");
    let out2 = tmp.path().join("out2");
    std::fs::write(tmp.path().join("n.toml"), copy_scene("src.nii", &out2)).unwrap();
    let copy = |seed: u8| {
        write_mhd(tmp.path(), seed);
        let v = voxflex_io::read_volume(&tmp.path().join("vol.mhd"), &Default::default()).unwrap();
        let staged = tmp.path().join("staged.nii");
        voxflex_io::write_volume(&staged, v.view()).unwrap();
        std::fs::read(staged).unwrap()
    };
    std::fs::write(&nii, copy(5)).unwrap();
    let run2 = || voxflex(&["run", "n.toml"], tmp.path());
    assert!(!up_to_date(&run2()));
    assert!(up_to_date(&run2()));
    let other = copy(7);
    assert_eq!(other.len(), std::fs::read(&nii).unwrap().len(), "same size");
    rewrite_keeping_mtime(&nii, &other);
    assert!(!up_to_date(&run2()));
}

#[test]
fn a_rebuilt_voxflex_does_not_find_its_predecessors_outputs_current() {
    let tmp = tempfile::tempdir().unwrap();
    let bin_dir = tmp.path().join("bin");
    std::fs::create_dir(&bin_dir).unwrap();
    let bin = bin_dir.join(voxflex_bin().file_name().unwrap());
    std::fs::copy(voxflex_bin(), &bin).unwrap();
    let out = tmp.path().join("out");
    std::fs::write(
        tmp.path().join("s.toml"),
        copy_scene("phantom:cube", &out).replace("[volume]\n", "[volume]\ndims = [8, 8, 8]\n"),
    )
    .unwrap();
    let run = |bin: &Path| {
        Command::new(bin)
            .args(["run", "s.toml"])
            .current_dir(tmp.path())
            .env_remove("RUST_LOG")
            .output()
            .unwrap()
    };
    assert!(!up_to_date(&run(&bin)));
    assert!(up_to_date(&run(&bin)));
    // "Rebuild": same version string, other bytes (trailing bytes leave the
    // executable runnable).
    let mut bytes = std::fs::read(&bin).unwrap();
    bytes.extend_from_slice(b"rebuilt");
    let rebuilt = bin_dir.join("voxflex-rebuilt");
    std::fs::write(&rebuilt, bytes).unwrap();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        std::fs::set_permissions(&rebuilt, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
    assert!(!up_to_date(&run(&rebuilt)));
}

#[test]
fn a_second_run_into_a_locked_directory_says_so_and_waits() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    std::fs::create_dir(&out).unwrap();
    std::fs::write(
        tmp.path().join("s.toml"),
        copy_scene("phantom:cube", &out).replace("[volume]\n", "[volume]\ndims = [8, 8, 8]\n"),
    )
    .unwrap();
    // This test plays the first run: it holds the directory's lock.
    let lock = std::fs::File::options()
        .create(true)
        .truncate(false)
        .write(true)
        .open(out.join(voxflex_runtime::out_dir::LOCK_FILE))
        .unwrap();
    lock.lock().unwrap();
    let mut child = Command::new(voxflex_bin())
        .args(["run", "s.toml"])
        .current_dir(tmp.path())
        .env_remove("RUST_LOG")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = BufReader::new(child.stderr.take().unwrap());
    let mut seen = String::new();
    loop {
        let mut line = String::new();
        // Without a lock the run ends and stderr reaches EOF unannounced.
        if stderr.read_line(&mut line).unwrap() == 0 {
            panic!("the run never said it waits for the lock:\n{seen}");
        }
        seen.push_str(&line);
        if line.contains("waiting") {
            break;
        }
    }
    assert!(
        seen.contains("another voxflex run holds the lock") && seen.contains("out"),
        "{seen}"
    );
    assert!(
        !out.join("metrics.json").exists(),
        "nothing is written while the lock is held"
    );
    drop(lock);
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{seen}{}", text(&o));
    assert!(out.join("copy.nii.gz").is_file() && out.join("metrics.json").is_file());
}

#[test]
fn temp_files_of_a_killed_run_are_removed_by_the_next() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    std::fs::create_dir(&out).unwrap();
    // A process id that has exited.
    let mut child = Command::new(voxflex_bin())
        .arg("--version")
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    let dead = child.id();
    child.wait().unwrap();
    let stale = out.join(format!(".copy.nii.gz.voxflex-tmp-{dead}-3"));
    std::fs::write(&stale, vec![0u8; 4096]).unwrap();
    std::fs::write(
        tmp.path().join("s.toml"),
        copy_scene("phantom:cube", &out).replace("[volume]\n", "[volume]\ndims = [8, 8, 8]\n"),
    )
    .unwrap();
    let o = voxflex(&["run", "s.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    assert!(!stale.exists(), "{} was left behind", stale.display());
}

#[test]
fn outputs_stay_inside_the_output_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let work = tmp.path().join("work");
    std::fs::create_dir(&work).unwrap();
    let base = copy_scene("phantom:cube", Path::new("out"))
        .replace("[volume]\n", "[volume]\ndims = [8, 8, 8]\n");
    let cases = [
        (base.replace("dir = \"out\"", "dir = \"/\""), "`dir`"),
        (base.replace("dir = \"out\"", "dir = \"\""), "`dir`"),
        (base.replace("copy.nii.gz", "../escaped.nii.gz"), "`nifti`"),
        (
            base.replace(
                "copy.nii.gz",
                &format!("{}/abs.nii.gz", tmp.path().display()),
            ),
            "`nifti`",
        ),
        (
            format!("{base}\n[[roi]]\nname = \"../../escaped\"\nseed = [0.0, 0.0, 0.0]\n"),
            "`name`",
        ),
        (
            format!("{base}\n[render]\nfile = \"../escaped.png\"\n"),
            "`file`",
        ),
    ];
    for (s, key) in cases {
        std::fs::write(work.join("s.toml"), &s).unwrap();
        let o = voxflex(&["run", "s.toml"], &work);
        assert_eq!(o.status.code(), Some(1), "{s}\n{}", text(&o));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains(key) && err.contains("output directory"),
            "{err}"
        );
    }
    std::fs::write(work.join("s.toml"), &base).unwrap();
    let o = voxflex(&["run", "s.toml", "--out", "/"], &work);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(text(&o).contains("file system root"), "{}", text(&o));
    let escaped: Vec<PathBuf> = std::fs::read_dir(tmp.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().contains("escaped") || p.ends_with("abs.nii.gz"))
        .collect();
    assert!(escaped.is_empty(), "{escaped:?}");
}

#[test]
fn oversized_scene_files_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let mut s = copy_scene("phantom:cube", &tmp.path().join("out"))
        .replace("[volume]\n", "[volume]\ndims = [8, 8, 8]\n");
    s.push_str(&"# padding padding padding padding padding padding padding\n".repeat(20_000));
    assert!(s.len() > 1 << 20);
    std::fs::write(tmp.path().join("big.toml"), s).unwrap();
    let o = voxflex(&["run", "big.toml"], tmp.path());
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(text(&o).contains("at most 1048576 bytes"), "{}", text(&o));
    assert!(!tmp.path().join("out").exists());
    #[cfg(unix)]
    {
        let o = voxflex(&["run", "/dev/zero"], tmp.path());
        assert_eq!(o.status.code(), Some(1), "{}", text(&o));
        assert!(text(&o).contains("not a scene file"), "{}", text(&o));
    }
}

#[test]
fn render_turntable_has_the_scene_cap() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = voxflex_runtime::scene::MAX_TURNTABLE_FRAMES;
    let o = voxflex(
        &[
            "render",
            "phantom:cube",
            "--dims",
            "8,8,8",
            "--size",
            "4x4",
            "--backend",
            "cpu",
            "--out",
            "t.png",
            "--turntable",
            &(cap + 1).to_string(),
        ],
        tmp.path(),
    );
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains(&format!("use 0 to {cap}")),
        "{}",
        text(&o)
    );
    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 0);
}

#[cfg(target_os = "linux")]
#[test]
fn a_full_disk_is_an_error_not_a_panic() {
    let full = std::fs::File::options()
        .write(true)
        .open("/dev/full")
        .unwrap();
    let o = Command::new(voxflex_bin())
        .args(["plugins"])
        .env("VOXFLEX_PLUGIN_PATH", test_plugin_path())
        .stdout(full)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(err.contains("error: writing to standard output"), "{err}");
}

#[test]
fn runtime_dirs_are_removed_and_not_made_for_the_cpu() {
    let tmp = tempfile::tempdir().unwrap();
    let temp = tmp.path().join("temp");
    std::fs::create_dir(&temp).unwrap();
    let render = |backend: &str, extra: &[&str]| {
        let mut args = vec![
            "render",
            "phantom:cube",
            "--dims",
            "8,8,8",
            "--size",
            "4x4",
            "--out",
            "r.png",
            "--backend",
            backend,
        ];
        args.extend_from_slice(extra);
        Command::new(voxflex_bin())
            .args(&args)
            .current_dir(tmp.path())
            .env("TMPDIR", &temp)
            .env_remove("XDG_RUNTIME_DIR")
            .env("VOXFLEX_PLUGIN_PATH", test_plugin_path())
            .output()
            .unwrap()
    };
    let left = || std::fs::read_dir(&temp).unwrap().count();
    let o = render("cpu", &[]);
    assert!(o.status.success(), "{}", text(&o));
    // auto probes adapters (with a runtime dir); an error exit cleans up too.
    let o = render("auto", &[]);
    assert!(o.status.success(), "{}", text(&o));
    let o = render("auto", &["--preset", "nonsense"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert_eq!(left(), 0, "left behind in TMPDIR");
}

#[test]
fn plugins_lists_no_test_fixture_and_each_plugin_once() {
    plugin_dir(&["affine", "ripple", "mismatched"]);
    // What a user of target/<profile>/ sees: no fixtures.
    let o = Command::new(voxflex_bin())
        .arg("plugins")
        .env_remove("VOXFLEX_PLUGIN_PATH")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let listing = stdout(&o);
    assert!(listing.contains("affine"), "{listing}");
    assert!(
        !listing.contains("ripple") && !listing.contains("mismatched"),
        "{listing}"
    );
    // A copy under another file name, and one earlier on the path.
    let tmp = tempfile::tempdir().unwrap();
    let lib = voxflex_runtime::plugin_loader::library_file_name("affine");
    let built = target_dir().join(&lib);
    let first = tmp.path().join(&lib);
    let tmp2 = tempfile::tempdir().unwrap();
    let renamed = tmp2
        .path()
        .join(voxflex_runtime::plugin_loader::library_file_name(
            "affine-copy",
        ));
    std::fs::copy(&built, &first).unwrap();
    std::fs::copy(&built, &renamed).unwrap();
    let o = voxflex(
        &[
            "plugins",
            "--dir",
            tmp.path().to_str().unwrap(),
            "--dir",
            tmp2.path().to_str().unwrap(),
        ],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let listing = stdout(&o);
    let rows: Vec<&str> = listing
        .lines()
        .filter(|l| l.starts_with("affine "))
        .collect();
    assert_eq!(rows.len(), 1, "{listing}");
    assert!(rows[0].ends_with(&first.display().to_string()), "{listing}");
    for shadowed in [&built, &renamed] {
        assert!(
            listing.lines().any(|l| l.contains("(shadowed)")
                && l.contains(&shadowed.display().to_string())
                && l.contains(&format!("scenes get {}", first.display()))),
            "{}: {listing}",
            shadowed.display()
        );
    }
}

/// `backend = "gpu"` on a software rasteriser (lavapipe here and in CI)
/// says so on the terminal; on a hardware adapter it does not.
#[test]
fn a_software_adapter_under_backend_gpu_is_warned_about() {
    let Some(gpu) = voxflex_runtime::gpu_context::testing::test_gpu() else {
        return;
    };
    let software = gpu.info().software;
    let tmp = tempfile::tempdir().unwrap();
    let o = voxflex(
        &[
            "render",
            "phantom:cube",
            "--dims",
            "8,8,8",
            "--size",
            "4x4",
            "--backend",
            "gpu",
            "--out",
            "r.png",
        ],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(
        err.contains("a software rasteriser"),
        software,
        "{} ({software}): {err}",
        gpu.info()
    );
}
