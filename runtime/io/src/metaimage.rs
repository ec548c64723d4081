//! MetaImage volumes (ITK's format): a text header of `Key = Value` lines
//! (`.mhd`) with the voxels in a separate file named by `ElementDataFile`
//! (resolved relative to the header's folder), or in the same file after the
//! header (`.mha`, `ElementDataFile = LOCAL`).
//!
//! Keys read (case-insensitive):
//! - `NDims` (1–3; more only when the extra sizes are 1), `DimSize`;
//! - `ElementType`: `MET_UCHAR`, `MET_SHORT`, `MET_USHORT`, `MET_FLOAT` as
//!   they are; `MET_CHAR` → `i16`; `MET_INT`, `MET_UINT`, `MET_LONG`,
//!   `MET_ULONG`, `MET_LONG_LONG`, `MET_ULONG_LONG`, `MET_DOUBLE` → `f32`;
//! - `ElementSpacing` (mm; else `ElementSize`; else 1 mm);
//! - `Offset` / `Position` / `Origin` (mm, position of voxel 0; else 0);
//! - `BinaryDataByteOrderMSB` / `ElementByteOrderMSB` (`True` = big-endian);
//! - `CompressedData = True`: zlib (or gzip) stream, optionally bounded by
//!   `CompressedDataSize`;
//! - `HeaderSize`: bytes to skip at the start of the data file (`-1`: the
//!   data is the last bytes of the file);
//! - `ElementNumberOfChannels` must be 1; `BinaryData` must not be `False`.
//! - `TransformMatrix` / `Rotation` / `Orientation` (row `a`: voxel axis
//!   `a`'s direction): applied, with the origin (ITK's LPS world is
//!   voxflex's), by reordering the voxels (see
//!   [`super::orientation`]); an oblique volume is placed along its closest
//!   axes with a warning.
//!
//! Other keys are ignored. File lists (`ElementDataFile = LIST` or a
//! `%d` pattern) are refused with a message.

use super::orientation::{HeaderFrame, HeaderGeometry, place};
use super::{
    DataSpec, RawType, ReadOptions, file_len, header_err, is_gzip, open, read_voxels, skip_bytes,
    validate_dims, validate_origin, validate_spacing,
};
use crate::error::IoError;
use crate::volume::Volume;
use glam::DVec3;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

/// Largest header (bytes before the data) accepted: anything longer is not
/// a MetaImage header.
const MAX_HEADER_BYTES: u64 = 1 << 20;

/// Parsed header lines: (key as written, value), in order.
struct Header {
    entries: Vec<(String, String)>,
    /// Bytes of the header, up to and including the `ElementDataFile` line.
    len: u64,
}

impl Header {
    /// The value of the first of `keys` present (case-insensitive), with the
    /// key as written.
    fn get(&self, keys: &[&str]) -> Option<(&str, &str)> {
        keys.iter().find_map(|k| {
            self.entries
                .iter()
                .find(|(key, _)| key.eq_ignore_ascii_case(k))
                .map(|(key, v)| (key.as_str(), v.as_str()))
        })
    }
}

fn parse_header(path: &Path, reader: &mut dyn BufRead) -> Result<Header, IoError> {
    let mut entries = Vec::new();
    let mut len: u64 = 0;
    let mut line = Vec::new();
    for line_no in 1.. {
        line.clear();
        let n = reader
            .take(MAX_HEADER_BYTES.saturating_sub(len).max(1))
            .read_until(b'\n', &mut line)
            .map_err(|source| IoError::Io {
                path: path.to_path_buf(),
                source,
            })?;
        len += n as u64;
        if n == 0 || len >= MAX_HEADER_BYTES {
            return Err(header_err(
                path,
                "ElementDataFile",
                format!(
                    "missing: the header ends (after {len} bytes) without an `ElementDataFile` \
                     line; this is not a MetaImage header or it is truncated — the last header \
                     line must be `ElementDataFile = <data file or LOCAL>`"
                ),
            ));
        }
        let Ok(text) = std::str::from_utf8(&line) else {
            return Err(IoError::Unsupported {
                path: path.to_path_buf(),
                message: format!(
                    "line {line_no} of the header is not text: this is not a MetaImage header \
                     (expected `Key = Value` lines ending with `ElementDataFile = ...`)"
                ),
            });
        };
        let text = text.trim();
        if text.is_empty() {
            continue;
        }
        let Some((key, value)) = text.split_once('=') else {
            return Err(IoError::Unsupported {
                path: path.to_path_buf(),
                message: format!(
                    "line {line_no} `{}` is not `Key = Value`: this is not a MetaImage header",
                    text.chars().take(60).collect::<String>()
                ),
            });
        };
        let key = key.trim().to_string();
        let value = value.trim().to_string();
        let last = key.eq_ignore_ascii_case("ElementDataFile");
        entries.push((key, value));
        if last {
            break;
        }
    }
    Ok(Header { entries, len })
}

