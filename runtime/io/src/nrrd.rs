//! NRRD volumes (Teem's format): `.nrrd` with the data attached after the
//! header's blank line, or `.nhdr` with the data in a detached file named by
//! `data file:` (resolved relative to the header's folder).
//!
//! Fields read:
//! - `dimension` (1–3; more only when the extra sizes are 1) and `sizes`;
//! - `type`: `uchar`, `short`, `ushort`, `float` and their synonyms
//!   (`unsigned char`, `uint8`, `int16_t`, …) as they are; `signed char` →
//!   `i16`; `int`, `uint`, `longlong`, `ulonglong`, `double` → `f32`;
//! - `encoding`: `raw`, `gzip`/`gz`, `ascii`/`text`/`txt` (`bzip2` and `hex`
//!   are refused with a message);
//! - `endian` (`little`/`big`; required for multi-byte binary data);
//! - geometry: `space directions` (each axis's step vector, mm) or else
//!   `spacings` (axis-aligned), else 1 mm; origin (mm) from `space origin`,
//!   else 0; `space` `right-anterior-superior` (RAS) and
//!   `left-anterior-superior` (LAS) are converted to voxflex's LPS world,
//!   other spaces taken as they are. Axis permutations and flips are
//!   applied by reordering the voxels (see [`super::orientation`]); an
//!   oblique volume is placed along its closest axes with a warning.
//!   `measurement frame` is ignored.
//! - `byte skip` (raw: in the file, `-1` = data at the end; gzip: in the
//!   decompressed stream) and `line skip` (lines skipped in the data file).
//!
//! Key/value pairs (`key:=value`) and comments (`#`) are ignored.

use super::orientation::{HeaderFrame, HeaderGeometry, place};
use super::{
    DataSpec, RawType, ReadOptions, file_len, header_err, open, read_voxels, skip_bytes,
    validate_dims, validate_origin, validate_spacing,
};
use crate::error::IoError;
use crate::volume::{Volume, VoxelData};
use glam::DVec3;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

/// Largest header accepted, in bytes.
const MAX_HEADER_BYTES: u64 = 1 << 20;

struct Header {
    /// (lower-case field name, value), in order.
    fields: Vec<(String, String)>,
    /// Bytes up to and including the blank line (start of attached data).
    len: u64,
    /// True when a blank line ended the header (data may be attached).
    blank_line: bool,
}

impl Header {
    fn get(&self, names: &[&str]) -> Option<&str> {
        names.iter().find_map(|n| {
            self.fields
                .iter()
                .find(|(k, _)| k == n)
                .map(|(_, v)| v.as_str())
        })
    }
}

fn parse_header(path: &Path, reader: &mut dyn BufRead) -> Result<Header, IoError> {
    let mut fields = Vec::new();
    let mut len: u64 = 0;
    let mut line = Vec::new();
    let mut blank_line = false;
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
        if len >= MAX_HEADER_BYTES {
            return Err(IoError::Unsupported {
                path: path.to_path_buf(),
                message: "the header is over 1 MiB without a blank line: this is not a NRRD \
                          header"
                    .into(),
            });
        }
        if n == 0 {
            break;
        }
        let Ok(text) = std::str::from_utf8(&line) else {
            return Err(IoError::Unsupported {
                path: path.to_path_buf(),
                message: format!(
                    "header line {line_no} is not text: this is not a NRRD header (or the \
                     blank line before the attached data is missing)"
                ),
            });
        };
        let text = text.trim_end_matches(['\n', '\r']);
        if line_no == 1 {
            if !text.starts_with("NRRD000") {
                return Err(header_err(
                    path,
                    "magic",
                    format!(
                        "the first line is `{}`, not `NRRD000x`: this is not a NRRD file",
                        text.chars().take(40).collect::<String>()
                    ),
                ));
            }
            continue;
        }
        if text.trim().is_empty() {
            blank_line = true;
            break;
        }
        if text.starts_with('#') || text.contains(":=") {
            continue;
        }
        let Some((key, value)) = text.split_once(':') else {
            return Err(IoError::Unsupported {
                path: path.to_path_buf(),
                message: format!(
                    "header line {line_no} `{}` is not `field: value`; a NRRD header ends with \
                     a blank line before attached data",
                    text.chars().take(60).collect::<String>()
                ),
            });
        };
        fields.push((key.trim().to_ascii_lowercase(), value.trim().to_string()));
    }
    Ok(Header {
        fields,
        len,
        blank_line,
    })
}

