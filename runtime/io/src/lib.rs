//! # voxflex-io
//!
//! Every file format voxflex reads or writes: volumes (NIfTI-1, NRRD,
//! MetaImage), PNG slice snapshots, tetrahedral meshes (VTU, Gmsh MSH,
//! TetGen) and triangle surfaces (OFF, OBJ, STL; [`surface_mesh`]). It owns
//! the format dependencies (`nifti`, `image`, `flate2`, `tobj`, `stl_io`).
//!
//! Its own crate because no plugin reads files: the deformation and render
//! plugins (and the ABI) depend on voxflex-core alone, so a change to a
//! reader recompiles only the crates that load or save data (the host, the
//! CLI, the mesh-model framework that reads mesh files, the phantoms'
//! source loader) — not the renderer or the plugins' kernels.
//!
//! Reading and writing volumes: NIfTI-1 ([`nifti`]), MetaImage
//! ([`metaimage`]), NRRD ([`nrrd`]) and PNG slice snapshots ([`png`]).
//!
//! [`read_volume`] picks the reader from the file name. Every reader validates
//! the header before it touches the data and refuses hostile or damaged input
//! with **one** [`IoError`] that names the file, the header field at fault and
//! what to do — never a panic:
//!
//! - dims that are zero, negative, or whose product (checked arithmetic)
//!   exceeds [`ReadOptions::max_voxels`];
//! - spacing that is NaN, infinite, zero or negative;
//! - a data length that disagrees with dims × bytes per voxel, too short *or*
//!   too long;
//! - a truncated or corrupt gzip/zlib stream, an unknown data type, a missing
//!   data file, or text that is not a header at all.
//!
//! Geometry: every reader maps voxel `(i, j, k)` to
//! `origin + (i, j, k) * spacing` (millimetres, see [`crate::grid`]). Header
//! rotations (NIfTI sform/qform, MetaImage `TransformMatrix`, NRRD
//! `space directions`) and axis flips are **not applied**: the origin is the
//! header's position of voxel 0 and the spacing is the length of each axis
//! step. A header with a non-diagonal rotation logs one `tracing` warning.
//!
//! Types that voxflex does not hold natively are converted when read:
//! `i8` → `i16` (exact); `i32`, `u32`, `i64`, `u64`, `f64` → `f32` (rounded
//! to f32 precision, exact for integers up to 2²⁴).
//!
//! NaN and ±∞ voxels of f32 files are counted and, by default, replaced
//! with a warning ([`crate::non_finite`] gives the policy);
//! [`read_volume_with`] can refuse them instead.
//!
//! Writes go through [`write_atomically`]: a temporary file in the target's
//! directory, renamed over the target only once it is complete.

#![warn(missing_docs)]

pub mod metaimage;
pub mod msh;
pub mod nifti;
pub mod nrrd;
mod oblique_resample;
pub mod off;
pub mod orientation;
pub mod png;
pub mod surface_mesh;
pub mod tetgen;
pub mod vtu;

// The voxflex-core modules this crate builds on, imported at the root so
// `crate::grid`, `crate::volume`, ... read as they did when the readers were
// a module of voxflex-core.
use voxflex_core::{error, grid, non_finite, tet_mesh, volume, with_voxels};

use crate::error::IoError;
use crate::non_finite::{NonFinitePolicy, apply_policy};
use crate::volume::{Volume, VolumeView, VoxelData};
use std::fs::File;
use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
pub use voxflex_core::oblique::ObliquePlacement;

/// Limits applied while reading untrusted files.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReadOptions {
    /// Largest accepted number of voxels (`dims[0] * dims[1] * dims[2]`).
    /// A header that asks for more is refused before any data is allocated.
    /// Default: 1024³ (1 GiB of u8, 4 GiB of f32).
    pub max_voxels: usize,
    /// What an oblique header (voxel axes rotated against the world axes
    /// by other than multiples of 90°) becomes: reordered onto the closest
    /// axes (default) or resampled where the header puts it; see
    /// [`voxflex_core::oblique`].
    pub oblique: ObliquePlacement,
}

impl ReadOptions {
    /// The default cap on voxels per volume: 1024³.
    pub const DEFAULT_MAX_VOXELS: usize = 1 << 30;
}

impl Default for ReadOptions {
    fn default() -> Self {
        Self {
            max_voxels: Self::DEFAULT_MAX_VOXELS,
            oblique: ObliquePlacement::ClosestAxes,
        }
    }
}