fn parse_numbers<T: std::str::FromStr>(
    path: &Path,
    field: &str,
    value: &str,
) -> Result<Vec<T>, IoError> {
    value
        .split_whitespace()
        .map(|t| {
            t.parse::<T>().map_err(|_| {
                header_err(
                    path,
                    field,
                    format!("`{t}` in `{value}` is not a valid number; fix the header"),
                )
            })
        })
        .collect()
}

fn parse_bool(path: &Path, field: &str, value: &str) -> Result<bool, IoError> {
    match value.to_ascii_lowercase().as_str() {
        "true" | "1" | "yes" => Ok(true),
        "false" | "0" | "no" => Ok(false),
        _ => Err(header_err(
            path,
            field,
            format!("`{value}` is not True or False"),
        )),
    }
}

fn element_type(path: &Path, field: &str, value: &str) -> Result<RawType, IoError> {
    Ok(match value.to_ascii_uppercase().as_str() {
        "MET_UCHAR" => RawType::U8,
        "MET_CHAR" => RawType::I8,
        "MET_SHORT" => RawType::I16,
        "MET_USHORT" => RawType::U16,
        "MET_INT" | "MET_LONG" => RawType::I32,
        "MET_UINT" | "MET_ULONG" => RawType::U32,
        "MET_LONG_LONG" => RawType::I64,
        "MET_ULONG_LONG" => RawType::U64,
        "MET_FLOAT" => RawType::F32,
        "MET_DOUBLE" => RawType::F64,
        _ => {
            return Err(header_err(
                path,
                field,
                format!(
                    "`{value}` is not an element type voxflex reads (MET_UCHAR, MET_CHAR, \
                     MET_SHORT, MET_USHORT, MET_INT, MET_UINT, MET_LONG, MET_ULONG, \
                     MET_LONG_LONG, MET_ULONG_LONG, MET_FLOAT, MET_DOUBLE; one channel)"
                ),
            ));
        }
    })
}

/// Pads or checks a per-axis list to 3 entries: axes beyond `ndims` get
/// `fill`; fewer than `ndims` values is an error.
fn per_axis<T: Copy + std::fmt::Debug>(
    path: &Path,
    field: &str,
    values: &[T],
    ndims: usize,
    fill: T,
) -> Result<[T; 3], IoError> {
    if values.len() < ndims {
        return Err(header_err(
            path,
            field,
            format!(
                "has {} value(s) {values:?} but NDims is {ndims}; give one value per axis",
                values.len()
            ),
        ));
    }
    let mut out = [fill; 3];
    for (o, v) in out.iter_mut().zip(values.iter().take(ndims.min(3))) {
        *o = *v;
    }
    Ok(out)
}

/// The data file a MetaImage header names (`ElementDataFile`, resolved
/// relative to the header's folder), or `None` for `LOCAL` data. Only the
/// header is read.
pub(crate) fn detached_data_file(path: &Path) -> Result<Option<PathBuf>, IoError> {
    let mut reader = BufReader::new(open(path)?);
    let h = parse_header(path, &mut reader)?;
    Ok(h.get(&["ElementDataFile"])
        .map(|(_, v)| v.trim())
        .filter(|v| !v.eq_ignore_ascii_case("LOCAL"))
        .map(|v| path.parent().unwrap_or(Path::new("")).join(v)))
}