fn numbers<T: std::str::FromStr>(path: &Path, field: &str, value: &str) -> Result<Vec<T>, IoError> {
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

/// Parses NRRD vectors `(x,y,z) (x,y,z) none …`; `none` becomes `None`.
fn vectors(path: &Path, field: &str, value: &str) -> Result<Vec<Option<Vec<f64>>>, IoError> {
    let mut out = Vec::new();
    let mut rest = value.trim();
    while !rest.is_empty() {
        if let Some(r) = rest.strip_prefix("none") {
            out.push(None);
            rest = r.trim_start();
            continue;
        }
        let bad = || {
            header_err(
                path,
                field,
                format!("`{value}` is not a list of vectors like `(1,0,0) (0,1,0) (0,0,1)`"),
            )
        };
        let r = rest.strip_prefix('(').ok_or_else(bad)?;
        let (inner, r) = r.split_once(')').ok_or_else(bad)?;
        let v = inner
            .split(',')
            .map(|t| t.trim().parse::<f64>().map_err(|_| bad()))
            .collect::<Result<Vec<_>, _>>()?;
        out.push(Some(v));
        rest = r.trim_start();
    }
    Ok(out)
}

fn type_of(path: &Path, value: &str) -> Result<RawType, IoError> {
    let v = value.to_ascii_lowercase();
    let v = v.split_whitespace().collect::<Vec<_>>().join(" ");
    Ok(match v.as_str() {
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => RawType::U8,
        "signed char" | "int8" | "int8_t" => RawType::I8,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => {
            RawType::I16
        }
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => RawType::U16,
        "int" | "signed int" | "int32" | "int32_t" => RawType::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => RawType::U32,
        "longlong"
        | "long long"
        | "long long int"
        | "signed long long"
        | "signed long long int"
        | "int64"
        | "int64_t" => RawType::I64,
        "ulonglong" | "unsigned long long" | "unsigned long long int" | "uint64" | "uint64_t" => {
            RawType::U64
        }
        "float" => RawType::F32,
        "double" => RawType::F64,
        _ => {
            return Err(header_err(
                path,
                "type",
                format!(
                    "`{value}` is not a NRRD scalar type voxflex reads (uchar, signed char, \
                     short, ushort, int, uint, longlong, ulonglong, float, double, or a synonym)"
                ),
            ));
        }
    })
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Encoding {
    Raw,
    Gzip,
    Ascii,
}

/// The detached data file a NRRD header names (`data file:`, resolved
/// relative to the header's folder), or `None` for attached data. Only the
/// header is read.
pub(crate) fn detached_data_file(path: &Path) -> Result<Option<PathBuf>, IoError> {
    let mut reader = BufReader::new(open(path)?);
    let h = parse_header(path, &mut reader)?;
    Ok(h.get(&["data file", "datafile"])
        .map(|name| path.parent().unwrap_or(Path::new("")).join(name.trim())))
}

/// Reads a NRRD `.nrrd` (attached or detached data) or `.nhdr` volume. See
/// the module docs for the fields understood; rotations are not applied.
pub fn read_nrrd(path: &Path, opts: &ReadOptions) -> Result<Volume, IoError> {
    let file = open(path)?;
    let header_file_len = file_len(path, &file)?;
    let mut reader = BufReader::with_capacity(1 << 20, file);
    let h = parse_header(path, &mut reader)?;
    let missing = |field: &str, what: &str| header_err(path, field, format!("missing; {what}"));

    // --- dims -----------------------------------------------------------
    let dimension: usize = match h.get(&["dimension"]) {
        Some(v) => match numbers::<i64>(path, "dimension", v)?.as_slice() {
            [n] if (1..=16).contains(n) => *n as usize,
            _ => {
                return Err(header_err(
                    path,
                    "dimension",
                    format!("`{v}` is not a dimension count (1 to 3 for a volume)"),
                ));
            }
        },
        None => return Err(missing("dimension", "add `dimension: 3`")),
    };
    let sizes_v = h
        .get(&["sizes"])
        .ok_or_else(|| missing("sizes", "add `sizes: <nx> <ny> <nz>`"))?;
    let sizes: Vec<i64> = numbers(path, "sizes", sizes_v)?;
    if sizes.len() != dimension {
        return Err(header_err(
            path,
            "sizes",
            format!(
                "has {} size(s) `{sizes_v}` but dimension is {dimension}; give one size per axis",
                sizes.len()
            ),
        ));
    }
    if let Some((i, &s)) = sizes.iter().enumerate().skip(3).find(|&(_, &s)| s != 1) {
        return Err(IoError::Unsupported {
            path: path.to_path_buf(),
            message: format!(
                "header field `sizes`: axis {i} has size {s}; voxflex reads 3-D scalar volumes"
            ),
        });
    }
    let mut raw_dims = [1i64; 3];
    for (d, s) in raw_dims.iter_mut().zip(sizes.iter()) {
        *d = *s;
    }
    let dims = validate_dims(path, "sizes", raw_dims, opts.max_voxels)?;

    // --- type, encoding, endian -----------------------------------------
    let ty = type_of(
        path,
        h.get(&["type"])
            .ok_or_else(|| missing("type", "add e.g. `type: short`"))?,
    )?;
    let enc_v = h
        .get(&["encoding"])
        .ok_or_else(|| missing("encoding", "add e.g. `encoding: raw`"))?;
    let encoding = match enc_v.to_ascii_lowercase().as_str() {
        "raw" => Encoding::Raw,
        "gzip" | "gz" => Encoding::Gzip,
        "ascii" | "text" | "txt" => Encoding::Ascii,
        "bzip2" | "bz2" | "hex" => {
            return Err(IoError::Unsupported {
                path: path.to_path_buf(),
                message: format!(
                    "header field `encoding`: `{enc_v}` is not supported; re-save with raw or \
                     gzip encoding (e.g. `unu save -e gzip`)"
                ),
            });
        }
        _ => {
            return Err(header_err(
                path,
                "encoding",
                format!("`{enc_v}` is not a NRRD encoding (raw, gzip, ascii)"),
            ));
        }
    };
    let big_endian = match h.get(&["endian"]) {
        Some(v) => match v.to_ascii_lowercase().as_str() {
            "little" => false,
            "big" => true,
            _ => {
                return Err(header_err(
                    path,
                    "endian",
                    format!("`{v}` is neither `little` nor `big`"),
                ));
            }
        },
        None if ty.size() > 1 && encoding != Encoding::Ascii => {
            return Err(missing(
                "endian",
                "multi-byte binary data needs `endian: little` or `endian: big`",
            ));
        }
        None => false,
    };

    // --- geometry -------------------------------------------------------
    let frame = match h.get(&["space"]).map(|v| v.trim().to_ascii_lowercase()) {
        Some(v) if v == "right-anterior-superior" || v == "ras" => HeaderFrame::Ras,
        Some(v) if v == "left-anterior-superior" || v == "las" => HeaderFrame::Las,
        // LPS, or a frame with no anatomical meaning (scanner-xyz,
        // 3D-right-handed, …): taken as voxflex's world as it is.
        _ => HeaderFrame::Lps,
    };
    let mut directions = None;
    let spacing = if let Some(v) = h.get(&["space directions"]) {
        let vecs = vectors(path, "space directions", v)?;
        if vecs.len() != dimension {
            return Err(header_err(
                path,
                "space directions",
                format!("has {} entries but dimension is {dimension}", vecs.len()),
            ));
        }
        let mut spacing = [1.0f64; 3];
        let mut cols = [[0.0f64; 3]; 3];
        for (axis, vec) in vecs.iter().take(3).enumerate() {
            let Some(vec) = vec else {
                return Err(IoError::Unsupported {
                    path: path.to_path_buf(),
                    message: format!(
                        "header field `space directions`: axis {axis} is `none` (not spatial); \
                         voxflex reads scalar volumes whose first three axes are spatial"
                    ),
                });
            };
            spacing[axis] = vec.iter().map(|c| c * c).sum::<f64>().sqrt();
            for (c, x) in cols[axis].iter_mut().zip(vec.iter()) {
                *c = *x;
            }
        }
        let spacing = validate_spacing(path, "space directions", spacing)?;
        directions = Some(cols.map(DVec3::from_array));
        spacing
    } else if let Some(v) = h.get(&["spacings"]) {
        let s: Vec<f64> = numbers(path, "spacings", v)?;
        if s.len() != dimension {
            return Err(header_err(
                path,
                "spacings",
                format!("has {} value(s) but dimension is {dimension}", s.len()),
            ));
        }
        let mut spacing = [1.0f64; 3];
        for (d, x) in spacing.iter_mut().zip(s.iter()) {
            *d = *x;
        }
        validate_spacing(path, "spacings", spacing)?
    } else {
        glam::DVec3::ONE
    };
    let origin = match h.get(&["space origin"]) {
        Some(v) => {
            let vecs = vectors(path, "space origin", v)?;
            match vecs.as_slice() {
                [Some(o)] if !o.is_empty() && o.len() <= 3 => {
                    let mut origin = [0.0f64; 3];
                    for (d, x) in origin.iter_mut().zip(o.iter()) {
                        *d = *x;
                    }
                    validate_origin(path, "space origin", origin)?
                }
                _ => {
                    return Err(header_err(
                        path,
                        "space origin",
                        format!("`{v}` is not one vector like `(0,0,0)`"),
                    ));
                }
            }
        }
        None => glam::DVec3::ZERO,
    };

    // --- skips ----------------------------------------------------------
    let byte_skip: i64 = match h.get(&["byte skip", "byteskip"]) {
        Some(v) => match numbers::<i64>(path, "byte skip", v)?.as_slice() {
            [n] if *n >= -1 && !(*n == -1 && encoding != Encoding::Raw) => *n,
            _ => {
                return Err(header_err(
                    path,
                    "byte skip",
                    format!("`{v}` is not a byte count (≥ 0, or -1 = data at the end, raw only)"),
                ));
            }
        },
        None => 0,
    };
    let line_skip: u64 = match h.get(&["line skip", "lineskip"]) {
        Some(v) => match numbers::<u64>(path, "line skip", v)?.as_slice() {
            [n] => *n,
            _ => {
                return Err(header_err(
                    path,
                    "line skip",
                    format!("`{v}` is not a line count"),
                ));
            }
        },
        None => 0,
    };

    // --- data source ----------------------------------------------------
    let data_path: PathBuf;
    let mut data_reader: Box<dyn BufRead>;
    let mut data_len: u64;
    match h.get(&["data file", "datafile"]) {
        Some(v) => {
            let name = v.trim();
            if name.eq_ignore_ascii_case("LIST")
                || name.contains('%')
                || name.split_whitespace().count() > 1
            {
                return Err(IoError::Unsupported {
                    path: path.to_path_buf(),
                    message: format!(
                        "header field `data file`: `{name}` names several files; voxflex reads \
                         one data file — merge the slices first"
                    ),
                });
            }
            let base = path.parent().unwrap_or(Path::new(""));
            data_path = base.join(name);
            super::refuse_non_regular(&data_path)?;
            let f = match std::fs::File::open(&data_path) {
                Ok(f) => f,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                    return Err(header_err(
                        path,
                        "data file",
                        format!(
                            "data file {} does not exist (`{name}` is resolved relative to the \
                             header's folder); copy the data file next to the header or fix the \
                             name",
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
        None => {
            if !h.blank_line {
                return Err(header_err(
                    path,
                    "data file",
                    "missing: the header has neither a `data file:` line (detached data, as in \
                     .nhdr) nor a blank line followed by attached data",
                ));
            }
            data_path = path.to_path_buf();
            data_len = header_file_len.saturating_sub(h.len);
            data_reader = Box::new(reader);
        }
    }
    for _ in 0..line_skip {
        let mut sink = Vec::new();
        let n = (&mut data_reader)
            .take(MAX_HEADER_BYTES)
            .read_until(b'\n', &mut sink)
            .map_err(|source| IoError::Io {
                path: data_path.clone(),
                source,
            })?;
        if n == 0 {
            return Err(header_err(
                path,
                "line skip",
                format!("is {line_skip} but the data ends first; fix the header"),
            ));
        }
        data_len = data_len.saturating_sub(n as u64);
    }

    let spec = DataSpec {
        header_path: path,
        data_path: &data_path,
        dims_field: "sizes",
        dims,
        ty,
        big_endian,
        compressed: encoding == Encoding::Gzip,
        available: None,
    };
    let needed = spec.needed_bytes()?;
    let data = match encoding {
        Encoding::Raw => {
            let skip = if byte_skip == -1 {
                data_len.saturating_sub(needed)
            } else {
                byte_skip as u64
            };
            let skipped = skip_bytes(&mut data_reader, skip).map_err(|source| IoError::Io {
                path: data_path.clone(),
                source,
            })?;
            if skipped < skip {
                return Err(header_err(
                    path,
                    "byte skip",
                    format!("is {skip} but the data holds only {skipped} bytes; fix the header"),
                ));
            }
            let spec = DataSpec {
                available: Some(data_len.saturating_sub(skip)),
                ..spec
            };
            read_voxels(&mut data_reader, &spec)?
        }
        Encoding::Gzip => {
            let mut gz: Box<dyn Read> = Box::new(flate2::bufread::MultiGzDecoder::new(data_reader));
            let skip = byte_skip as u64; // -1 refused above for gzip
            let skipped = skip_bytes(&mut gz, skip).map_err(|e| IoError::Corrupt {
                path: data_path.clone(),
                message: format!(
                    "the gzip stream is truncated or corrupt ({e}); obtain a complete copy"
                ),
            })?;
            if skipped < skip {
                return Err(header_err(
                    path,
                    "byte skip",
                    format!("is {skip} but the data holds only {skipped} bytes; fix the header"),
                ));
            }
            read_voxels(&mut gz, &spec)?
        }
        Encoding::Ascii => {
            if byte_skip > 0 {
                skip_bytes(&mut data_reader, byte_skip as u64).map_err(|source| IoError::Io {
                    path: data_path.clone(),
                    source,
                })?;
            }
            read_ascii(&mut data_reader, &spec)?
        }
    };
    let geometry = match directions {
        Some(directions) => HeaderGeometry {
            directions,
            origin,
            frame,
            field: "space directions",
        },
        None => HeaderGeometry::aligned(spacing, origin, frame, "spacings"),
    };
    place(path, dims, data, geometry, opts)
}

/// Reads whitespace-separated ASCII values.
fn read_ascii(reader: &mut dyn BufRead, spec: &DataSpec<'_>) -> Result<VoxelData, IoError> {
    let n = spec.dims[0] * spec.dims[1] * spec.dims[2];
    let mut values: Vec<f64> = Vec::new();
    values
        .try_reserve_exact(n)
        .map_err(|_| IoError::InvalidRequest {
            path: spec.header_path.to_path_buf(),
            message: format!("cannot allocate memory for {n} values"),
        })?;
    let mut line = String::new();
    let mut count: u64 = 0;
    loop {
        line.clear();
        let got = reader
            .take(1 << 20)
            .read_line(&mut line)
            .map_err(|e| IoError::Corrupt {
                path: spec.data_path.to_path_buf(),
                message: format!("ASCII data is not text ({e})"),
            })?;
        if got == 0 {
            break;
        }
        for t in line.split(|c: char| c.is_whitespace() || c == ',') {
            if t.is_empty() {
                continue;
            }
            count += 1;
            if values.len() < n {
                let v = t.parse::<f64>().map_err(|_| IoError::Corrupt {
                    path: spec.data_path.to_path_buf(),
                    message: format!("ASCII value {count} `{t}` is not a number"),
                })?;
                values.push(v);
            }
        }
    }
    if count != n as u64 {
        return Err(header_err(
            spec.header_path,
            spec.dims_field,
            format!(
                "the ASCII data holds {count} values but dims {} × {} × {} need {n}; fix the \
                 header or the data",
                spec.dims[0], spec.dims[1], spec.dims[2]
            ),
        ));
    }
    Ok(match spec.ty {
        RawType::U8 => VoxelData::U8(values.iter().map(|&v| v as u8).collect()),
        RawType::I8 | RawType::I16 => VoxelData::I16(values.iter().map(|&v| v as i16).collect()),
        RawType::U16 => VoxelData::U16(values.iter().map(|&v| v as u16).collect()),
        _ => VoxelData::F32(values.iter().map(|&v| v as f32).collect()),
    })
}

#[cfg(test)]
mod tests {
    use super::super::test_util::{expect_err, gzip, reversed};
    use super::*;
    use glam::DVec3;

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
            read_nrrd(p, &ReadOptions::default())
        }
    }

    const HDR: &str = "NRRD0004\n# Complete NRRD file format specification at:\n\
                       # http://teem.sourceforge.net/nrrd/format.html\ntype: short\n\
                       dimension: 3\nspace: left-posterior-superior\nsizes: 3 2 2\n\
                       spacings: 0.5 1 2.5\nkinds: domain domain domain\nendian: little\n\
                       encoding: raw\nspace origin: (-1.5,2,30)\nkey:=value\n\n";

    fn vals() -> Vec<i16> {
        (0..12).map(|i| i * 100 - 500).collect()
    }
    fn le(v: &[i16]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_le_bytes()).collect()
    }
    fn attached(hdr: &str, data: &[u8]) -> Vec<u8> {
        let mut b = hdr.as_bytes().to_vec();
        b.extend_from_slice(data);
        b
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_data_file_is_refused_without_blocking() {
        let d = Dir::new();
        let fifo = d.0.path().join("pipe.raw");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap();
        assert!(made.success());
        let p = d.write(
            "fifo.nhdr",
            HDR.replace("encoding: raw\n", "encoding: raw\ndata file: pipe.raw\n")
                .as_bytes(),
        );
        // Before the check, this open blocked forever waiting for a writer.
        let e = d.read(&p).unwrap_err().to_string();
        assert!(e.contains("pipe.raw") && e.contains("a FIFO"), "{e}");
        // The source itself as a FIFO is refused the same way.
        let fifo_src = d.0.path().join("src.nrrd");
        assert!(
            std::process::Command::new("mkfifo")
                .arg(&fifo_src)
                .status()
                .unwrap()
                .success()
        );
        let e = d.read(&fifo_src).unwrap_err().to_string();
        assert!(e.contains("src.nrrd") && e.contains("a FIFO"), "{e}");
    }

    #[test]
    fn volume_files_name_the_detached_data_file() {
        let d = Dir::new();
        let p = d.write(
            "v.nhdr",
            HDR.replace("encoding: raw\n", "encoding: raw\ndata file: sub/v.raw\n")
                .as_bytes(),
        );
        assert_eq!(
            super::super::volume_files(&p).unwrap(),
            vec![p.clone(), d.0.path().join("sub/v.raw")]
        );
        let p = d.write("a.nrrd", &attached(HDR, &le(&vals())));
        assert_eq!(super::super::volume_files(&p).unwrap(), vec![p.clone()]);
    }

    #[test]
    fn reads_attached_raw() {
        let d = Dir::new();
        let p = d.write("v.nrrd", &attached(HDR, &le(&vals())));
        let v = super::super::read_volume(&p, &ReadOptions::default()).unwrap();
        assert_eq!(v.grid.dims, [3, 2, 2]);
        assert_eq!(v.grid.spacing, DVec3::new(0.5, 1.0, 2.5));
        // `space: left-posterior-superior` is voxflex's own world.
        assert_eq!(v.grid.origin, DVec3::new(-1.5, 2.0, 30.0));
        assert_eq!(v.data, VoxelData::I16(vals()));
        // The same header in RAS: x and y reversed, voxel 0 at RAS
        // (−1.5, 2, 30) = LPS (1.5, −2, 30) now the last along both.
        let ras = HDR.replace("left-posterior-superior", "right-anterior-superior");
        let p = d.write("ras.nrrd", &attached(&ras, &le(&vals())));
        let v = d.read(&p).unwrap();
        assert_eq!(v.grid.origin, DVec3::new(0.5, -3.0, 30.0));
        assert_eq!(
            v.data,
            VoxelData::I16(reversed(&vals(), [3, 2, 2], [true, true, false]))
        );
    }

    #[test]
    fn reads_gzip_big_endian_detached_and_ascii() {
        let d = Dir::new();
        // Attached gzip, big-endian float, space directions.
        let f: Vec<f32> = (0..12).map(|i| i as f32 * 0.5 - 1.0).collect();
        let be: Vec<u8> = f.iter().flat_map(|x| x.to_be_bytes()).collect();
        let hdr = "NRRD0005\ntype: float\ndimension: 3\nsizes: 2 3 2\n\
                   space directions: (0.7,0,0) (0,0.8,0) (0,0,-3)\nendian: big\n\
                   encoding: gzip\nspace origin: (1, 2, 3)\n\n";
        let p = d.write("g.nrrd", &attached(hdr, &gzip(&be)));
        let v = d.read(&p).unwrap();
        assert_eq!(v.grid.dims, [2, 3, 2]);
        assert_eq!(v.grid.spacing, DVec3::new(0.7, 0.8, 3.0));
        // z runs backwards (−3 mm per slice): the slices are reversed and
        // the grid starts at the last one, 3 mm below voxel 0.
        assert_eq!(v.grid.origin, DVec3::new(1.0, 2.0, 0.0));
        assert_eq!(
            v.data,
            VoxelData::F32(reversed(&f, [2, 3, 2], [false, false, true]))
        );

        // Detached gz (`gz` synonym) with MSB ushort and byte skip after decompression.
        let u: Vec<u16> = vec![1, 2, 0x1234, 65535];
        let mut raw = vec![0xAA; 5];
        raw.extend(u.iter().flat_map(|x| x.to_be_bytes()));
        std::fs::create_dir_all(d.0.path().join("data")).unwrap();
        d.write("data/u.raw.gz", &gzip(&raw));
        let p = d.write(
            "u.nhdr",
            b"NRRD0004\ntype: unsigned short\ndimension: 2\nsizes: 2 2\nendian: big\n\
              encoding: gz\nbyte skip: 5\ndata file: data/u.raw.gz\n",
        );
        let v = d.read(&p).unwrap();
        assert_eq!(v.grid.dims, [2, 2, 1]);
        assert_eq!(v.data, VoxelData::U16(u));

        // Detached raw with byte skip -1 and line skip; uchar needs no endian.
        d.write("b.raw", b"junk line\nXXXX\x01\x02\x03");
        let p = d.write(
            "b.nhdr",
            b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 3 1 1\nencoding: raw\n\
              line skip: 1\nbyte skip: -1\ndatafile: b.raw\n",
        );
        assert_eq!(d.read(&p).unwrap().data, VoxelData::U8(vec![1, 2, 3]));

        // ASCII int → f32, double via raw → f32.
        let p = d.write(
            "a.nrrd",
            b"NRRD0004\ntype: int\ndimension: 3\nsizes: 2 2 1\nencoding: ascii\n\n1 -2\n3 400000\n",
        );
        assert_eq!(
            d.read(&p).unwrap().data,
            VoxelData::F32(vec![1.0, -2.0, 3.0, 400000.0])
        );
        let dd: Vec<u8> = [2.5f64, -1.0]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        let p = d.write(
            "d.nrrd",
            &attached(
                "NRRD0004\ntype: double\ndimension: 1\nsizes: 2\nendian: little\nencoding: raw\n\n",
                &dd,
            ),
        );
        assert_eq!(d.read(&p).unwrap().data, VoxelData::F32(vec![2.5, -1.0]));
    }

    #[test]
    fn hostile_inputs() {
        let d = Dir::new();
        let data = le(&vals());
        let hdr = |from: &str, to: &str| {
            assert!(HDR.contains(from), "{from}");
            HDR.replace(from, to)
        };
        // Length both ways, attached and gzip.
        let p = d.write("short.nrrd", &attached(HDR, &data[..data.len() - 1]));
        expect_err(
            d.read(&p),
            &p,
            &["`sizes`", "only 23 bytes", "need 24 bytes"],
        );
        let mut long = data.clone();
        long.push(0);
        let p = d.write("long.nrrd", &attached(HDR, &long));
        expect_err(
            d.read(&p),
            &p,
            &["`sizes`", "holds 25 bytes", "need 24 bytes"],
        );
        let gz_hdr = hdr("encoding: raw", "encoding: gzip");
        let p = d.write("long_gz.nrrd", &attached(&gz_hdr, &gzip(&long)));
        expect_err(d.read(&p), &p, &["`sizes`", "holds 25 bytes"]);
        // Truncated gzip.
        let big: Vec<u8> = (0..80_000u32)
            .map(|i| (i.wrapping_mul(2654435761) >> 24) as u8)
            .collect();
        let z = gzip(&big);
        let p = d.write(
            "cut.nrrd",
            &attached(
                "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 100 100 8\nencoding: gzip\n\n",
                &z[..z.len() / 2],
            ),
        );
        expect_err(d.read(&p), &p, &["damaged data", "truncated or corrupt"]);
        // Dims.
        let p = d.write("ok.nrrd", &attached(HDR, &data));
        expect_err(
            read_nrrd(
                &p,
                &ReadOptions {
                    max_voxels: 5,
                    ..Default::default()
                },
            ),
            &p,
            &["`sizes`", "12 voxels", "max_voxels"],
        );
        let p = d.write(
            "zero.nrrd",
            &attached(&hdr("sizes: 3 2 2", "sizes: 0 2 2"), &data),
        );
        expect_err(d.read(&p), &p, &["`sizes`", "axis 0 is 0", "positive"]);
        let p = d.write(
            "neg.nrrd",
            &attached(&hdr("sizes: 3 2 2", "sizes: 3 -2 2"), &data),
        );
        expect_err(d.read(&p), &p, &["`sizes`", "axis 1 is -2"]);
        let p = d.write(
            "count.nrrd",
            &attached(&hdr("sizes: 3 2 2", "sizes: 3 2"), &data),
        );
        expect_err(d.read(&p), &p, &["`sizes`", "dimension is 3"]);
        let p = d.write(
            "huge.nrrd",
            &attached(
                &hdr("sizes: 3 2 2", "sizes: 9000000000 9000000000 9000000000"),
                &data,
            ),
        );
        expect_err(d.read(&p), &p, &["`sizes`", "max_voxels"]);
        // Spacing.
        for (name, s) in [("nan", "nan"), ("inf", "inf"), ("zero", "0"), ("neg", "-2")] {
            let p = d.write(
                &format!("sp_{name}.nrrd"),
                &attached(
                    &hdr("spacings: 0.5 1 2.5", &format!("spacings: 0.5 1 {s}")),
                    &data,
                ),
            );
            expect_err(d.read(&p), &p, &["`spacings`", "axis 2", "finite positive"]);
        }
        let p = d.write(
            "dir_zero.nrrd",
            &attached(
                &hdr(
                    "spacings: 0.5 1 2.5",
                    "space directions: (1,0,0) (0,0,0) (0,0,1)",
                ),
                &data,
            ),
        );
        expect_err(
            d.read(&p),
            &p,
            &["`space directions`", "axis 1", "finite positive"],
        );
        let p = d.write(
            "dir_nan.nrrd",
            &attached(
                &hdr(
                    "spacings: 0.5 1 2.5",
                    "space directions: (nan,0,0) (0,1,0) (0,0,1)",
                ),
                &data,
            ),
        );
        expect_err(d.read(&p), &p, &["`space directions`", "axis 0"]);
        // Type, encoding, endian.
        let p = d.write(
            "type.nrrd",
            &attached(&hdr("type: short", "type: quaternion"), &data),
        );
        expect_err(d.read(&p), &p, &["`type`", "quaternion", "uchar"]);
        let p = d.write(
            "enc.nrrd",
            &attached(&hdr("encoding: raw", "encoding: zip"), &data),
        );
        expect_err(d.read(&p), &p, &["`encoding`", "zip"]);
        let p = d.write(
            "bz.nrrd",
            &attached(&hdr("encoding: raw", "encoding: bzip2"), &data),
        );
        expect_err(d.read(&p), &p, &["`encoding`", "bzip2", "gzip"]);
        let p = d.write(
            "endian.nrrd",
            &attached(&hdr("endian: little\n", ""), &data),
        );
        expect_err(d.read(&p), &p, &["`endian`", "missing"]);
        // Missing data file, and no data at all.
        let p = d.write(
            "missing.nhdr",
            hdr("encoding: raw\n", "encoding: raw\ndata file: gone.raw\n").as_bytes(),
        );
        expect_err(
            d.read(&p),
            &p,
            &["`data file`", "gone.raw", "does not exist"],
        );
        let p = d.write("nodata.nhdr", HDR.trim_end().as_bytes());
        expect_err(d.read(&p), &p, &["`data file`", "missing"]);
        // Garbage.
        let p = d.write("garbage.nrrd", b"<html><body>404 Not Found</body></html>\n");
        expect_err(d.read(&p), &p, &["`magic`", "not a NRRD file"]);
        let p = d.write("nocolon.nrrd", b"NRRD0004\ntype short\n\n");
        expect_err(d.read(&p), &p, &["`type short`", "not `field: value`"]);
        let p = d.write(
            "bin.nrrd",
            &[
                b'N', b'R', b'R', b'D', b'0', b'0', b'0', b'4', b'\n', 0xff, 0xfe, b'\n',
            ],
        );
        expect_err(d.read(&p), &p, &["not text"]);
        let p = d.write(
            "ascii_bad.nrrd",
            b"NRRD0004\ntype: float\ndimension: 1\nsizes: 2\nencoding: ascii\n\n1.0 abc\n",
        );
        expect_err(d.read(&p), &p, &["damaged data", "`abc`"]);
    }
}