/// The file formats voxflex reads, as recognised from a file name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum VolumeFormat {
    /// NIfTI-1 single file, `.nii` or `.nii.gz` (gzip detected from the bytes).
    Nifti,
    /// MetaImage: `.mhd` header with a separate data file, or `.mha` with the
    /// data in the same file.
    MetaImage,
    /// NRRD: `.nrrd` with attached data, or `.nhdr` with a detached data file.
    Nrrd,
}

impl VolumeFormat {
    /// The format a file name's extension names (case-insensitive), if any.
    pub fn from_path(path: &Path) -> Option<Self> {
        let name = path.file_name()?.to_string_lossy().to_ascii_lowercase();
        if name.ends_with(".nii") || name.ends_with(".nii.gz") {
            Some(Self::Nifti)
        } else if name.ends_with(".mhd") || name.ends_with(".mha") {
            Some(Self::MetaImage)
        } else if name.ends_with(".nrrd") || name.ends_with(".nhdr") {
            Some(Self::Nrrd)
        } else {
            None
        }
    }
}

/// The extensions [`read_volume`] understands, for messages.
pub const READ_EXTENSIONS: &str = ".nii, .nii.gz, .mhd, .mha, .nrrd, .nhdr";

/// Reads a volume, choosing the reader from the file extension
/// ([`VolumeFormat::from_path`]).
///
/// Spacing and origin of the result are in millimetres; see the module docs
/// for what is validated and how geometry is interpreted.
///
/// NaN and ±∞ voxels are replaced under the default
/// [`NonFinitePolicy::Replace`](crate::non_finite::NonFinitePolicy) (with a
/// warning giving the counts); [`read_volume_with`] chooses the policy.
pub fn read_volume(path: &Path, opts: &ReadOptions) -> Result<Volume, IoError> {
    read_volume_with(path, opts, NonFinitePolicy::Replace, None)
}

/// [`read_volume`] with the non-finite `policy` and the value NaN voxels
/// become (`nan_to`, volume units; default the smallest finite value); see
/// [`crate::non_finite`]. A refusal is [`IoError::NonFinite`].
pub fn read_volume_with(
    path: &Path,
    opts: &ReadOptions,
    policy: NonFinitePolicy,
    nan_to: Option<f32>,
) -> Result<Volume, IoError> {
    let mut volume = read_volume_raw(path, opts)?;
    let count =
        apply_policy(&mut volume.data, policy, nan_to).map_err(|message| IoError::NonFinite {
            path: path.to_path_buf(),
            message,
        })?;
    if count.total() > 0 {
        let (lo, hi) = count.finite_range.unwrap_or_default();
        tracing::warn!(
            "{}: {} replaced: NaN by {}, +inf by {hi}, -inf by {lo} (the finite range); set \
             `[volume] non_finite = \"refuse\"` to refuse such a file",
            path.display(),
            count.describe(),
            nan_to.filter(|v| v.is_finite()).unwrap_or(lo),
        );
    }
    Ok(volume)
}

/// The reader's volume as the file holds it (non-finite voxels kept).
fn read_volume_raw(path: &Path, opts: &ReadOptions) -> Result<Volume, IoError> {
    match VolumeFormat::from_path(path) {
        Some(VolumeFormat::Nifti) => nifti::read_nifti(path, opts),
        Some(VolumeFormat::MetaImage) => metaimage::read_metaimage(path, opts),
        Some(VolumeFormat::Nrrd) => nrrd::read_nrrd(path, opts),
        None => Err(IoError::Unsupported {
            path: path.to_path_buf(),
            message: format!(
                "unknown volume file extension; voxflex reads {READ_EXTENSIONS} \
                 (convert other formats, e.g. DICOM series, to NIfTI first)"
            ),
        }),
    }
}

/// Writes a volume, choosing the writer from the file extension. Only NIfTI
/// (`.nii`, `.nii.gz`) is written; see [`nifti::write_nifti`].
pub fn write_volume(path: &Path, volume: VolumeView<'_>) -> Result<(), IoError> {
    match VolumeFormat::from_path(path) {
        Some(VolumeFormat::Nifti) => nifti::write_nifti(path, volume),
        _ => Err(IoError::Unsupported {
            path: path.to_path_buf(),
            message: "voxflex writes volumes as NIfTI only; name the output `.nii` or `.nii.gz`"
                .into(),
        }),
    }
}

