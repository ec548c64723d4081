//! NIfTI-1 single-file volumes (`.nii`, `.nii.gz`).
//!
//! **Reading** ([`read_nifti`]): the 348-byte header is decoded by the
//! `nifti` crate (which also detects the byte order); the voxel data is read
//! by voxflex itself, streamed, so a `.nii.gz` is never held twice in memory.
//! gzip is recognised from the file's first bytes, whatever its name.
//!
//! - dims from `dim[1..=3]` (a 2-D image gets one slice); a 4-D file is
//!   accepted only when `dim[4..]` are all 1.
//! - geometry, in millimetres (`xyzt_units` metres and microns are
//!   converted; "unknown" is taken as mm): the sform (`srow_x/y/z`) when
//!   `sform_code > 0`, else the qform (quaternion, `qfac`, `pixdim[1..=3]`,
//!   `qoffset_x/y/z`) when `qform_code > 0`, else `pixdim[1..=3]` spacing
//!   at the origin, all in NIfTI's RAS world, turned into voxflex's LPS
//!   one. Axis permutations and flips are applied by reordering the
//!   voxels into voxflex's axis-aligned grid (see
//!   [`super::orientation`]): a coronal or radiologically stored file
//!   reads anatomically. An oblique header is placed along its closest
//!   axes with a warning giving the angle.
//! - data types: `uint8`, `int16`, `uint16`, `float32` as they are; `int8` →
//!   `i16`; `int32`, `uint32`, `int64`, `uint64`, `float64` → `f32`.
//! - `scl_slope`/`scl_inter`: when the slope is finite, non-zero and the pair
//!   is not the identity `(1, 0)`, values become `f32` `v * slope + inter`.
//!   A NaN or infinite slope means "no scaling", as in nibabel.
//!
//! **Writing** ([`write_nifti`]): the `nifti` crate writes only through
//! `ndarray`, which voxflex does not depend on, so the header is written here
//! byte by byte (little-endian NIfTI-1, `vox_offset` 352, no extensions,
//! `xyzt_units` mm/s, qform and sform code 1 = scanner: the grid's axes in
//! NIfTI's RAS world, x and y negated, so other tools show it the right
//! way round). NIfTI stores spacing and origin as `f32`.
//! A name ending in `.gz` is gzip-compressed.

use super::orientation::{HeaderFrame, HeaderGeometry, place};
use super::{
    DataSpec, RawType, file_len, header_err, is_gzip, open, read_voxels, skip_bytes, validate_dims,
    validate_origin, validate_spacing, write_atomically,
};
use crate::error::IoError;
use crate::volume::{Volume, VolumeView, VoxelData, VoxelSlice};
use glam::DVec3;
use rayon::prelude::*;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::Path;

/// Size of a NIfTI-1 header in bytes.
pub const HEADER_SIZE: usize = 348;
/// Offset of the voxel data in the files voxflex writes (header + 4-byte
/// extension flag).
pub const WRITE_VOX_OFFSET: usize = 352;

/// The NIfTI-1 datatype code, bits per value and voxflex raw type of
/// everything we read.
fn raw_type_of(code: i16) -> Result<RawType, &'static str> {
    Ok(match code {
        2 => RawType::U8,
        4 => RawType::I16,
        8 => RawType::I32,
        16 => RawType::F32,
        64 => RawType::F64,
        256 => RawType::I8,
        512 => RawType::U16,
        768 => RawType::U32,
        1024 => RawType::I64,
        1280 => RawType::U64,
        1 => return Err("binary (1 bit)"),
        32 => return Err("complex64"),
        128 => return Err("RGB24"),
        1536 => return Err("float128"),
        1792 => return Err("complex128"),
        2048 => return Err("complex256"),
        2304 => return Err("RGBA32"),
        _ => return Err(""),
    })
}

/// The NIfTI-1 datatype code and bits per voxel of a voxflex scalar type.
fn code_of(s: &VoxelSlice<'_>) -> (i16, i16) {
    match s {
        VoxelSlice::U8(_) => (2, 8),
        VoxelSlice::I16(_) => (4, 16),
        VoxelSlice::U16(_) => (512, 16),
        VoxelSlice::F32(_) => (16, 32),
    }
}