/// How far a `TransformMatrix` row's length may differ from 1 (rounded
/// direction cosines) before the header is refused.
const DIRECTION_TOLERANCE: f64 = 1e-3;

/// Reads a MetaImage `.mhd` (+ data file) or `.mha` volume. See the module
/// docs for the keys understood; rotations are not applied.
pub fn read_metaimage(path: &Path, opts: &ReadOptions) -> Result<Volume, IoError> {
    let file = open(path)?;
    let header_file_len = file_len(path, &file)?;
    let mut reader = BufReader::with_capacity(1 << 20, file);
    let h = parse_header(path, &mut reader)?;

    // --- dims -----------------------------------------------------------
    let (dims_key, dims_value) = h
        .get(&["DimSize"])
        .ok_or_else(|| header_err(path, "DimSize", "missing; add `DimSize = <nx> <ny> <nz>`"))?;
    let sizes: Vec<i64> = parse_numbers(path, dims_key, dims_value)?;
    let ndims = match h.get(&["NDims"]) {
        Some((k, v)) => {
            let n: Vec<i64> = parse_numbers(path, k, v)?;
            match n.as_slice() {
                [n] if (1..=16).contains(n) => *n as usize,
                _ => {
                    return Err(header_err(
                        path,
                        k,
                        format!("`{v}` is not a dimension count (1 to 3 for a volume)"),
                    ));
                }
            }
        }
        None => sizes.len(),
    };
    if sizes.len() != ndims {
        return Err(header_err(
            path,
            dims_key,
            format!(
                "has {} size(s) `{dims_value}` but NDims is {ndims}; give one size per axis",
                sizes.len()
            ),
        ));
    }
    if let Some((i, &s)) = sizes.iter().enumerate().skip(3).find(|&(_, &s)| s != 1) {
        return Err(IoError::Unsupported {
            path: path.to_path_buf(),
            message: format!(
                "header field `{dims_key}`: axis {i} has size {s}; voxflex reads 3-D volumes — \
                 extract one 3-D volume first"
            ),
        });
    }
    let raw_dims = per_axis(path, dims_key, &sizes, ndims, 1)?;
    let dims = validate_dims(path, dims_key, raw_dims, opts.max_voxels)?;

    // --- type -----------------------------------------------------------
    let (type_key, type_value) = h.get(&["ElementType"]).ok_or_else(|| {
        header_err(
            path,
            "ElementType",
            "missing; add e.g. `ElementType = MET_SHORT`",
        )
    })?;
    let ty = element_type(path, type_key, type_value)?;
    if let Some((k, v)) = h.get(&["ElementNumberOfChannels"]) {
        let c: Vec<i64> = parse_numbers(path, k, v)?;
        if c != [1] {
            return Err(IoError::Unsupported {
                path: path.to_path_buf(),
                message: format!(
                    "header field `{k}` is {v}; voxflex reads one-channel (scalar) volumes"
                ),
            });
        }
    }
    if let Some((k, v)) = h.get(&["BinaryData"])
        && !parse_bool(path, k, v)?
    {
        return Err(IoError::Unsupported {
            path: path.to_path_buf(),
            message: format!(
                "header field `{k}` is {v}: ASCII MetaImage data is not supported; \
                              re-save as binary"
            ),
        });
    }
    let big_endian = match h.get(&["BinaryDataByteOrderMSB", "ElementByteOrderMSB"]) {
        Some((k, v)) => parse_bool(path, k, v)?,
        None => false,
    };
    let compressed = match h.get(&["CompressedData"]) {
        Some((k, v)) => parse_bool(path, k, v)?,
        None => false,
    };

    // --- geometry -------------------------------------------------------
    let spacing = match h.get(&["ElementSpacing", "ElementSize"]) {
        Some((k, v)) => {
            let s: Vec<f64> = parse_numbers(path, k, v)?;
            validate_spacing(path, k, per_axis(path, k, &s, ndims, 1.0)?)?
        }
        None => glam::DVec3::ONE,
    };
    let origin = match h.get(&["Offset", "Position", "Origin"]) {
        Some((k, v)) => {
            let o: Vec<f64> = parse_numbers(path, k, v)?;
            validate_origin(path, k, per_axis(path, k, &o, ndims, 0.0)?)?
        }
        None => glam::DVec3::ZERO,
    };
    // ITK's world is LPS, voxflex's too; row `a` of the matrix is the
    // direction of voxel axis `a` (ITK's reading).
    let geometry = match h.get(&["TransformMatrix", "Rotation", "Orientation"]) {
        Some((k, v)) => {
            let m: Vec<f64> = parse_numbers(path, k, v)?;
            // A 1-D or 2-D file's matrix is 1 × 1 or 2 × 2.
            let m: [f64; 9] = match *m.as_slice() {
                [x] if ndims == 1 => [x, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                [a, b, c, d] if ndims == 2 => [a, b, 0.0, c, d, 0.0, 0.0, 0.0, 1.0],
                _ => m.as_slice().try_into().map_err(|_| {
                    header_err(
                        path,
                        k,
                        format!("`{v}` is not an NDims × NDims matrix (NDims is {ndims})"),
                    )
                })?,
            };
            // Rows are direction cosines; the spacing is ElementSpacing. A
            // row of another length would silently scale that axis (the
            // NIfTI qform's bug class), so it is refused. Zero and
            // dependent rows are left to the orientation check.
            for a in 0..3 {
                let len = DVec3::new(m[3 * a], m[3 * a + 1], m[3 * a + 2]).length();
                if len > 0.0 && (len - 1.0).abs() > DIRECTION_TOLERANCE {
                    return Err(header_err(
                        path,
                        k,
                        format!(
                            "row {a} has length {len:.4}, not 1: the matrix holds direction \
                             cosines (the spacing is ElementSpacing); fix the header"
                        ),
                    ));
                }
            }
            HeaderGeometry {
                directions: [0, 1, 2]
                    .map(|a| DVec3::new(m[3 * a], m[3 * a + 1], m[3 * a + 2]) * spacing[a]),
                origin,
                frame: HeaderFrame::Lps,
                field: "TransformMatrix",
            }
        }
        None => HeaderGeometry::aligned(spacing, origin, HeaderFrame::Lps, "ElementSpacing"),
    };

    // --- data -----------------------------------------------------------
    let header_size: i64 = match h.get(&["HeaderSize"]) {
        Some((k, v)) => match parse_numbers::<i64>(path, k, v)?.as_slice() {
            [n] if *n >= -1 => *n,
            _ => {
                return Err(header_err(
                    path,
                    k,
                    format!("`{v}` is not a byte count (≥ 0, or -1 for \"data at the end\")"),
                ));
            }
        },
        None => 0,
    };
    let compressed_size: Option<u64> = match h.get(&["CompressedDataSize"]) {
        Some((k, v)) => match parse_numbers::<u64>(path, k, v)?.as_slice() {
            [n] => Some(*n),
            _ => return Err(header_err(path, k, format!("`{v}` is not a byte count"))),
        },
        None => None,
    };
    let (file_key, file_value) = h
        .get(&["ElementDataFile"])
        .ok_or_else(|| header_err(path, "ElementDataFile", "missing"))?;
    let local = file_value.eq_ignore_ascii_case("LOCAL");
    if file_value.eq_ignore_ascii_case("LIST") || file_value.contains('%') {
        return Err(IoError::Unsupported {
            path: path.to_path_buf(),
            message: format!(
                "header field `{file_key}` is `{file_value}`: multi-file (slice list) MetaImage \
                 is not supported; merge the slices into one data file"
            ),
        });
    }
    if file_value.is_empty() {
        return Err(header_err(
            path,
            file_key,
            "is empty; name the data file (relative to the header) or LOCAL",
        ));
    }

    let data_path: PathBuf;
    let mut data_reader: Box<dyn BufRead>;
    let data_len: u64;
    if local {
        data_path = path.to_path_buf();
        data_reader = Box::new(reader);
        data_len = header_file_len.saturating_sub(h.len);
    } else {
        let base = path.parent().unwrap_or(Path::new(""));
        data_path = base.join(file_value);
        super::refuse_non_regular(&data_path)?;
        let f = match std::fs::File::open(&data_path) {
            Ok(f) => f,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(header_err(
                    path,
                    file_key,
                    format!(
                        "data file {} does not exist (`{file_value}` is resolved relative to the \
                         header's folder); copy the data file next to the header or fix the name",
                        data_path.display()
                    ),
                ));
            }
            Err(source) => {
                return Err(IoError::Io {
                    path: data_path,
                    source,
                });
            }
        };
        data_len = file_len(&data_path, &f)?;
        data_reader = Box::new(BufReader::with_capacity(1 << 20, f));
    }

    let needed_probe = DataSpec {
        header_path: path,
        data_path: &data_path,
        dims_field: dims_key,
        dims,
        ty,
        big_endian,
        compressed,
        available: None,
    };
    let needed = needed_probe.needed_bytes()?;
    // Bytes to skip before the data.
    let skip = if compressed {
        u64::try_from(header_size).unwrap_or(0)
    } else if header_size == -1 {
        data_len.saturating_sub(needed)
    } else {
        header_size as u64
    };
    if skip > data_len {
        return Err(header_err(
            path,
            "HeaderSize",
            format!(
                "is {skip} but the data holds only {data_len} bytes; fix HeaderSize{}",
                if local { "" } else { " or the data file" }
            ),
        ));
    }
    let skipped = skip_bytes(&mut data_reader, skip).map_err(|source| IoError::Io {
        path: data_path.clone(),
        source,
    })?;
    if skipped < skip {
        return Err(needed_probe.too_short(0, needed));
    }
    let remaining = data_len - skip;

    let mut reader: Box<dyn Read> = if compressed {
        let bounded = data_reader.take(compressed_size.unwrap_or(u64::MAX));
        let mut bounded = BufReader::new(bounded);
        let gz = is_gzip(bounded.fill_buf().map_err(|source| IoError::Io {
            path: data_path.clone(),
            source,
        })?);
        if gz {
            Box::new(flate2::bufread::MultiGzDecoder::new(bounded))
        } else {
            Box::new(flate2::bufread::ZlibDecoder::new(bounded))
        }
    } else {
        Box::new(data_reader)
    };
    let spec = DataSpec {
        available: (!compressed).then_some(remaining),
        ..needed_probe
    };
    let data = read_voxels(&mut reader, &spec)?;
    place(path, dims, data, geometry, opts)
}