static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Removes the temporary file unless the write completed.
struct TempGuard {
    path: PathBuf,
    armed: bool,
}

impl Drop for TempGuard {
    fn drop(&mut self) {
        if self.armed {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

/// Writes `path` atomically: `write` fills a temporary file created in the
/// same directory (so the final rename never crosses file systems), the file
/// is flushed and synced, then renamed over `path`.
///
/// If `write` fails (or panics), or any step fails, the temporary file is
/// removed and an existing file at `path` is left untouched: a reader never
/// sees a half-written file and a failed write never loses the old data.
pub fn write_atomically<F>(path: &Path, write: F) -> Result<(), IoError>
where
    F: FnOnce(&mut dyn Write) -> std::io::Result<()>,
{
    let io_err = |p: &Path, source: std::io::Error| IoError::Io {
        path: p.to_path_buf(),
        source,
    };
    let file_name = path.file_name().ok_or_else(|| IoError::InvalidRequest {
        path: path.to_path_buf(),
        message: "output path has no file name; give a file path such as `out.nii.gz`".into(),
    })?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let n = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    let tmp_name = format!(
        ".{}.voxflex-tmp-{}-{n}",
        file_name.to_string_lossy(),
        std::process::id()
    );
    let tmp_path = dir.join(tmp_name);
    let file = File::options()
        .write(true)
        .create_new(true)
        .open(&tmp_path)
        .map_err(|e| io_err(path, e))?;
    let mut guard = TempGuard {
        path: tmp_path.clone(),
        armed: true,
    };
    let mut writer = BufWriter::with_capacity(1 << 20, file);
    write(&mut writer).map_err(|e| io_err(path, e))?;
    let file = writer
        .into_inner()
        .map_err(|e| io_err(path, e.into_error()))?;
    file.sync_all().map_err(|e| io_err(path, e))?;
    drop(file);
    std::fs::rename(&tmp_path, path).map_err(|e| io_err(path, e))?;
    guard.armed = false;
    // Make the rename itself durable (best effort: not every platform lets a
    // directory be opened and synced).
    if let Ok(d) = File::open(&dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

// ---------------------------------------------------------------------------
// Shared machinery of the readers.
// ---------------------------------------------------------------------------

/// A header-field error.
pub(crate) fn header_err(path: &Path, field: &str, message: impl Into<String>) -> IoError {
    IoError::Header {
        path: path.to_path_buf(),
        field: field.to_string(),
        message: message.into(),
    }
}

/// Refuses a path that exists but is not a regular file (a FIFO, a device
/// such as `/dev/zero`, a directory) before it is opened: opening a FIFO
/// blocks until a writer appears, and a device never ends. A missing path
/// passes, so the caller's open names it.
pub(crate) fn refuse_non_regular(path: &Path) -> Result<(), IoError> {
    match std::fs::metadata(path) {
        Ok(m) if !m.is_file() => Err(IoError::InvalidRequest {
            path: path.to_path_buf(),
            message: format!(
                "is not a regular file (it is {}); voxflex reads volumes from regular files only",
                file_kind(&m)
            ),
        }),
        _ => Ok(()),
    }
}

/// `a directory`, `a FIFO`, … for messages.
pub fn file_kind(m: &std::fs::Metadata) -> &'static str {
    let t = m.file_type();
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt as _;
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_char_device() || t.is_block_device() {
            return "a device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_dir() {
        "a directory"
    } else if t.is_file() {
        "a regular file"
    } else {
        "not a regular file"
    }
}

/// The files a volume's voxels come from: the file itself and, for a
/// MetaImage `.mhd` or NRRD `.nhdr` header with detached data, the data file
/// it names (resolved relative to the header). The header is parsed, the
/// data is not read. Used to fingerprint a run's inputs.
pub fn volume_files(path: &Path) -> Result<Vec<PathBuf>, IoError> {
    let mut files = vec![path.to_path_buf()];
    let detached = match VolumeFormat::from_path(path) {
        Some(VolumeFormat::MetaImage) => metaimage::detached_data_file(path)?,
        Some(VolumeFormat::Nrrd) => nrrd::detached_data_file(path)?,
        _ => None,
    };
    files.extend(detached);
    Ok(files)
}

/// Opens a file for reading, naming it in the error.
pub(crate) fn open(path: &Path) -> Result<File, IoError> {
    refuse_non_regular(path)?;
    File::open(path).map_err(|source| IoError::Io {
        path: path.to_path_buf(),
        source: if source.kind() == std::io::ErrorKind::NotFound {
            std::io::Error::new(
                std::io::ErrorKind::NotFound,
                "no such file; check the path (a relative path starts from the current \
                 directory)",
            )
        } else {
            source
        },
    })
}

/// Length of an open file in bytes.
pub(crate) fn file_len(path: &Path, file: &File) -> Result<u64, IoError> {
    file.metadata()
        .map(|m| m.len())
        .map_err(|source| IoError::Io {
            path: path.to_path_buf(),
            source,
        })
}

/// Scalar types found in files, before conversion to a voxflex type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum RawType {
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    U64,
    I64,
    F32,
    F64,
}

impl RawType {
    /// Bytes per value.
    pub(crate) fn size(self) -> usize {
        match self {
            RawType::U8 | RawType::I8 => 1,
            RawType::U16 | RawType::I16 => 2,
            RawType::U32 | RawType::I32 | RawType::F32 => 4,
            RawType::U64 | RawType::I64 | RawType::F64 => 8,
        }
    }

    /// Name for messages.
    pub(crate) fn name(self) -> &'static str {
        match self {
            RawType::U8 => "uint8",
            RawType::I8 => "int8",
            RawType::U16 => "uint16",
            RawType::I16 => "int16",
            RawType::U32 => "uint32",
            RawType::I32 => "int32",
            RawType::U64 => "uint64",
            RawType::I64 => "int64",
            RawType::F32 => "float32",
            RawType::F64 => "float64",
        }
    }
}

/// Validates header dims: every axis positive, the product (checked) within
/// `max_voxels`. `raw` holds the values as written (possibly negative).
pub(crate) fn validate_dims(
    path: &Path,
    field: &str,
    raw: [i64; 3],
    max_voxels: usize,
) -> Result<[usize; 3], IoError> {
    let mut dims = [0usize; 3];
    for (axis, (&r, d)) in raw.iter().zip(dims.iter_mut()).enumerate() {
        if r <= 0 {
            return Err(header_err(
                path,
                field,
                format!(
                    "size along axis {axis} is {r}, but every size must be a positive voxel count \
                     (dims {raw:?}); the header is damaged or not a 3-D image"
                ),
            ));
        }
        *d = usize::try_from(r).map_err(|_| {
            header_err(
                path,
                field,
                format!("size {r} along axis {axis} does not fit this machine's address space"),
            )
        })?;
    }
    let total = dims[0]
        .checked_mul(dims[1])
        .and_then(|v| v.checked_mul(dims[2]));
    match total {
        Some(n) if n <= max_voxels => Ok(dims),
        _ => Err(header_err(
            path,
            field,
            format!(
                "dims {} × {} × {} = {} voxels exceed the limit of {max_voxels} voxels \
                 (ReadOptions::max_voxels); if the volume is genuine, raise the limit, \
                 otherwise the header is damaged",
                dims[0],
                dims[1],
                dims[2],
                total.map_or_else(|| "more than usize::MAX".to_string(), |n| n.to_string()),
            ),
        )),
    }
}

/// Validates voxel spacing (mm): finite and strictly positive on every axis.
pub(crate) fn validate_spacing(
    path: &Path,
    field: &str,
    spacing: [f64; 3],
) -> Result<glam::DVec3, IoError> {
    for (axis, &s) in spacing.iter().enumerate() {
        if !s.is_finite() || s <= 0.0 {
            return Err(header_err(
                path,
                field,
                format!(
                    "spacing along axis {axis} is {s}, but spacing must be a finite positive \
                     length in mm (got {spacing:?}); fix the header"
                ),
            ));
        }
    }
    Ok(glam::DVec3::from_array(spacing))
}

/// Validates an origin (mm): finite on every axis.
pub(crate) fn validate_origin(
    path: &Path,
    field: &str,
    origin: [f64; 3],
) -> Result<glam::DVec3, IoError> {
    if origin.iter().any(|v| !v.is_finite()) {
        return Err(header_err(
            path,
            field,
            format!("origin {origin:?} is not finite; fix the header"),
        ));
    }
    Ok(glam::DVec3::from_array(origin))
}

/// How voxel data is laid out in a file: everything [`read_voxels`] needs to
/// check and decode it.
pub(crate) struct DataSpec<'a> {
    /// File named when the *header* is wrong (length mismatch).
    pub header_path: &'a Path,
    /// File named when the *data* is damaged (decompression failure).
    pub data_path: &'a Path,
    /// Header field that carries the dims (named in length errors).
    pub dims_field: &'a str,
    /// Validated dims.
    pub dims: [usize; 3],
    /// Scalar type in the file.
    pub ty: RawType,
    /// Multi-byte values are big-endian.
    pub big_endian: bool,
    /// The stream is decompressed (errors from it mean a damaged stream).
    pub compressed: bool,
    /// Bytes available from the data start to the end of an uncompressed
    /// file, when known: checked against the need before reading.
    pub available: Option<u64>,
}

impl DataSpec<'_> {
    /// Bytes the header asks for (checked).
    pub(crate) fn needed_bytes(&self) -> Result<u64, IoError> {
        let n = self.dims[0] as u64;
        n.checked_mul(self.dims[1] as u64)
            .and_then(|v| v.checked_mul(self.dims[2] as u64))
            .and_then(|v| v.checked_mul(self.ty.size() as u64))
            .ok_or_else(|| {
                header_err(
                    self.header_path,
                    self.dims_field,
                    format!("dims {:?} overflow the byte count", self.dims),
                )
            })
    }