/// Reads a NIfTI-1 `.nii` or `.nii.gz` file (see the module docs for how the
/// header is interpreted; rotations are not applied).
///
/// Errors name the file and the header field (`dim`, `pixdim`, `datatype`,
/// `vox_offset`, …) and say what to do; gzip damage is an
/// [`IoError::Corrupt`].
pub fn read_nifti(path: &Path, opts: &super::ReadOptions) -> Result<Volume, IoError> {
    let file = open(path)?;
    let total_len = file_len(path, &file)?;
    let mut buffered = BufReader::with_capacity(1 << 20, file);
    let prefix = buffered.fill_buf().map_err(|source| IoError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let gz = is_gzip(prefix);
    let mut reader: Box<dyn Read> = if gz {
        Box::new(flate2::bufread::MultiGzDecoder::new(buffered))
    } else {
        Box::new(buffered)
    };

    // --- header ---------------------------------------------------------
    let mut raw = [0u8; HEADER_SIZE];
    let got = super::read_full(&mut reader, &mut raw).map_err(|e| {
        if gz {
            IoError::Corrupt {
                path: path.to_path_buf(),
                message: format!(
                    "the gzip stream ends or breaks inside the NIfTI header ({e}); the file is \
                     truncated or not gzip data — obtain a complete copy"
                ),
            }
        } else {
            IoError::Io {
                path: path.to_path_buf(),
                source: e,
            }
        }
    })?;
    if got < HEADER_SIZE {
        return Err(header_err(
            path,
            "sizeof_hdr",
            format!(
                "the file holds only {got} {}bytes, too few for a NIfTI-1 header ({HEADER_SIZE} \
                 bytes): it is truncated or not a NIfTI file",
                if gz { "decompressed " } else { "" }
            ),
        ));
    }
    let size_le = i32::from_le_bytes([raw[0], raw[1], raw[2], raw[3]]);
    let size_be = i32::from_be_bytes([raw[0], raw[1], raw[2], raw[3]]);
    if size_le == 540 || size_be == 540 {
        return Err(IoError::Unsupported {
            path: path.to_path_buf(),
            message: "this is a NIfTI-2 file; voxflex reads NIfTI-1 — convert it (e.g. \
                      `nibabel`: nib.Nifti1Image(img.dataobj, img.affine).to_filename(...))"
                .into(),
        });
    }
    if size_le != HEADER_SIZE as i32 && size_be != HEADER_SIZE as i32 {
        return Err(header_err(
            path,
            "sizeof_hdr",
            format!(
                "is {size_le} (byte-swapped {size_be}), not 348: this is not a NIfTI-1 file \
                 (wrong format or garbage under a .nii name){}",
                if gz {
                    ""
                } else {
                    "; if it should be compressed, name it .nii.gz"
                }
            ),
        ));
    }
    let magic = &raw[344..348];
    if magic == b"ni1\0" {
        return Err(IoError::Unsupported {
            path: path.to_path_buf(),
            message: "this is the header of a two-file NIfTI pair (.hdr/.img, magic `ni1`); \
                      voxflex reads single-file NIfTI — convert the pair to .nii.gz"
                .into(),
        });
    }
    if magic != b"n+1\0" {
        return Err(header_err(
            path,
            "magic",
            format!(
                "is {:?}, expected \"n+1\\0\": the file is not NIfTI-1 or its header is damaged",
                String::from_utf8_lossy(magic)
            ),
        ));
    }
    // The byte order is that of sizeof_hdr; the nifti crate guesses it from
    // dim[0], so a damaged dim[0] must be caught before it misleads the crate.
    let big_endian = size_le != HEADER_SIZE as i32;
    let dim0 = if big_endian {
        i16::from_be_bytes([raw[40], raw[41]])
    } else {
        i16::from_le_bytes([raw[40], raw[41]])
    };
    if !(1..=7).contains(&dim0) {
        return Err(header_err(
            path,
            "dim[0]",
            format!("is {dim0}; the number of dimensions must be 1 to 7 — the header is damaged"),
        ));
    }
    let h = ::nifti::NiftiHeader::from_reader(&raw[..])
        .map_err(|e| header_err(path, "header", format!("cannot be decoded: {e}")))?;
    if (h.endianness == ::nifti::Endianness::Big) != big_endian {
        return Err(header_err(
            path,
            "sizeof_hdr",
            "byte order of sizeof_hdr and dim[0] disagree; the header is damaged",
        ));
    }

    // --- dims -----------------------------------------------------------
    // The nifti crate stores dim as u16; the format's field is a signed short.
    let ndim = h.dim[0] as i16;
    let ndim = ndim as usize;
    let mut raw_dims = [1i64; 3];
    for (i, d) in raw_dims.iter_mut().enumerate() {
        if i < ndim {
            *d = i64::from(h.dim[i + 1] as i16);
        }
    }
    for i in 4..=ndim {
        let d = h.dim[i] as i16;
        if d > 1 {
            return Err(IoError::Unsupported {
                path: path.to_path_buf(),
                message: format!(
                    "header field `dim[{i}]` is {d}: this is a {ndim}-D series of {d} volumes; \
                     voxflex reads one 3-D volume — extract one first (e.g. `fslroi in out 0 1`)"
                ),
            });
        }
        if d < 1 {
            return Err(header_err(
                path,
                &format!("dim[{i}]"),
                format!("is {d}, but every size must be positive; the header is damaged"),
            ));
        }
    }
    let dims = validate_dims(path, "dim", raw_dims, opts.max_voxels)?;

    // --- type -----------------------------------------------------------
    let ty = raw_type_of(h.datatype).map_err(|name| {
        if name.is_empty() {
            header_err(
                path,
                "datatype",
                format!(
                    "code {} is not a NIfTI-1 data type: the header is damaged (voxflex reads \
                     uint8, int8, int16, uint16, int32, uint32, int64, uint64, float32, float64)",
                    h.datatype
                ),
            )
        } else {
            IoError::Unsupported {
                path: path.to_path_buf(),
                message: format!(
                    "header field `datatype`: {name} (code {}) is not supported; convert to a \
                     scalar type (uint8, int16, uint16 or float32)",
                    h.datatype
                ),
            }
        }
    })?;
    if h.bitpix as usize != ty.size() * 8 {
        tracing::warn!(
            file = %path.display(),
            "NIfTI bitpix {} disagrees with datatype {} ({} bits); trusting datatype",
            h.bitpix, h.datatype, ty.size() * 8
        );
    }

    // --- geometry -------------------------------------------------------
    let unit_mm = match h.xyzt_units & 0x07 {
        1 => 1000.0, // metre
        3 => 0.001,  // micron
        _ => 1.0,    // mm, or unknown (taken as mm)
    };
    let mut spacing = [1.0f64; 3];
    for (i, s) in spacing.iter_mut().enumerate() {
        let p = f64::from(h.pixdim[i + 1]);
        if i < ndim || (p.is_finite() && p > 0.0) {
            *s = p * unit_mm;
        }
    }
    let spacing = validate_spacing(path, "pixdim", spacing)?;
    // The sform when it is set (method 3), else the qform (method 2), else
    // axis-aligned at zero (method 1).
    let geometry = if h.sform_code > 0 {
        let field = "srow_x/srow_y/srow_z";
        let rows = [h.srow_x, h.srow_y, h.srow_z].map(|r| r.map(|v| f64::from(v) * unit_mm));
        let origin = validate_origin(path, field, [rows[0][3], rows[1][3], rows[2][3]])?;
        HeaderGeometry {
            directions: [0, 1, 2].map(|a| DVec3::new(rows[0][a], rows[1][a], rows[2][a])),
            origin,
            frame: HeaderFrame::Ras,
            field,
        }
    } else if h.qform_code > 0 {
        let field = "qoffset_x/qoffset_y/qoffset_z";
        let origin = validate_origin(
            path,
            field,
            [h.quatern_x, h.quatern_y, h.quatern_z].map(|v| f64::from(v) * unit_mm),
        )?;
        let (b, c, d) = (h.quatern_b, h.quatern_c, h.quatern_d);
        let norm2 = [b, c, d].map(f64::from).iter().map(|v| v * v).sum::<f64>();
        // A unit quaternion's vector part has length ≤ 1 (up to f32
        // rounding); a longer one describes no rotation, and reading it
        // anyway silently scales the axes.
        if norm2.is_nan() || norm2 > 1.0 + QUATERNION_TOLERANCE {
            return Err(header_err(
                path,
                "quatern_b/quatern_c/quatern_d",
                format!(
                    "({b}, {c}, {d}) has length {:.4} > 1, so it is no rotation; fix the \
                     header's qform (or set an sform, or qform_code = 0 to use pixdim alone)",
                    norm2.sqrt()
                ),
            ));
        }
        let r = quaternion_matrix(&h);
        HeaderGeometry {
            directions: [0, 1, 2].map(|a| DVec3::from_array(r[a]) * spacing[a]),
            origin,
            frame: HeaderFrame::Ras,
            field: "quatern_b/quatern_c/quatern_d",
        }
    } else {
        HeaderGeometry::aligned(spacing, DVec3::ZERO, HeaderFrame::Ras, "qform_code")
    };

    // --- data -----------------------------------------------------------
    let vox_offset = f64::from(h.vox_offset);
    if !vox_offset.is_finite()
        || vox_offset < HEADER_SIZE as f64
        || vox_offset.fract() != 0.0
        || vox_offset > 1e15
    {
        return Err(header_err(
            path,
            "vox_offset",
            format!(
                "is {vox_offset}; a single-file NIfTI-1 puts its data at a whole byte offset of \
                 at least 352 — the header is damaged"
            ),
        ));
    }
    let vox_offset = vox_offset as u64;
    let skip = vox_offset - HEADER_SIZE as u64;
    let skipped = skip_bytes(&mut reader, skip).map_err(|e| {
        if gz {
            IoError::Corrupt {
                path: path.to_path_buf(),
                message: format!(
                    "the gzip stream is truncated or corrupt before the voxel data ({e}); \
                     obtain a complete copy"
                ),
            }
        } else {
            IoError::Io {
                path: path.to_path_buf(),
                source: e,
            }
        }
    })?;
    if skipped < skip {
        return Err(header_err(
            path,
            "vox_offset",
            format!(
                "is {vox_offset} but the file ends after {} {}bytes: no voxel data; the file is \
                 truncated or the header is wrong",
                HEADER_SIZE as u64 + skipped,
                if gz { "decompressed " } else { "" }
            ),
        ));
    }
    let spec = DataSpec {
        header_path: path,
        data_path: path,
        dims_field: "dim",
        dims,
        ty,
        big_endian,
        compressed: gz,
        available: (!gz).then(|| total_len.saturating_sub(vox_offset)),
    };
    let mut data = read_voxels(&mut reader, &spec)?;

    // --- scaling --------------------------------------------------------
    let slope = h.scl_slope;
    let inter = h.scl_inter;
    if slope.is_finite() && slope != 0.0 && !(slope == 1.0 && inter == 0.0) {
        if !inter.is_finite() {
            return Err(header_err(
                path,
                "scl_inter",
                format!("is {inter} while scl_slope is {slope}; fix the header's scaling"),
            ));
        }
        data = scale_to_f32(&data, slope, inter);
    }
    place(path, dims, data, geometry, opts)
}

/// How far `quatern_b² + quatern_c² + quatern_d²` may exceed 1 (f32
/// rounding of a unit quaternion) before the qform is refused.
const QUATERNION_TOLERANCE: f64 = 1e-4;

/// Rotation matrix (columns = axis directions) of a NIfTI quaternion, with
/// `qfac` (`pixdim[0]`) applied to the third axis.
fn quaternion_matrix(h: &::nifti::NiftiHeader) -> [[f64; 3]; 3] {
    let (b, c, d) = (
        f64::from(h.quatern_b),
        f64::from(h.quatern_c),
        f64::from(h.quatern_d),
    );
    let a = (1.0 - (b * b + c * c + d * d)).max(0.0).sqrt();
    let qfac = if h.pixdim[0] < 0.0 { -1.0 } else { 1.0 };
    // Row-major R from the NIfTI-1 standard; returned as columns.
    let r = [
        [
            a * a + b * b - c * c - d * d,
            2.0 * (b * c - a * d),
            2.0 * (b * d + a * c),
        ],
        [
            2.0 * (b * c + a * d),
            a * a + c * c - b * b - d * d,
            2.0 * (c * d - a * b),
        ],
        [
            2.0 * (b * d - a * c),
            2.0 * (c * d + a * b),
            a * a + d * d - c * c - b * b,
        ],
    ];
    [
        [r[0][0], r[1][0], r[2][0]],
        [r[0][1], r[1][1], r[2][1]],
        [qfac * r[0][2], qfac * r[1][2], qfac * r[2][2]],
    ]
}

/// `v * slope + inter` as f32, in parallel.
fn scale_to_f32(data: &VoxelData, slope: f32, inter: f32) -> VoxelData {
    use crate::volume::Sample;
    let out: Vec<f32> = crate::with_voxels!(data.as_slice(), |s| s
        .par_iter()
        .map(|v| v.to_f32() * slope + inter)
        .collect());
    VoxelData::F32(out)
}

/// Builds the 352-byte little-endian NIfTI-1 header (+ empty extension flag)
/// voxflex writes.
fn build_header(path: &Path, volume: &VolumeView<'_>) -> Result<Vec<u8>, IoError> {
    let g = &volume.grid;
    let invalid = |message: String| IoError::InvalidRequest {
        path: path.to_path_buf(),
        message,
    };
    let mut dim = [0i16; 3];
    for (d, &n) in dim.iter_mut().zip(g.dims.iter()) {
        *d = i16::try_from(n).ok().filter(|&v| v > 0).ok_or_else(|| {
            invalid(format!(
                "dims {:?} cannot be stored in NIfTI-1 (every size must be 1..=32767)",
                g.dims
            ))
        })?;
    }
    let sp = g.spacing.to_array();
    let or = g.origin.to_array();
    if sp.iter().any(|s| !(s.is_finite() && *s > 0.0)) || or.iter().any(|o| !o.is_finite()) {
        return Err(invalid(format!(
            "spacing {sp:?} / origin {or:?} must be finite (spacing positive) to be written"
        )));
    }
    let (code, bitpix) = code_of(&volume.data);

    let mut h = vec![0u8; WRITE_VOX_OFFSET];
    let put = |h: &mut Vec<u8>, at: usize, bytes: &[u8]| {
        h[at..at + bytes.len()].copy_from_slice(bytes);
    };
    put(&mut h, 0, &(HEADER_SIZE as i32).to_le_bytes());
    h[38] = b'r'; // regular
    let dims8 = [3, dim[0], dim[1], dim[2], 1, 1, 1, 1];
    for (i, d) in dims8.iter().enumerate() {
        put(&mut h, 40 + 2 * i, &d.to_le_bytes());
    }
    put(&mut h, 70, &code.to_le_bytes());
    put(&mut h, 72, &bitpix.to_le_bytes());
    let pixdim = [
        1.0f32,
        sp[0] as f32,
        sp[1] as f32,
        sp[2] as f32,
        1.0,
        1.0,
        1.0,
        1.0,
    ];
    for (i, p) in pixdim.iter().enumerate() {
        put(&mut h, 76 + 4 * i, &p.to_le_bytes());
    }
    put(&mut h, 108, &(WRITE_VOX_OFFSET as f32).to_le_bytes());
    put(&mut h, 112, &1.0f32.to_le_bytes()); // scl_slope
    put(&mut h, 116, &0.0f32.to_le_bytes()); // scl_inter
    h[123] = 2 | 8; // xyzt_units: mm, s
    put(&mut h, 148, b"voxflex");
    put(&mut h, 252, &1i16.to_le_bytes()); // qform_code: scanner
    put(&mut h, 254, &1i16.to_le_bytes()); // sform_code: scanner
    // voxflex's LPS grid in NIfTI's RAS world: x and y negated, a
    // rotation of 180° about z (quatern_b = quatern_c = 0, quatern_d = 1).
    let to_ras = [-1.0, -1.0, 1.0];
    put(&mut h, 264, &1.0f32.to_le_bytes());
    for (i, o) in or.iter().enumerate() {
        put(&mut h, 268 + 4 * i, &((o * to_ras[i]) as f32).to_le_bytes());
    }
    for row in 0..3 {
        let mut srow = [0.0f32; 4];
        srow[row] = (sp[row] * to_ras[row]) as f32;
        srow[3] = (or[row] * to_ras[row]) as f32;
        for (i, v) in srow.iter().enumerate() {
            put(&mut h, 280 + 16 * row + 4 * i, &v.to_le_bytes());
        }
    }
    put(&mut h, 344, b"n+1\0");
    Ok(h)
}

/// Writes voxel values little-endian, chunk by chunk.
fn write_data(w: &mut dyn Write, data: VoxelSlice<'_>) -> std::io::Result<()> {
    if cfg!(target_endian = "little") {
        return w.write_all(data.as_bytes());
    }
    const CHUNK: usize = 1 << 16;
    let mut buf = Vec::with_capacity(CHUNK * 4);
    macro_rules! le_chunks {
        ($s:expr) => {
            for c in $s.chunks(CHUNK) {
                buf.clear();
                for v in c {
                    buf.extend_from_slice(&v.to_le_bytes());
                }
                w.write_all(&buf)?;
            }
        };
    }
    match data {
        VoxelSlice::U8(s) => w.write_all(s)?,
        VoxelSlice::I16(s) => le_chunks!(s),
        VoxelSlice::U16(s) => le_chunks!(s),
        VoxelSlice::F32(s) => le_chunks!(s),
    }
    Ok(())
}

/// Writes a volume as NIfTI-1, gzip-compressed when the name ends in `.gz`
/// (any case). Atomic: see [`write_atomically`]. Any scalar type is written
/// as it is (uint8, int16, uint16, float32); spacing and origin (mm) are
/// stored as `f32`, with an identity rotation.
///
/// Refuses (as [`IoError::InvalidRequest`]) dims above 32767 per axis, a
/// value count that disagrees with the grid, and non-finite geometry.
pub fn write_nifti(path: &Path, volume: VolumeView<'_>) -> Result<(), IoError> {
    if volume.data.len() != volume.grid.len() {
        return Err(IoError::InvalidRequest {
            path: path.to_path_buf(),
            message: format!(
                "volume has {} values but its dims {:?} need {}",
                volume.data.len(),
                volume.grid.dims,
                volume.grid.len()
            ),
        });
    }
    let header = build_header(path, &volume)?;
    let gz = path
        .file_name()
        .is_some_and(|n| n.to_string_lossy().to_ascii_lowercase().ends_with(".gz"));
    write_atomically(path, |w| {
        if gz {
            let mut enc = flate2::write::GzEncoder::new(w, flate2::Compression::default());
            enc.write_all(&header)?;
            write_data(&mut enc, volume.data)?;
            enc.finish()?;
        } else {
            w.write_all(&header)?;
            write_data(w, volume.data)?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::super::ReadOptions;
    use super::super::test_util::{expect_err, gzip};
    use super::*;
    use crate::grid::Grid;
    use glam::DVec3;
    use std::path::PathBuf;

    fn grid() -> Grid {
        Grid::new(
            [5, 4, 3],
            DVec3::new(0.5, 1.25, 2.0),
            DVec3::new(-90.5, 12.25, 3.0),
        )
    }

    fn volumes() -> Vec<Volume> {
        let g = grid();
        let n = g.len();
        vec![
            Volume::new(
                g,
                VoxelData::U8((0..n).map(|i| (i * 7 % 256) as u8).collect()),
            )
            .unwrap(),
            Volume::new(
                g,
                VoxelData::I16((0..n).map(|i| i as i16 * 97 - 1000).collect()),
            )
            .unwrap(),
            Volume::new(g, VoxelData::U16((0..n).map(|i| i as u16 * 1000).collect())).unwrap(),
            Volume::new(
                g,
                VoxelData::F32((0..n).map(|i| i as f32 * 0.37 - 3.5).collect()),
            )
            .unwrap(),
        ]
    }

    #[test]
    fn round_trip_nii_and_nii_gz() {
        let dir = tempfile::tempdir().unwrap();
        for v in volumes() {
            for ext in ["nii", "nii.gz", "NII.GZ"] {
                let p = dir
                    .path()
                    .join(format!("v_{}.{ext}", v.scalar_type().name()));
                write_nifti(&p, v.view()).unwrap();
                let r = super::super::read_volume(&p, &ReadOptions::default()).unwrap();
                assert_eq!(r, v, "{}", p.display());
            }
        }
        // The gzip file really is gzip.
        let p = dir.path().join("v_u8.nii.gz");
        assert!(is_gzip(&std::fs::read(p).unwrap()));
    }

    /// A valid small i16 `.nii` in memory, with its values.
    fn valid_bytes() -> Vec<u8> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("ok.nii");
        write_nifti(&p, volumes()[1].view()).unwrap();
        std::fs::read(p).unwrap()
    }

    fn put_i16(b: &mut [u8], at: usize, v: i16) {
        b[at..at + 2].copy_from_slice(&v.to_le_bytes());
    }
    fn put_f32(b: &mut [u8], at: usize, v: f32) {
        b[at..at + 4].copy_from_slice(&v.to_le_bytes());
    }

    struct Case {
        dir: tempfile::TempDir,
    }
    impl Case {
        fn new() -> Self {
            Self {
                dir: tempfile::tempdir().unwrap(),
            }
        }
        fn write(&self, name: &str, bytes: &[u8]) -> PathBuf {
            let p = self.dir.path().join(name);
            std::fs::write(&p, bytes).unwrap();
            p
        }
        fn read(&self, p: &Path) -> Result<Volume, IoError> {
            read_nifti(p, &ReadOptions::default())
        }
    }

    #[test]
    fn hostile_length_mismatch() {
        let c = Case::new();
        let b = valid_bytes();
        let p = c.write("short.nii", &b[..b.len() - 5]);
        expect_err(
            c.read(&p),
            &p,
            &["`dim`", "only 115 bytes", "need 120 bytes", "truncated"],
        );
        let mut long = b.clone();
        long.extend_from_slice(&[0; 7]);
        let p = c.write("long.nii", &long);
        expect_err(
            c.read(&p),
            &p,
            &["`dim`", "holds 127 bytes", "need 120 bytes"],
        );
        // The same through gzip (length known only after decompression).
        let p = c.write("short.nii.gz", &gzip(&b[..b.len() - 5]));
        expect_err(c.read(&p), &p, &["`dim`", "only 115 bytes", "need 120"]);
        let p = c.write("long.nii.gz", &gzip(&long));
        expect_err(c.read(&p), &p, &["`dim`", "holds 127 bytes", "need 120"]);
        // vox_offset past the end.
        let mut b2 = b.clone();
        put_f32(&mut b2, 108, 4096.0);
        let p = c.write("offset.nii", &b2);
        expect_err(c.read(&p), &p, &["`vox_offset`", "4096"]);
        let mut b2 = b.clone();
        put_f32(&mut b2, 108, f32::NAN);
        let p = c.write("offset_nan.nii", &b2);
        expect_err(c.read(&p), &p, &["`vox_offset`", "NaN"]);
    }

    #[test]
    fn hostile_dims() {
        let c = Case::new();
        let b = valid_bytes();
        let p = c.write("cap.nii", &b);
        expect_err(
            read_nifti(
                &p,
                &ReadOptions {
                    max_voxels: 59,
                    ..Default::default()
                },
            ),
            &p,
            &["`dim`", "60 voxels", "limit of 59", "max_voxels"],
        );
        let mut z = b.clone();
        put_i16(&mut z, 44, 0);
        let p = c.write("zero.nii", &z);
        expect_err(c.read(&p), &p, &["`dim`", "axis 1 is 0", "positive"]);
        let mut n = b.clone();
        put_i16(&mut n, 42, -5);
        let p = c.write("neg.nii", &n);
        expect_err(c.read(&p), &p, &["`dim`", "axis 0 is -5", "positive"]);
        let mut huge = b.clone();
        for i in 1..=3 {
            put_i16(&mut huge, 40 + 2 * i, 32767);
        }
        let p = c.write("huge.nii", &huge);
        expect_err(c.read(&p), &p, &["`dim`", "max_voxels"]);
        let mut nd = b.clone();
        put_i16(&mut nd, 40, 9);
        let p = c.write("ndim.nii", &nd);
        expect_err(c.read(&p), &p, &["`dim[0]`", "is 9", "1 to 7"]);
        put_i16(&mut nd, 40, 0);
        let p = c.write("ndim0.nii", &nd);
        expect_err(c.read(&p), &p, &["`dim[0]`", "is 0", "1 to 7"]);
        let mut four = b.clone();
        put_i16(&mut four, 40, 4);
        put_i16(&mut four, 48, 10);
        let p = c.write("four.nii", &four);
        expect_err(c.read(&p), &p, &["`dim[4]`", "10 volumes", "fslroi"]);
    }

    #[test]
    fn hostile_spacing() {
        let c = Case::new();
        let b = valid_bytes();
        for (name, v) in [
            ("nan", f32::NAN),
            ("inf", f32::INFINITY),
            ("zero", 0.0),
            ("neg", -1.0),
        ] {
            let mut s = b.clone();
            put_f32(&mut s, 80 + 4, v); // pixdim[2]
            let p = c.write(&format!("sp_{name}.nii"), &s);
            expect_err(c.read(&p), &p, &["`pixdim`", "axis 1", "finite positive"]);
        }
        let mut o = b.clone();
        put_f32(&mut o, 280 + 12, f32::INFINITY); // srow_x[3]
        let p = c.write("origin.nii", &o);
        expect_err(c.read(&p), &p, &["srow_x", "not finite"]);
        // A singular or NaN sform places no volume.
        for (name, v) in [("flat", 0.0), ("nan", f32::NAN)] {
            let mut s = b.clone();
            put_f32(&mut s, 280 + 16 + 4, v); // srow_y[1]
            let p = c.write(&format!("sform_{name}.nii"), &s);
            expect_err(
                c.read(&p),
                &p,
                &[
                    "`srow_x/srow_y/srow_z`",
                    "linearly dependent",
                    "fix the header",
                ],
            );
        }
    }

    /// Without an sform, the qform our writer also writes (a 180° turn
    /// about z: voxflex's LPS grid in NIfTI's RAS world) reads back the
    /// same volume.
    #[test]
    fn the_qform_alone_places_the_volume() {
        let c = Case::new();
        let v = &volumes()[1];
        let mut s = valid_bytes();
        put_i16(&mut s, 254, 0); // sform_code: none
        let p = c.write("qform.nii", &s);
        let back = c.read(&p).unwrap();
        assert_eq!((back.grid.dims, &back.data), (v.grid.dims, &v.data));
        assert!((back.grid.spacing - v.grid.spacing).abs().max_element() < 1e-6);
        assert!((back.grid.origin - v.grid.origin).abs().max_element() < 1e-4);
    }

    /// A qform quaternion whose vector part is longer than 1 is no
    /// rotation: refused naming the fields, not read with scaled axes.
    #[test]
    fn an_invalid_qform_quaternion_is_refused() {
        let c = Case::new();
        let mut s = valid_bytes();
        put_i16(&mut s, 254, 0); // sform_code: none, so the qform is used
        for (at, v) in [(256, 1.0f32), (260, 1.0), (264, 1.0)] {
            put_f32(&mut s, at, v);
        }
        let p = c.write("bad_quaternion.nii", &s);
        expect_err(
            c.read(&p),
            &p,
            &[
                "`quatern_b/quatern_c/quatern_d`",
                "(1, 1, 1)",
                "no rotation",
            ],
        );
        let mut s = valid_bytes();
        put_i16(&mut s, 254, 0);
        put_f32(&mut s, 256, f32::NAN);
        let p = c.write("nan_quaternion.nii", &s);
        expect_err(c.read(&p), &p, &["`quatern_b/quatern_c/quatern_d`"]);
    }

    /// The sform's axis order and directions are applied: a file whose
    /// sform swaps i and j and reverses k reads back as the volume it was
    /// written from, transposed and flipped, every voxel at its world
    /// position.
    #[test]
    fn the_sform_places_every_voxel() {
        let c = Case::new();
        let v = &volumes()[1];
        let [nx, ny, nz] = v.grid.dims;
        let mut s = valid_bytes();
        // Swap dims and spacing of i and j, and store the voxels j-fastest.
        put_i16(&mut s, 42, ny as i16);
        put_i16(&mut s, 44, nx as i16);
        let sp = v.grid.spacing;
        // RAS rows: i steps LPS +y (RAS −y), j steps LPS +x (RAS −x), k
        // steps LPS −z (reversed) from RAS (−ox, −oy, oz + (nz − 1) sz).
        let o = v.grid.origin;
        let top = o.z + (nz - 1) as f64 * sp.z;
        for (row, vals) in [
            [0.0, -sp.x, 0.0, -o.x],
            [-sp.y, 0.0, 0.0, -o.y],
            [0.0, 0.0, -sp.z, top],
        ]
        .iter()
        .enumerate()
        {
            for (i, x) in vals.iter().enumerate() {
                put_f32(&mut s, 280 + 16 * row + 4 * i, *x as f32);
            }
        }
        put_i16(&mut s, 252, 0); // no qform
        let header = 352;
        let values: Vec<i16> = match &v.data {
            VoxelData::I16(d) => d.clone(),
            other => panic!("the test volume is i16, not {other:?}"),
        };
        let mut data = Vec::new();
        for k in (0..nz).rev() {
            for x in 0..nx {
                for y in 0..ny {
                    data.extend_from_slice(&values[v.grid.linear(x, y, k)].to_le_bytes());
                }
            }
        }
        s.truncate(header);
        s.extend_from_slice(&data);
        let p = c.write("turned.nii", &s);
        let back = c.read(&p).unwrap();
        assert_eq!(back.grid.dims, v.grid.dims);
        assert!((back.grid.spacing - sp).abs().max_element() < 1e-6);
        assert!((back.grid.origin - o).abs().max_element() < 1e-4);
        assert_eq!(back.data, v.data);
    }

    #[test]
    fn hostile_gzip_type_missing_garbage() {
        let c = Case::new();
        // Big enough that half the gzip stream ends inside the data.
        let g = Grid::new([64, 64, 16], DVec3::ONE, DVec3::ZERO);
        let vals: Vec<f32> = (0..g.len())
            .map(|i| ((i * 2654435761) % 1000) as f32)
            .collect();
        let v = Volume::new(g, VoxelData::F32(vals)).unwrap();
        let full = c.dir.path().join("full.nii.gz");
        write_nifti(&full, v.view()).unwrap();
        let bytes = std::fs::read(&full).unwrap();
        let p = c.write("half.nii.gz", &bytes[..bytes.len() / 2]);
        expect_err(
            c.read(&p),
            &p,
            &["damaged data", "truncated or corrupt", "complete copy"],
        );
        // Cut inside the header too.
        let p = c.write("tiny.nii.gz", &bytes[..20]);
        expect_err(c.read(&p), &p, &["damaged data", "header"]);

        let mut t = valid_bytes();
        put_i16(&mut t, 70, 9999);
        let p = c.write("type.nii", &t);
        expect_err(
            c.read(&p),
            &p,
            &["`datatype`", "9999", "not a NIfTI-1 data type"],
        );
        put_i16(&mut t, 70, 128);
        let p = c.write("rgb.nii", &t);
        expect_err(c.read(&p), &p, &["`datatype`", "RGB24"]);

        let p = c.dir.path().join("missing.nii");
        expect_err(c.read(&p), &p, &["no such file", "check the path"]);

        let text = "this is not a volume, just some text that someone saved as .nii\n".repeat(10);
        let p = c.write("garbage.nii", text.as_bytes());
        expect_err(c.read(&p), &p, &["`sizeof_hdr`", "not a NIfTI-1 file"]);
        let p = c.write("garbage.nii.gz", &gzip(text.as_bytes()));
        expect_err(c.read(&p), &p, &["`sizeof_hdr`", "not a NIfTI-1 file"]);
        let p = c.write("short_text.nii", b"hello");
        expect_err(c.read(&p), &p, &["`sizeof_hdr`", "only 5 bytes"]);
        let mut m = valid_bytes();
        m[344] = b'x';
        let p = c.write("magic.nii", &m);
        expect_err(c.read(&p), &p, &["`magic`", "not NIfTI-1"]);
    }

    #[test]
    fn converts_types_and_applies_scaling() {
        let c = Case::new();
        let base = valid_bytes(); // i16, 60 voxels
        let hdr = &base[..WRITE_VOX_OFFSET];
        // int32 big-endian is converted to f32.
        let mut be = hdr.to_vec();
        for (at, size) in [(0, 4), (40, 2), (42, 2), (44, 2), (46, 2), (48, 2)] {
            be[at..at + size].reverse();
        }
        for at in [50, 52, 54] {
            be[at..at + 2].reverse();
        }
        // datatype int32, bitpix 32 (big-endian)
        be[70..72].copy_from_slice(&8i16.to_be_bytes());
        be[72..74].copy_from_slice(&32i16.to_be_bytes());
        for at in (76..124).step_by(4) {
            if at != 120 {
                be[at..at + 4].reverse();
            }
        }
        be[120..122].reverse();
        for at in (252..256).step_by(2) {
            be[at..at + 2].reverse();
        }
        for at in (256..328).step_by(4) {
            be[at..at + 4].reverse();
        }
        for i in 0..60i32 {
            be.extend_from_slice(&(i * 100_000 - 7).to_be_bytes());
        }
        let p = c.write("be_i32.nii", &be);
        let v = c.read(&p).unwrap();
        assert_eq!(v.grid, grid());
        let VoxelData::F32(d) = &v.data else {
            panic!("expected f32, got {:?}", v.scalar_type())
        };
        assert_eq!(d[3], 299_993.0);

        // scl_slope 2, scl_inter -1024 on i16 → f32.
        let mut s = base.clone();
        put_f32(&mut s, 112, 2.0);
        put_f32(&mut s, 116, -1024.0);
        let p = c.write("scaled.nii", &s);
        let v = c.read(&p).unwrap();
        assert_eq!(v.get_f32(1, 0, 0), (97.0 - 1000.0) * 2.0 - 1024.0);
        assert_eq!(v.scalar_type(), crate::volume::ScalarType::F32);
        // slope 0 = no scaling; int8 → i16
        let mut s = base[..WRITE_VOX_OFFSET].to_vec();
        put_i16(&mut s, 70, 256);
        put_i16(&mut s, 72, 8);
        put_f32(&mut s, 112, 0.0);
        s.extend((0..60).map(|i| (i as i8 - 30) as u8));
        let p = c.write("i8.nii", &s);
        let v = c.read(&p).unwrap();
        assert_eq!(v.data, VoxelData::I16((0..60).map(|i| i - 30).collect()));
        // Units: metres become mm.
        let mut s = base.clone();
        s[123] = 1;
        let p = c.write("metres.nii", &s);
        let v = c.read(&p).unwrap();
        assert_eq!(v.grid.spacing, DVec3::new(500.0, 1250.0, 2000.0));
    }

    #[test]
    fn real_data() {
        let Some(dir) = voxflex_core::test_data::dir() else {
            return;
        };
        let opts = ReadOptions::default();
        let t = std::time::Instant::now();
        let colin = read_nifti(&dir.join("mri_colin27_t1.nii.gz"), &opts).unwrap();
        eprintln!(
            "mri_colin27_t1.nii.gz read in {:?}\n{}",
            t.elapsed(),
            voxflex_core::stats::VolumeStats::compute(colin.view())
        );
        assert_eq!(colin.grid.dims, [181, 217, 181]);
        assert_eq!(colin.grid.spacing, DVec3::ONE);
        // RAS-stored (identity sform at (−90, −125, −71)): x and y reversed
        // into LPS; grid voxel 0 is file voxel (180, 216, 0), at RAS
        // (90, 91, −71) = LPS (−90, −91, −71) mm.
        assert_eq!(colin.grid.origin, DVec3::new(-90.0, -91.0, -71.0));
        assert_eq!(colin.scalar_type(), crate::volume::ScalarType::U8);
        let (lo, hi) = colin.value_range();
        assert!(lo >= 0.0 && hi > 100.0, "{lo}..{hi}");

        // A coronal acquisition: its sform runs i towards RAS −x = LPS +x
        // (2 mm), j towards +z (2 mm) and k towards RAS +y = LPS −y (3 mm),
        // so the grid holds 128 columns along x, 62 coronal slices along y
        // (reversed) and 128 rows along z.
        let small = read_nifti(&dir.join("mri_t1_small.nii.gz"), &opts).unwrap();
        assert_eq!(small.grid.dims, [128, 62, 128]);
        assert_eq!(small.grid.spacing, DVec3::new(2.0, 3.0, 2.0));
        // Grid voxel 0 is file voxel (0, 0, 61), at RAS (0, −254 + 183, 0)
        // = LPS (0, 71, 0) mm.
        assert_eq!(small.grid.origin, DVec3::new(0.0, 71.0, 0.0));
        // Stored as int16 in the file (values 0..255).
        assert_eq!(small.scalar_type(), crate::volume::ScalarType::I16);

        // Stored along RAS −x and −y (sform −3.94 mm), i.e. LPS +x and +y:
        // voxflex's own order, nothing reordered.
        let ct = read_nifti(&dir.join("ct_skull_64.nii.gz"), &opts).unwrap();
        assert_eq!(ct.grid.dims, [64, 64, 64]);
        assert_eq!(ct.grid.origin, DVec3::ZERO);
        assert!(
            (ct.grid.spacing - DVec3::new(3.94, 3.94, 3.65))
                .abs()
                .max_element()
                < 1e-5
        );
        assert_eq!(ct.scalar_type(), crate::volume::ScalarType::F32);
        let (lo, hi) = ct.value_range();
        assert!(lo >= -1e-3 && (5.0..6.0).contains(&hi), "{lo}..{hi}");

        // Round trip of real data through our writer.
        let tmp = tempfile::tempdir().unwrap();
        let p = tmp.path().join("ct.nii.gz");
        write_nifti(&p, ct.view()).unwrap();
        let back = read_nifti(&p, &opts).unwrap();
        assert_eq!(
            (back.grid.dims, back.grid.spacing),
            (ct.grid.dims, ct.grid.spacing)
        );
        assert_eq!(back.data, ct.data);
        // NIfTI stores the origin as f32.
        assert!((back.grid.origin - ct.grid.origin).length() < 1e-4);
    }
}