#[cfg(test)]
mod tests {
    use super::super::test_util::expect_err;
    use super::*;
    use crate::volume::VoxelData;
    use glam::DVec3;
    use std::io::Write;

    fn zlib(data: &[u8]) -> Vec<u8> {
        let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
        e.write_all(data).unwrap();
        e.finish().unwrap()
    }

    struct Dir(tempfile::TempDir);
    impl Dir {
        fn new() -> Self {
            Self(tempfile::tempdir().unwrap())
        }
        fn write(&self, name: &str, bytes: &[u8]) -> PathBuf {
            let p = self.0.path().join(name);
            std::fs::write(&p, bytes).unwrap();
            p
        }
        fn read(&self, p: &Path) -> Result<Volume, IoError> {
            read_metaimage(p, &ReadOptions::default())
        }
    }

    #[test]
    fn volume_files_name_the_detached_data_file() {
        let d = Dir::new();
        let p = d.write(
            "v.mhd",
            b"NDims = 3\nDimSize = 2 1 1\nElementType = MET_UCHAR\nElementDataFile = v.raw\n",
        );
        let files = super::super::volume_files(&p).unwrap();
        assert_eq!(files, vec![p.clone(), d.0.path().join("v.raw")]);
        let p = d.write(
            "l.mha",
            b"NDims = 3\nDimSize = 2 1 1\nElementType = MET_UCHAR\nElementDataFile = LOCAL\nab",
        );
        assert_eq!(super::super::volume_files(&p).unwrap(), vec![p.clone()]);
    }