    fn describe_need(&self, needed: u64) -> String {
        format!(
            "dims {} × {} × {} of {} ({} byte{} each) need {needed} bytes",
            self.dims[0],
            self.dims[1],
            self.dims[2],
            self.ty.name(),
            self.ty.size(),
            if self.ty.size() == 1 { "" } else { "s" },
        )
    }

    pub(crate) fn too_short(&self, got: u64, needed: u64) -> IoError {
        header_err(
            self.header_path,
            self.dims_field,
            format!(
                "the data holds only {got} bytes but {}{}: the file is truncated or the header \
                 is wrong; re-export or re-download the file",
                self.describe_need(needed),
                self.data_file_note(),
            ),
        )
    }

    fn too_long(&self, got: String, needed: u64) -> IoError {
        header_err(
            self.header_path,
            self.dims_field,
            format!(
                "the data holds {got} bytes but {}{}: the header's dims or data type do not \
                 match the data; fix the header",
                self.describe_need(needed),
                self.data_file_note(),
            ),
        )
    }

    fn data_file_note(&self) -> String {
        if self.data_path == self.header_path {
            String::new()
        } else {
            format!(" (data file {})", self.data_path.display())
        }
    }

    fn stream_error(&self, got: u64, needed: u64, e: &std::io::Error) -> IoError {
        if self.compressed {
            IoError::Corrupt {
                path: self.data_path.to_path_buf(),
                message: format!(
                    "the compressed data stream is truncated or corrupt ({e}) after {got} of \
                     {needed} decompressed bytes{}; the file was probably cut short by an \
                     interrupted download or copy — obtain a complete copy",
                    if self.data_path == self.header_path {
                        String::new()
                    } else {
                        format!(" (data file of header {})", self.header_path.display())
                    }
                ),
            }
        } else {
            IoError::Io {
                path: self.data_path.to_path_buf(),
                source: std::io::Error::new(e.kind(), e.to_string()),
            }
        }
    }
}