    const HDR: &str = "ObjectType = Image\nNDims = 3\nBinaryData = True\n\
                       BinaryDataByteOrderMSB = False\nCompressedData = False\n\
                       TransformMatrix = 1 0 0 0 1 0 0 0 1\nOffset = -1.5 2 30\n\
                       ElementSpacing = 0.5 1 2.5\nDimSize = 3 2 2\nElementType = MET_SHORT\n\
                       ElementDataFile = vol.raw\n";

    fn i16_le(vals: &[i16]) -> Vec<u8> {
        vals.iter().flat_map(|v| v.to_le_bytes()).collect()
    }

    fn vals() -> Vec<i16> {
        (0..12).map(|i| i * 100 - 500).collect()
    }

    #[test]
    fn reads_mhd_with_raw() {
        let d = Dir::new();
        d.write("vol.raw", &i16_le(&vals()));
        let p = d.write("vol.mhd", HDR.as_bytes());
        let v = super::super::read_volume(&p, &ReadOptions::default()).unwrap();
        assert_eq!(v.grid.dims, [3, 2, 2]);
        assert_eq!(v.grid.spacing, DVec3::new(0.5, 1.0, 2.5));
        assert_eq!(v.grid.origin, DVec3::new(-1.5, 2.0, 30.0));
        assert_eq!(v.data, VoxelData::I16(vals()));
        // A matrix that reverses x: the columns come back in order, from
        // the file's last one, 2 × 0.5 mm towards −x.
        let flipped = HDR.replace("TransformMatrix = 1 0 0", "TransformMatrix = -1 0 0");
        let p = d.write("flipped.mhd", flipped.as_bytes());
        let v = d.read(&p).unwrap();
        assert_eq!(v.grid.origin, DVec3::new(-2.5, 2.0, 30.0));
        assert_eq!(
            v.data,
            VoxelData::I16(super::super::test_util::reversed(
                &vals(),
                [3, 2, 2],
                [true, false, false]
            ))
        );
        // Data file in a sub-folder, CRLF line ends, Position instead of Offset.
        std::fs::create_dir(d.0.path().join("sub")).unwrap();
        d.write("sub/x.raw", &i16_le(&vals()));
        let h = HDR
            .replace("vol.raw", "sub/x.raw")
            .replace("Offset", "Position")
            .replace('\n', "\r\n");
        let p = d.write("crlf.mhd", h.as_bytes());
        let v = d.read(&p).unwrap();
        assert_eq!(v.data, VoxelData::I16(vals()));
        assert_eq!(v.grid.origin, DVec3::new(-1.5, 2.0, 30.0));
    }

    /// A matrix row longer or shorter than 1 would scale that axis's
    /// spacing: refused naming the field and the row.
    #[test]
    fn a_transform_matrix_row_that_is_no_direction_is_refused() {
        let d = Dir::new();
        d.write("vol.raw", &i16_le(&vals()));
        let scaled = HDR.replace("TransformMatrix = 1 0 0", "TransformMatrix = 12 0 0");
        let p = d.write("scaled.mhd", scaled.as_bytes());
        super::super::test_util::expect_err(
            d.read(&p),
            &p,
            &["`TransformMatrix`", "row 0 has length 12", "direction"],
        );
        let rounded = HDR.replace("TransformMatrix = 1 0 0", "TransformMatrix = 0.9999 0 0");
        let p = d.write("rounded.mhd", rounded.as_bytes());
        let spacing = d.read(&p).unwrap().grid.spacing;
        assert!((spacing - DVec3::new(0.5, 1.0, 2.5)).abs().max_element() < 1e-3);
    }

    #[test]
    fn reads_msb_and_local_and_compressed() {
        let d = Dir::new();
        // Big-endian u16, 2-D image, ElementSize.
        let v16: Vec<u16> = vec![1, 256, 65535, 4660];
        let be: Vec<u8> = v16.iter().flat_map(|v| v.to_be_bytes()).collect();
        d.write("be.raw", &be);
        let p = d.write(
            "be.mhd",
            b"NDims = 2\nDimSize = 2 2\nElementSize = 0.7 0.8\nElementType = MET_USHORT\n\
              BinaryDataByteOrderMSB = True\nElementDataFile = be.raw\n",
        );
        let v = d.read(&p).unwrap();
        assert_eq!(v.grid.dims, [2, 2, 1]);
        assert_eq!(v.grid.spacing, DVec3::new(0.7, 0.8, 1.0));
        assert_eq!(v.data, VoxelData::U16(v16));

        // .mha with LOCAL float data.
        let f: Vec<f32> = vec![0.5, -1.25, 3.0, 1e6];
        let mut mha = b"NDims = 3\nDimSize = 1 2 2\nElementType = MET_FLOAT\n\
                        ElementDataFile = LOCAL\n"
            .to_vec();
        mha.extend(f.iter().flat_map(|v| v.to_le_bytes()));
        let p = d.write("f.mha", &mha);
        assert_eq!(d.read(&p).unwrap().data, VoxelData::F32(f));

        // Compressed (zlib) uchar in a .mha, and MET_DOUBLE / MET_CHAR conversions.
        let u: Vec<u8> = (0..60).collect();
        let z = zlib(&u);
        let mut mha = format!(
            "NDims = 3\nDimSize = 5 4 3\nElementType = MET_UCHAR\nCompressedData = True\n\
             CompressedDataSize = {}\nElementDataFile = LOCAL\n",
            z.len()
        )
        .into_bytes();
        mha.extend_from_slice(&z);
        let p = d.write("z.mha", &mha);
        assert_eq!(d.read(&p).unwrap().data, VoxelData::U8(u));

        let dd: Vec<u8> = [1.5f64, -2.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        d.write("d.raw", &dd);
        let p = d.write(
            "d.mhd",
            b"NDims = 3\nDimSize = 2 1 1\nElementType = MET_DOUBLE\nElementDataFile = d.raw\n",
        );
        assert_eq!(d.read(&p).unwrap().data, VoxelData::F32(vec![1.5, -2.0]));
        d.write("c.raw", &[0xff, 0x05]);
        let p = d.write(
            "c.mhd",
            b"NDims = 3\nDimSize = 2 1 1\nElementType = MET_CHAR\nElementDataFile = c.raw\n",
        );
        assert_eq!(d.read(&p).unwrap().data, VoxelData::I16(vec![-1, 5]));
        // HeaderSize = -1: data at the end of the file.
        let mut tail = vec![9u8; 17];
        tail.extend_from_slice(&[7, 8]);
        d.write("t.raw", &tail);
        let p = d.write(
            "t.mhd",
            b"NDims = 3\nDimSize = 2 1 1\nElementType = MET_UCHAR\nHeaderSize = -1\n\
              ElementDataFile = t.raw\n",
        );
        assert_eq!(d.read(&p).unwrap().data, VoxelData::U8(vec![7, 8]));
    }

    #[test]
    fn hostile_inputs() {
        let d = Dir::new();
        let raw = i16_le(&vals());
        d.write("vol.raw", &raw);
        let hdr = |from: &str, to: &str| {
            assert!(HDR.contains(from), "{from}");
            HDR.replace(from, to)
        };
        // Length: too short and too long.
        d.write("short.raw", &raw[..raw.len() - 3]);
        let p = d.write("short.mhd", hdr("vol.raw", "short.raw").as_bytes());
        expect_err(
            d.read(&p),
            &p,
            &["`DimSize`", "only 21 bytes", "need 24 bytes", "short.raw"],
        );
        let mut long = raw.clone();
        long.extend_from_slice(&[0; 4]);
        d.write("long.raw", &long);
        let p = d.write("long.mhd", hdr("vol.raw", "long.raw").as_bytes());
        expect_err(
            d.read(&p),
            &p,
            &["`DimSize`", "holds 28 bytes", "need 24 bytes"],
        );
        // Dims: cap, zero, negative, count.
        let p = d.write("ok.mhd", HDR.as_bytes());
        expect_err(
            read_metaimage(
                &p,
                &ReadOptions {
                    max_voxels: 11,
                    ..Default::default()
                },
            ),
            &p,
            &["`DimSize`", "12 voxels", "max_voxels"],
        );
        let p = d.write(
            "zero.mhd",
            hdr("DimSize = 3 2 2", "DimSize = 3 0 2").as_bytes(),
        );
        expect_err(d.read(&p), &p, &["`DimSize`", "axis 1 is 0", "positive"]);
        let p = d.write(
            "neg.mhd",
            hdr("DimSize = 3 2 2", "DimSize = 3 2 -2").as_bytes(),
        );
        expect_err(d.read(&p), &p, &["`DimSize`", "axis 2 is -2"]);
        let p = d.write(
            "few.mhd",
            hdr("DimSize = 3 2 2", "DimSize = 3 2").as_bytes(),
        );
        expect_err(d.read(&p), &p, &["`DimSize`", "NDims is 3"]);
        let p = d.write(
            "huge.mhd",
            hdr(
                "DimSize = 3 2 2",
                "DimSize = 4294967296 4294967296 4294967296",
            )
            .as_bytes(),
        );
        expect_err(d.read(&p), &p, &["`DimSize`", "max_voxels"]);
        // Spacing.
        for (name, s) in [("nan", "nan"), ("inf", "inf"), ("zero", "0"), ("neg", "-1")] {
            let p = d.write(
                &format!("sp_{name}.mhd"),
                hdr(
                    "ElementSpacing = 0.5 1 2.5",
                    &format!("ElementSpacing = 0.5 {s} 2.5"),
                )
                .as_bytes(),
            );
            expect_err(
                d.read(&p),
                &p,
                &["`ElementSpacing`", "axis 1", "finite positive"],
            );
        }
        let p = d.write(
            "sp_text.mhd",
            hdr("ElementSpacing = 0.5 1 2.5", "ElementSpacing = 0.5 one 2.5").as_bytes(),
        );
        expect_err(
            d.read(&p),
            &p,
            &["`ElementSpacing`", "`one`", "not a valid number"],
        );
        // Truncated compressed data.
        let big: Vec<u8> = (0..40_000u32)
            .map(|i| (i.wrapping_mul(2654435761) >> 24) as u8)
            .collect();
        let z = zlib(&big);
        d.write("cut.zraw", &z[..z.len() / 2]);
        let p = d.write(
            "cut.mhd",
            b"NDims = 3\nDimSize = 100 100 4\nElementType = MET_UCHAR\nCompressedData = True\n\
              ElementDataFile = cut.zraw\n",
        );
        expect_err(
            d.read(&p),
            &p,
            &["damaged data", "truncated or corrupt", "cut.zraw"],
        );
        // Unknown type, missing data file, garbage.
        let p = d.write("type.mhd", hdr("MET_SHORT", "MET_QUATERNION").as_bytes());
        expect_err(
            d.read(&p),
            &p,
            &["`ElementType`", "MET_QUATERNION", "MET_UCHAR"],
        );
        let p = d.write("missing.mhd", hdr("vol.raw", "nowhere.raw").as_bytes());
        expect_err(
            d.read(&p),
            &p,
            &[
                "`ElementDataFile`",
                "nowhere.raw",
                "does not exist",
                "relative to the header",
            ],
        );
        let p = d.write("garbage.mhd", b"Lorem ipsum dolor sit amet\nconsectetur\n");
        expect_err(
            d.read(&p),
            &p,
            &["is not `Key = Value`", "not a MetaImage header"],
        );
        let p = d.write("nofile.mhd", b"NDims = 3\nDimSize = 1 1 1\n");
        expect_err(d.read(&p), &p, &["`ElementDataFile`", "missing"]);
        let p = d.write(
            "binary.mha",
            &[0xff, 0xfe, 0x00, 0x80, b'=', 0x9f, b'\n', 1, 2],
        );
        expect_err(d.read(&p), &p, &["not text", "not a MetaImage header"]);
        let p = d.write(
            "channels.mhd",
            hdr("NDims = 3", "NDims = 3\nElementNumberOfChannels = 3").as_bytes(),
        );
        expect_err(d.read(&p), &p, &["ElementNumberOfChannels", "one-channel"]);
    }
}