/// Reads until `buf` is full or the stream ends; returns the bytes read.
fn read_full(reader: &mut dyn Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let (filled, err) = read_full_counted(reader, buf);
    match err {
        Some(e) => Err(e),
        None => Ok(filled),
    }
}

/// Like [`read_full`], but also reports how many bytes arrived before an
/// error.
fn read_full_counted(reader: &mut dyn Read, buf: &mut [u8]) -> (usize, Option<std::io::Error>) {
    let mut filled = 0;
    while filled < buf.len() {
        match reader.read(&mut buf[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return (filled, Some(e)),
        }
    }
    (filled, None)
}

/// Reads and discards exactly `n` bytes (a header remainder, a byte skip).
/// Returns the bytes actually skipped (fewer when the stream ends).
pub(crate) fn skip_bytes(reader: &mut dyn Read, n: u64) -> std::io::Result<u64> {
    std::io::copy(&mut reader.take(n), &mut std::io::sink())
}

const CHUNK_BYTES: usize = 1 << 20;

/// Reads `n` values of `N` bytes each, decoding each with `dec`.
fn decode_stream<T, const N: usize>(
    reader: &mut dyn Read,
    spec: &DataSpec<'_>,
    needed: u64,
    n: usize,
    dec: impl Fn([u8; N]) -> T,
) -> Result<Vec<T>, IoError> {
    let mut out: Vec<T> = Vec::new();
    out.try_reserve_exact(n)
        .map_err(|_| IoError::InvalidRequest {
            path: spec.header_path.to_path_buf(),
            message: format!(
                "cannot allocate memory for {} ({needed} bytes); lower the resolution or use a \
             machine with more memory",
                spec.describe_need(needed)
            ),
        })?;
    let per_chunk = (CHUNK_BYTES / N).max(1);
    let mut buf = vec![0u8; per_chunk * N];
    let mut got: u64 = 0;
    while out.len() < n {
        let want = (n - out.len()).min(per_chunk) * N;
        let (filled, err) = read_full_counted(reader, &mut buf[..want]);
        got += filled as u64;
        if let Some(e) = err {
            return Err(spec.stream_error(got, needed, &e));
        }
        out.extend(
            buf[..filled - filled % N]
                .chunks_exact(N)
                .map(|c| dec(c.try_into().expect("chunks of N bytes"))),
        );
        if filled < want {
            return Err(spec.too_short(got, needed));
        }
    }
    Ok(out)
}

/// Reads the voxel data described by `spec` from `reader`, positioned at the
/// first data byte. Checks the length both ways (too short: error; anything
/// left after the last voxel: error) and converts non-native types (see the
/// module docs).
pub(crate) fn read_voxels(
    reader: &mut dyn Read,
    spec: &DataSpec<'_>,
) -> Result<VoxelData, IoError> {
    let needed = spec.needed_bytes()?;
    if let Some(avail) = spec.available {
        if avail < needed {
            return Err(spec.too_short(avail, needed));
        }
        if avail > needed {
            return Err(spec.too_long(avail.to_string(), needed));
        }
    }
    let n = spec.dims[0] * spec.dims[1] * spec.dims[2];
    let big = spec.big_endian;
    // `decode_stream` of values of type `$t` in the file's byte order, each
    // mapped by `$map`: one closure per byte order, so the decoder is
    // inlined into the loop (a function pointer per voxel kept it scalar:
    // ~75 ms for a 70 MB CT, most of its load).
    macro_rules! decode {
        ($t:ty, $map:expr) => {
            if big {
                decode_stream(reader, spec, needed, n, |a| $map(<$t>::from_be_bytes(a)))
            } else {
                decode_stream(reader, spec, needed, n, |a| $map(<$t>::from_le_bytes(a)))
            }
        };
    }
    let data = match spec.ty {
        RawType::U8 => VoxelData::U8(decode_stream::<u8, 1>(reader, spec, needed, n, |a| a[0])?),
        RawType::I8 => VoxelData::I16(decode_stream::<i16, 1>(reader, spec, needed, n, |a| {
            i16::from(a[0] as i8)
        })?),
        RawType::U16 => VoxelData::U16(decode!(u16, |v| v)?),
        RawType::I16 => VoxelData::I16(decode!(i16, |v| v)?),
        RawType::F32 => VoxelData::F32(decode!(f32, |v| v)?),
        RawType::U32 => VoxelData::F32(decode!(u32, |v| v as f32)?),
        RawType::I32 => VoxelData::F32(decode!(i32, |v| v as f32)?),
        RawType::U64 => VoxelData::F32(decode!(u64, |v| v as f32)?),
        RawType::I64 => VoxelData::F32(decode!(i64, |v| v as f32)?),
        RawType::F64 => VoxelData::F32(decode!(f64, |v| v as f32)?),
    };
    // Anything after the last voxel means the header and the data disagree.
    let mut probe = [0u8; 1];
    let extra = read_full(reader, &mut probe).map_err(|e| spec.stream_error(needed, needed, &e))?;
    if extra > 0 {
        const COUNT_LIMIT: u64 = 64 << 20;
        let rest = skip_bytes(reader, COUNT_LIMIT).unwrap_or(0);
        let got = if rest >= COUNT_LIMIT {
            format!("more than {}", needed + 1 + rest)
        } else {
            (needed + 1 + rest).to_string()
        };
        return Err(spec.too_long(got, needed));
    }
    Ok(data)
}

/// True when the stream starts with the gzip magic bytes.
pub(crate) fn is_gzip(prefix: &[u8]) -> bool {
    prefix.len() >= 2 && prefix[0] == 0x1f && prefix[1] == 0x8b
}

#[cfg(test)]
pub(crate) mod test_util {
    //! Helpers shared by the readers' tests.
    use crate::error::IoError;
    use std::path::Path;

    /// Asserts that `r` is an error whose message names the file and
    /// contains every `needle`; returns the message.
    pub fn expect_err<T: std::fmt::Debug>(
        r: Result<T, IoError>,
        file: &Path,
        needles: &[&str],
    ) -> String {
        let msg = match r {
            Ok(v) => panic!("expected an error for {}, got {v:?}", file.display()),
            Err(e) => e.to_string(),
        };
        let name = file.file_name().map(|n| n.to_string_lossy().to_string());
        if let Some(name) = name {
            assert!(
                msg.contains(&name),
                "message does not name the file {name}: {msg}"
            );
        }
        for n in needles {
            assert!(msg.contains(n), "message lacks `{n}`: {msg}");
        }
        eprintln!("refused as expected: {msg}");
        msg
    }

    /// `values` (x fastest, `dims`) with the axes where `reverse` is set
    /// reversed: how a reader reorders a file whose header runs those
    /// axes backwards in voxflex's RAS world (an LPS file's x and y).
    pub fn reversed<T: Clone>(values: &[T], dims: [usize; 3], reverse: [bool; 3]) -> Vec<T> {
        let mut out = Vec::with_capacity(values.len());
        let pick = |i: usize, a: usize| if reverse[a] { dims[a] - 1 - i } else { i };
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let (i, j, k) = (pick(i, 0), pick(j, 1), pick(k, 2));
                    out.push(values[i + dims[0] * (j + dims[1] * k)].clone());
                }
            }
        }
        out
    }

    /// gzip-compresses bytes.
    pub fn gzip(data: &[u8]) -> Vec<u8> {
        use std::io::Write;
        let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        e.write_all(data).expect("gzip to memory");
        e.finish().expect("gzip to memory")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Grid;
    use glam::DVec3;

    #[test]
    fn atomic_write_replaces_only_on_success() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("out.bin");
        write_atomically(&p, |w| w.write_all(b"first")).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"first");
        let r = write_atomically(&p, |w| {
            w.write_all(b"partial")?;
            Err(std::io::Error::other("disk on fire"))
        });
        let msg = r.unwrap_err().to_string();
        assert!(
            msg.contains("out.bin") && msg.contains("disk on fire"),
            "{msg}"
        );
        assert_eq!(
            std::fs::read(&p).unwrap(),
            b"first",
            "old data must survive"
        );
        let leftovers: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(leftovers.len(), 1, "temporary file must be removed");
    }

    #[test]
    fn unknown_extension_is_refused() {
        let p = Path::new("/tmp/volume.dcm");
        let msg = read_volume(p, &ReadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("volume.dcm") && msg.contains(".nii.gz"),
            "{msg}"
        );
        let v = Volume::new(
            Grid::new([1, 1, 1], DVec3::ONE, DVec3::ZERO),
            VoxelData::U8(vec![1]),
        )
        .unwrap();
        let msg = write_volume(Path::new("/tmp/x.nrrd"), v.view())
            .unwrap_err()
            .to_string();
        assert!(msg.contains("NIfTI"), "{msg}");
    }

    #[test]
    fn formats_from_names() {
        assert_eq!(
            VolumeFormat::from_path(Path::new("a/B.NII.GZ")),
            Some(VolumeFormat::Nifti)
        );
        assert_eq!(
            VolumeFormat::from_path(Path::new("x.mha")),
            Some(VolumeFormat::MetaImage)
        );
        assert_eq!(
            VolumeFormat::from_path(Path::new("x.nhdr")),
            Some(VolumeFormat::Nrrd)
        );
        assert_eq!(VolumeFormat::from_path(Path::new("x.gz")), None);
    }

    mod fuzz {
        use super::super::test_util::gzip;
        use super::super::*;
        use proptest::prelude::*;

        /// Valid files of every format, as (name, bytes).
        fn seeds() -> Vec<(&'static str, Vec<u8>)> {
            let dir = tempfile::tempdir().unwrap();
            let g = crate::grid::Grid::new([4, 3, 2], glam::DVec3::ONE, glam::DVec3::ZERO);
            let v = Volume::new(g, VoxelData::I16((0..24).collect())).unwrap();
            let nii = dir.path().join("a.nii");
            nifti::write_nifti(&nii, v.view()).unwrap();
            let nii = std::fs::read(nii).unwrap();
            let data: Vec<u8> = (0..24i16).flat_map(|x| x.to_le_bytes()).collect();
            let mut nrrd = b"NRRD0004\ntype: short\ndimension: 3\nsizes: 4 3 2\n\
                             spacings: 1 1 1\nendian: little\nencoding: gzip\n\n"
                .to_vec();
            nrrd.extend(gzip(&data));
            let mut mha = b"NDims = 3\nDimSize = 4 3 2\nElementType = MET_SHORT\n\
                            ElementSpacing = 1 1 1\nElementDataFile = LOCAL\n"
                .to_vec();
            mha.extend(&data);
            vec![
                ("f.nii.gz", gzip(&nii)),
                ("f.nii", nii),
                ("f.nrrd", nrrd),
                ("f.mha", mha),
            ]
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(256))]
            /// Corrupted files are refused or read, never a panic.
            #[test]
            fn corrupted_files_never_panic(
                which in 0usize..4,
                edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..6),
                cut in any::<prop::sample::Index>(),
                do_cut in any::<bool>(),
            ) {
                let (name, mut bytes) = seeds().swap_remove(which);
                for (i, b) in edits {
                    let i = i.index(bytes.len());
                    bytes[i] = b;
                }
                if do_cut {
                    bytes.truncate(cut.index(bytes.len() + 1));
                }
                let dir = tempfile::tempdir().unwrap();
                let p = dir.path().join(name);
                std::fs::write(&p, &bytes).unwrap();
                let _ = read_volume(
                    &p,
                    &ReadOptions {
                        max_voxels: 1 << 16,
                        ..Default::default()
                    },
                );
            }
        }
    }

    /// NaN and ±∞ voxels never come out of `read_volume`: replaced by
    /// default, refused on request, with the counts in the message.
    #[test]
    fn non_finite_voxels_are_replaced_or_refused_at_load() {
        let dir = tempfile::tempdir().unwrap();
        let g = crate::grid::Grid::new([3, 2, 1], glam::DVec3::ONE, glam::DVec3::ZERO);
        let values = vec![1.0, f32::NAN, 4.0, f32::INFINITY, f32::NEG_INFINITY, -2.0];
        let v = Volume::new(g, VoxelData::F32(values)).unwrap();
        let p = dir.path().join("bad.nii");
        nifti::write_nifti(&p, v.view()).unwrap();
        let read = read_volume(&p, &ReadOptions::default()).unwrap();
        let VoxelData::F32(got) = &read.data else {
            panic!("f32 in, f32 out");
        };
        let mut got = got.clone();
        got.sort_by(f32::total_cmp);
        assert_eq!(got, vec![-2.0, -2.0, -2.0, 1.0, 4.0, 4.0]);
        let read = read_volume_with(
            &p,
            &ReadOptions::default(),
            NonFinitePolicy::Replace,
            Some(-9.0),
        )
        .unwrap();
        assert!(
            read.data.as_slice().to_f32_vec().contains(&-9.0),
            "NaN → the given background"
        );
        let e = read_volume_with(&p, &ReadOptions::default(), NonFinitePolicy::Refuse, None)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("bad.nii")
                && e.contains("1 NaN, 1 +inf and 1 -inf")
                && e.contains("non_finite"),
            "{e}"
        );
    }

    #[test]
    fn dims_validation() {
        let p = Path::new("h.hdr");
        assert_eq!(validate_dims(p, "d", [2, 3, 4], 24).unwrap(), [2, 3, 4]);
        let m = validate_dims(p, "d", [2, 3, 4], 23)
            .unwrap_err()
            .to_string();
        assert!(m.contains("max_voxels"), "{m}");
        let m = validate_dims(p, "d", [i64::MAX, i64::MAX, 2], usize::MAX)
            .unwrap_err()
            .to_string();
        assert!(m.contains("more than usize::MAX"), "{m}");
        let m = validate_dims(p, "d", [2, 0, 4], 100)
            .unwrap_err()
            .to_string();
        assert!(m.contains("positive"), "{m}");
    }
}
