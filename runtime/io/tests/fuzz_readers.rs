//! Property-based fuzzing of the file readers (issue 13): NIfTI-1, NRRD,
//! MetaImage, Gmsh MSH and TetGen, fed mutated *real* headers and bodies.
//!
//! Seeds: a NIfTI written by voxflex's own writer, the header of each real
//! NIfTI in `VOXFLEX_TEST_DATA` (dims shrunk, small body attached; and once
//! untouched with the body cut off), and the NRRD / MetaImage / MSH / TetGen
//! texts of the readers' own tests. Mutations (1–4 per case): byte flips
//! and overwrites, truncation, inserted junk, a numeric field (text: a number
//! token; NIfTI: a binary header field) replaced by a hostile value (huge,
//! negative, NaN, 1e308, overflowing products), a duplicated line
//! (duplicate keys), and — for NIfTI and gzip-encoded NRRD — gzip of the
//! mutated bytes with a damaged stream.
//!
//! Every case must end in `Ok` (a volume within `max_voxels`) or one error
//! whose message is a single non-empty line — never a panic — and no single
//! allocation may exceed what `max_voxels` (volumes) or the file size
//! (meshes) allows: a counting global allocator records the largest request
//! of the reading thread (requests above 1 GiB are refused outright, so a
//! hostile header fails the test instead of the machine).
//!
//! `cargo test -p voxflex-io --test fuzz_readers` runs 10,400 cases
//! (seeded: the same cases every run). For a long run:
//! `VOXFLEX_FUZZ_CASES=200000 VOXFLEX_FUZZ_SEED=7 cargo test --release -p
//! voxflex-io --test fuzz_readers -- --ignored --nocapture` runs that many
//! cases per reader (5 readers) and prints the count and time.

use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::io::Write;
use std::path::{Path, PathBuf};
use voxflex_io::{self as io, ReadOptions};

// ---------------------------------------------------------------------------
// Allocation accounting.
// ---------------------------------------------------------------------------

/// Forwards to the system allocator, recording the largest single request
/// per thread; refuses requests above [`HARD_CAP`].
struct Counting;

/// Requests above this are refused (null), so a reader that trusts a
/// hostile size fails its test instead of exhausting the machine.
const HARD_CAP: usize = 1 << 30;

thread_local! {
    static LARGEST: Cell<usize> = const { Cell::new(0) };
}

fn note(size: usize) {
    let _ = LARGEST.try_with(|l| {
        if size > l.get() {
            l.set(size);
        }
    });
}

// SAFETY: every call forwards to `System` with the caller's arguments.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        if layout.size() > HARD_CAP {
            return std::ptr::null_mut();
        }
        // SAFETY: forwarded.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        if layout.size() > HARD_CAP {
            return std::ptr::null_mut();
        }
        // SAFETY: forwarded.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note(new_size);
        if new_size > HARD_CAP {
            return std::ptr::null_mut();
        }
        // SAFETY: forwarded.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

/// Runs `f`, returning its result and the largest single allocation it (on
/// this thread) requested, bytes.
fn largest_allocation<T>(f: impl FnOnce() -> T) -> (T, usize) {
    LARGEST.with(|l| l.set(0));
    let r = f();
    (r, LARGEST.with(|l| l.get()))
}

/// The fuzzers' voxel cap: 64 × 64 × 64.
const MAX_VOXELS: usize = 1 << 18;

/// The most a volume read may allocate at once: the voxels as f32 (a
/// converted type; 4 bytes each — twice for a reorientation copy), the
/// readers' 1 MiB stream chunk / buffer, and slack for the header text.
fn volume_allocation_bound(input_len: usize) -> usize {
    8 * MAX_VOXELS + (2 << 20) + 4 * input_len
}

/// The most a mesh read may allocate at once: the readers check counts
/// against the file size, so a few dozen bytes per input byte, plus slack.
fn mesh_allocation_bound(input_len: usize) -> usize {
    64 * input_len + (1 << 16)
}

// ---------------------------------------------------------------------------
// Seeds.
// ---------------------------------------------------------------------------

/// Byte offset, width and kind of each NIfTI-1 header field worth breaking.
#[derive(Clone, Copy, Debug)]
enum NiftiField {
    I16(usize),
    I32(usize),
    F32(usize),
}

const NIFTI_FIELDS: &[NiftiField] = &[
    NiftiField::I32(0), // sizeof_hdr
    NiftiField::I16(40),
    NiftiField::I16(42),
    NiftiField::I16(44),
    NiftiField::I16(46),
    NiftiField::I16(48), // dim[4]
    NiftiField::I16(50),
    NiftiField::I16(70), // datatype
    NiftiField::I16(72), // bitpix
    NiftiField::F32(76), // pixdim[0] = qfac
    NiftiField::F32(80),
    NiftiField::F32(84),
    NiftiField::F32(88),
    NiftiField::F32(108), // vox_offset
    NiftiField::F32(112), // scl_slope
    NiftiField::F32(116), // scl_inter
    NiftiField::I16(252), // qform_code
    NiftiField::I16(254), // sform_code
    NiftiField::F32(256), // quatern_b
    NiftiField::F32(260),
    NiftiField::F32(264),
    NiftiField::F32(268), // qoffset_x
    NiftiField::F32(280), // srow_x
    NiftiField::F32(284),
    NiftiField::F32(296), // srow_y
    NiftiField::F32(312), // srow_z
    NiftiField::F32(324),
];

const HOSTILE_INTS: &[i64] = &[
    0,
    -1,
    1,
    2,
    3,
    7,
    8,
    16,
    64,
    255,
    1000,
    1024,
    32767,
    -32768,
    65535,
    1_000_000,
    1_000_000_000,
    i32::MAX as i64,
    i32::MIN as i64,
];

const HOSTILE_FLOATS: &[f32] = &[
    0.0,
    -0.0,
    -1.0,
    1e-30,
    1e30,
    f32::MAX,
    f32::MIN,
    f32::NAN,
    f32::INFINITY,
    f32::NEG_INFINITY,
    f32::MIN_POSITIVE,
    352.0,
    348.0,
    1e9,
    0.5,
];

/// Hostile replacements for a number in a text header.
const HOSTILE_TOKENS: &[&str] = &[
    "0",
    "-1",
    "1",
    "2",
    "-0",
    "1000000000",
    "4294967296",
    "2147483648",
    "18446744073709551616",
    "99999999999999999999999",
    "1e308",
    "-1e308",
    "1e400",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "0.0",
    "1e-320",
    "3.5",
    "0x10",
    "",
    " ",
    "1 2 3 4 5 6 7 8 9 10 11 12",
    "(nan,nan,nan)",
    "none",
];

/// One fuzz input: the file the reader is pointed at, and its sidecars.
#[derive(Clone, Debug)]
struct Seed {
    /// File name read (its extension picks the reader).
    name: &'static str,
    bytes: Vec<u8>,
    /// Other files the header may name (detached data, `.ele`).
    sidecars: Vec<(&'static str, Vec<u8>)>,
}

fn seed(name: &'static str, bytes: impl Into<Vec<u8>>) -> Seed {
    Seed {
        name,
        bytes: bytes.into(),
        sidecars: vec![],
    }
}

fn gunzip(data: &[u8]) -> Vec<u8> {
    use std::io::Read;
    let mut out = Vec::new();
    let _ = flate2::read::MultiGzDecoder::new(data)
        .take(1 << 16)
        .read_to_end(&mut out);
    out
}

fn gzip(data: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    e.write_all(data).unwrap();
    e.finish().unwrap()
}

fn put_i16(b: &mut [u8], at: usize, v: i16, big: bool) {
    let bytes = if big {
        v.to_be_bytes()
    } else {
        v.to_le_bytes()
    };
    b[at..at + 2].copy_from_slice(&bytes);
}

/// NIfTI seeds: voxflex's own writer, and every real file's header.
fn nifti_seeds() -> Vec<Seed> {
    let mut seeds = vec![];
    // Written by voxflex: a 5 × 4 × 3 int16 volume with a real geometry.
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("own.nii");
    let grid = voxflex_core::grid::Grid::new(
        [5, 4, 3],
        voxflex_core::glam::DVec3::new(0.8, 1.0, 2.5),
        voxflex_core::glam::DVec3::new(-10.0, 4.0, 30.0),
    );
    let vol = voxflex_core::volume::Volume::new(
        grid,
        voxflex_core::volume::VoxelData::I16((0..60).map(|i| i * 37 - 900).collect()),
    )
    .unwrap();
    io::nifti::write_nifti(&p, vol.view()).unwrap();
    seeds.push(seed("own.nii", std::fs::read(&p).unwrap()));
    // Real headers (the body replaced by a small one that fits).
    let data = voxflex_core::test_data::dir().unwrap_or_default();
    for f in [
        "ct_skull_64.nii.gz",
        "mri_t1_small.nii.gz",
        "mri_colin27_t1.nii.gz",
    ] {
        let Ok(gz) = std::fs::read(data.join(f)) else {
            continue;
        };
        let raw = gunzip(&gz);
        if raw.len() < 352 {
            continue;
        }
        let big = i32::from_le_bytes(raw[0..4].try_into().unwrap()) != 348;
        let vox_offset = {
            let b: [u8; 4] = raw[108..112].try_into().unwrap();
            let v = if big {
                f32::from_be_bytes(b)
            } else {
                f32::from_le_bytes(b)
            };
            (v as usize).clamp(348, 1024).min(raw.len())
        };
        let bitpix = i16::from_le_bytes([raw[72], raw[73]]).max(8) as usize;
        // The real header, untouched, with its body cut off.
        seeds.push(seed("real-cut.nii", raw[..vox_offset + 64].to_vec()));
        // The real header with dims 4 × 3 × 2 and a body that fits.
        let mut hdr = raw[..vox_offset].to_vec();
        for (i, d) in [3i16, 4, 3, 2, 1].iter().enumerate() {
            put_i16(&mut hdr, 40 + 2 * i, *d, big);
        }
        let body: Vec<u8> = (0..24 * bitpix / 8).map(|i| (i * 7) as u8).collect();
        hdr.extend_from_slice(&body);
        seeds.push(seed("real.nii", hdr));
    }
    seeds
}

const NRRD_HDR: &str = "NRRD0004\n# Complete NRRD file format specification at:\n\
# http://teem.sourceforge.net/nrrd/format.html\ntype: short\n\
dimension: 3\nspace: left-posterior-superior\nsizes: 3 2 2\n\
space directions: (0.5,0,0) (0,1,0) (0,0,2.5)\nkinds: domain domain domain\nendian: little\n\
encoding: raw\nspace origin: (-1.5,2,30)\nkey:=value\n\n";

fn nrrd_seeds() -> Vec<Seed> {
    let body: Vec<u8> = (0..12i16)
        .flat_map(|v| (v * 100 - 500).to_le_bytes())
        .collect();
    let mut attached = NRRD_HDR.as_bytes().to_vec();
    attached.extend_from_slice(&body);
    let mut gz = NRRD_HDR
        .replace("encoding: raw", "encoding: gzip")
        .into_bytes();
    gz.extend_from_slice(&gzip(&body));
    let detached = NRRD_HDR.replace("key:=value\n", "data file: vol.raw\n");
    vec![
        seed("a.nrrd", attached),
        seed("g.nrrd", gz),
        seed(
            "a.nrrd",
            "NRRD0004\ntype: int\ndimension: 3\nsizes: 2 2 1\nspacings: 1 2 3\n\
             encoding: ascii\n\n1 -2\n3 400000\n",
        ),
        seed(
            "a.nrrd",
            "NRRD0005\ntype: unsigned short\ndimension: 2\nsizes: 2 2\nendian: big\n\
             encoding: raw\n\n\x00\x01\x00\x02\x00\x03\x00\x04",
        ),
        Seed {
            name: "d.nhdr",
            bytes: detached.into_bytes(),
            sidecars: vec![("vol.raw", body)],
        },
    ]
}

const MHA_HDR: &str = "ObjectType = Image\nNDims = 3\nBinaryData = True\n\
BinaryDataByteOrderMSB = False\nCompressedData = False\n\
TransformMatrix = 1 0 0 0 1 0 0 0 1\nOffset = -1.5 2 30\n\
ElementSpacing = 0.5 1 2.5\nDimSize = 3 2 2\nElementType = MET_SHORT\n\
ElementDataFile = LOCAL\n";

fn metaimage_seeds() -> Vec<Seed> {
    let body: Vec<u8> = (0..12i16)
        .flat_map(|v| (v * 100 - 500).to_le_bytes())
        .collect();
    let mut local = MHA_HDR.as_bytes().to_vec();
    local.extend_from_slice(&body);
    let mut compressed = MHA_HDR
        .replace("CompressedData = False", "CompressedData = True")
        .into_bytes();
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
    z.write_all(&body).unwrap();
    compressed.extend_from_slice(&z.finish().unwrap());
    vec![
        seed("a.mha", local),
        seed("c.mha", compressed),
        Seed {
            name: "d.mhd",
            bytes: MHA_HDR
                .replace("LOCAL", "vol.raw")
                .replace("MET_SHORT", "MET_FLOAT")
                .into_bytes(),
            sidecars: vec![(
                "vol.raw",
                (0..12)
                    .flat_map(|v| (v as f32 * 0.5).to_le_bytes())
                    .collect(),
            )],
        },
    ]
}

const MSH: &str = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$PhysicalNames\n1\n3 1 \"tissue\"\n\
$EndPhysicalNames\n$Nodes\n2 5 1 50\n0 1 0 1\n10\n0 0 0\n3 2 0 4\n20\n30\n40\n50\n1 0 0\n\
0 1 0\n0 0 1\n1 1 1\n$EndNodes\n$Elements\n3 4 1 4\n2 5 2 1\n1 20 30 40\n3 7 4 2\n\
2 10 20 30 40\n3 20 30 40 50\n3 9 4 1\n4 10 20 30 50\n$EndElements\n";

fn msh_seeds() -> Vec<Seed> {
    vec![seed("m.msh", MSH)]
}

const NODE: &str =
    "# a cube corner and its neighbour\n5 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 1 1 1\n";
const ELE: &str = "2 4 1\n1 1 2 3 4 7\n2 2 3 4 5 9\n";

fn tetgen_seeds() -> Vec<Seed> {
    vec![
        Seed {
            name: "m.1.node",
            bytes: NODE.into(),
            sidecars: vec![("m.1.ele", ELE.into())],
        },
        Seed {
            name: "m.1.ele",
            bytes: ELE.into(),
            sidecars: vec![("m.1.node", NODE.into())],
        },
    ]
}

// ---------------------------------------------------------------------------
// Mutations.
// ---------------------------------------------------------------------------

/// One change to an input. Positions are taken modulo the input's length.
#[derive(Clone, Debug)]
enum Mutation {
    Flip(usize, u8),
    Set(usize, u8),
    Truncate(usize),
    Insert(usize, Vec<u8>),
    /// Replace the n-th number token (text) by a hostile one.
    Token(usize, usize),
    /// Overwrite a NIfTI header field (binary) by a hostile value.
    Field(usize, usize),
    /// Duplicate the n-th line (a duplicated key).
    DuplicateLine(usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        1 => (any::<usize>(), 1..=255u8).prop_map(|(i, x)| Mutation::Flip(i, x)),
        1 => (any::<usize>(), any::<u8>()).prop_map(|(i, x)| Mutation::Set(i, x)),
        1 => any::<usize>().prop_map(Mutation::Truncate),
        1 => (any::<usize>(), prop::collection::vec(any::<u8>(), 1..12))
            .prop_map(|(i, b)| Mutation::Insert(i, b)),
        3 => (any::<usize>(), any::<usize>()).prop_map(|(i, t)| Mutation::Token(i, t)),
        3 => (any::<usize>(), any::<usize>()).prop_map(|(f, v)| Mutation::Field(f, v)),
        1 => any::<usize>().prop_map(Mutation::DuplicateLine),
    ]
}

/// Byte ranges of the number-like tokens of a text.
fn number_tokens(b: &[u8]) -> Vec<(usize, usize)> {
    let mut out = vec![];
    let mut i = 0;
    while i < b.len() {
        if b[i].is_ascii_digit() {
            let s = i;
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b"+-.".contains(&b[i])) {
                i += 1;
            }
            let s = if s > 0 && b[s - 1] == b'-' { s - 1 } else { s };
            out.push((s, i));
        } else {
            i += 1;
        }
    }
    out
}

fn apply(bytes: &mut Vec<u8>, m: &Mutation, nifti: bool) {
    let n = bytes.len();
    match *m {
        Mutation::Flip(i, x) if n > 0 => bytes[i % n] ^= x,
        Mutation::Set(i, x) if n > 0 => bytes[i % n] = x,
        Mutation::Truncate(i) => bytes.truncate(i % (n + 1)),
        Mutation::Insert(i, ref b) => {
            let at = i % (n + 1);
            bytes.splice(at..at, b.iter().copied());
        }
        Mutation::Field(f, v) if nifti => {
            let big = n >= 4 && i32::from_le_bytes(bytes[0..4].try_into().unwrap()) != 348;
            let (at, val): (usize, Vec<u8>) = match NIFTI_FIELDS[f % NIFTI_FIELDS.len()] {
                NiftiField::I16(at) => {
                    let x = HOSTILE_INTS[v % HOSTILE_INTS.len()] as i16;
                    (
                        at,
                        if big {
                            x.to_be_bytes()
                        } else {
                            x.to_le_bytes()
                        }
                        .into(),
                    )
                }
                NiftiField::I32(at) => {
                    let x = HOSTILE_INTS[v % HOSTILE_INTS.len()] as i32;
                    (
                        at,
                        if big {
                            x.to_be_bytes()
                        } else {
                            x.to_le_bytes()
                        }
                        .into(),
                    )
                }
                NiftiField::F32(at) => {
                    let x = HOSTILE_FLOATS[v % HOSTILE_FLOATS.len()];
                    (
                        at,
                        if big {
                            x.to_be_bytes()
                        } else {
                            x.to_le_bytes()
                        }
                        .into(),
                    )
                }
            };
            if at + val.len() <= n {
                bytes[at..at + val.len()].copy_from_slice(&val);
            }
        }
        Mutation::Token(t, v) | Mutation::Field(t, v) => {
            let tokens = number_tokens(bytes);
            if !tokens.is_empty() {
                let (s, e) = tokens[t % tokens.len()];
                let r = HOSTILE_TOKENS[v % HOSTILE_TOKENS.len()].as_bytes();
                bytes.splice(s..e, r.iter().copied());
            }
        }
        Mutation::DuplicateLine(l) => {
            let starts: Vec<usize> = std::iter::once(0)
                .chain(
                    bytes
                        .iter()
                        .enumerate()
                        .filter(|(_, c)| **c == b'\n')
                        .map(|(i, _)| i + 1),
                )
                .filter(|&i| i < n)
                .collect();
            if !starts.is_empty() {
                let s = starts[l % starts.len()];
                let e = bytes[s..]
                    .iter()
                    .position(|&c| c == b'\n')
                    .map_or(n, |p| s + p + 1);
                let line = bytes[s..e].to_vec();
                bytes.splice(s..s, line);
            }
        }
        _ => {}
    }
}

/// A fuzz case: which seed, the mutations, and (NIfTI, NRRD) whether the
/// result is gzipped and the stream then damaged.
#[derive(Clone, Debug)]
struct Case {
    seed: usize,
    mutations: Vec<Mutation>,
    gzip: bool,
    after_gzip: Option<Mutation>,
    /// Mutate a sidecar instead of the main file.
    sidecar: bool,
}

fn case() -> impl Strategy<Value = Case> {
    (
        any::<usize>(),
        prop::collection::vec(mutation(), 1..=4),
        any::<bool>(),
        prop::option::weighted(0.3, mutation()),
        prop::bool::weighted(0.15),
    )
        .prop_map(|(seed, mutations, gzip, after_gzip, sidecar)| Case {
            seed,
            mutations,
            gzip,
            after_gzip,
            sidecar,
        })
}

/// Writes a case's files into `dir`; returns the path to read.
fn materialise(dir: &Path, seeds: &[Seed], c: &Case, nifti: bool) -> (PathBuf, usize) {
    let s = &seeds[c.seed % seeds.len()];
    let mut main = s.bytes.clone();
    let mut sidecars = s.sidecars.clone();
    let target = match (c.sidecar, sidecars.first_mut()) {
        (true, Some((_, b))) => b,
        _ => &mut main,
    };
    for m in &c.mutations {
        apply(target, m, nifti && !c.sidecar);
    }
    let mut name = s.name.to_string();
    if nifti && c.gzip {
        main = gzip(&main);
        name.push_str(".gz");
        if let Some(m) = &c.after_gzip {
            apply(&mut main, m, false);
        }
    }
    for (n, b) in &sidecars {
        std::fs::write(dir.join(n), b).unwrap();
    }
    let p = dir.join(name);
    std::fs::write(&p, &main).unwrap();
    let len = main.len() + sidecars.iter().map(|(_, b)| b.len()).sum::<usize>();
    (p, len)
}

/// Checks one error: a single, non-empty line.
fn one_line(e: &voxflex_core::error::IoError) -> Result<(), TestCaseError> {
    let m = e.to_string();
    prop_assert!(!m.trim().is_empty(), "empty error message");
    prop_assert!(!m.contains('\n'), "error spans several lines: {m}");
    Ok(())
}

/// Which reader a fuzz target drives.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Target {
    Nifti,
    Nrrd,
    MetaImage,
    Msh,
    TetGen,
}

impl Target {
    fn seeds(self) -> Vec<Seed> {
        match self {
            Target::Nifti => nifti_seeds(),
            Target::Nrrd => nrrd_seeds(),
            Target::MetaImage => metaimage_seeds(),
            Target::Msh => msh_seeds(),
            Target::TetGen => tetgen_seeds(),
        }
    }
}

/// Reads `p` with the target's reader and checks the outcome and the
/// allocations.
fn check(
    target: Target,
    p: &Path,
    input_len: usize,
    read_ok: &Cell<u32>,
) -> Result<(), TestCaseError> {
    let opts = ReadOptions {
        max_voxels: MAX_VOXELS,
        ..Default::default()
    };
    match target {
        Target::Nifti | Target::Nrrd | Target::MetaImage => {
            let (r, largest) = largest_allocation(|| io::read_volume(p, &opts));
            let bound = volume_allocation_bound(input_len);
            prop_assert!(
                largest <= bound,
                "an allocation of {largest} bytes (bound {bound}) for a {input_len}-byte input"
            );
            match r {
                Ok(v) => {
                    read_ok.set(read_ok.get() + 1);
                    prop_assert!(v.grid.len() <= MAX_VOXELS);
                    prop_assert_eq!(v.data.as_slice().len(), v.grid.len());
                }
                Err(e) => one_line(&e)?,
            }
        }
        Target::Msh | Target::TetGen => {
            let (r, largest) = largest_allocation(|| {
                if target == Target::Msh {
                    io::msh::read_msh(p)
                } else {
                    io::tetgen::read_tetgen(p)
                }
            });
            let bound = mesh_allocation_bound(input_len);
            prop_assert!(
                largest <= bound,
                "an allocation of {largest} bytes (bound {bound}) for a {input_len}-byte input"
            );
            match r {
                Ok(m) => {
                    read_ok.set(read_ok.get() + 1);
                    prop_assert_eq!(m.tets.len(), m.labels.len());
                    let n = m.nodes.len() as u32;
                    prop_assert!(m.tets.iter().flatten().all(|&i| i < n));
                    prop_assert!(m.nodes.iter().all(|p| p.is_finite()));
                }
                Err(e) => one_line(&e)?,
            }
        }
    }
    Ok(())
}

/// Cases for one target: `VOXFLEX_FUZZ_CASES`, else `default`.
fn cases(default: u32) -> u32 {
    std::env::var("VOXFLEX_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// The RNG seed: `VOXFLEX_FUZZ_SEED`, else a fixed one (the same cases
/// every run of `cargo test`).
fn rng_seed() -> u64 {
    std::env::var("VOXFLEX_FUZZ_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(13)
}

/// Runs `n` cases against one reader; panics with the minimal failing
/// input. Returns the cases run.
fn fuzz(target: Target, n: u32) -> u32 {
    let seeds = target.seeds();
    assert!(!seeds.is_empty());
    let dir = tempfile::tempdir().unwrap();
    let mut key = [0u8; 32];
    key[..8].copy_from_slice(&rng_seed().to_le_bytes());
    key[8] = target as u8;
    let mut runner = TestRunner::new_with_rng(
        Config {
            cases: n,
            failure_persistence: None,
            max_shrink_iters: 2000,
            ..Config::default()
        },
        TestRng::from_seed(RngAlgorithm::ChaCha, &key),
    );
    let nifti = target == Target::Nifti;
    let read_ok = Cell::new(0u32);
    let result = runner.run(&case(), |c| {
        let (p, len) = materialise(dir.path(), &seeds, &c, nifti);
        check(target, &p, len, &read_ok)
    });
    if let Err(e) = result {
        panic!("{target:?} reader: {e}");
    }
    // A fuzzer whose every case fails at the first byte tests nothing.
    let ok = read_ok.get();
    eprintln!("{target:?}: {n} cases, {ok} read, {} refused", n - ok);
    assert!(
        n < 100 || (ok > n / 50 && ok < n - n / 50),
        "{target:?}: {ok} of {n} cases read: the mutations are too mild or too harsh"
    );
    n
}

#[test]
fn fuzz_nifti() {
    fuzz(Target::Nifti, cases(3000));
}

#[test]
fn fuzz_nrrd() {
    fuzz(Target::Nrrd, cases(2400));
}

#[test]
fn fuzz_metaimage() {
    fuzz(Target::MetaImage, cases(2400));
}

#[test]
fn fuzz_msh() {
    fuzz(Target::Msh, cases(1300));
}

#[test]
fn fuzz_tetgen() {
    fuzz(Target::TetGen, cases(1300));
}

/// The long run: `VOXFLEX_FUZZ_CASES` (default 200,000) cases per reader.
#[test]
#[ignore = "long: run with --release -- --ignored"]
fn fuzz_long() {
    let per = cases(200_000);
    let t = std::time::Instant::now();
    let mut total = 0u64;
    for target in [
        Target::Nifti,
        Target::Nrrd,
        Target::MetaImage,
        Target::Msh,
        Target::TetGen,
    ] {
        let t0 = std::time::Instant::now();
        total += u64::from(fuzz(target, per));
        println!(
            "{target:?}: {per} cases in {:.1} s",
            t0.elapsed().as_secs_f64()
        );
    }
    println!(
        "fuzz_long: {total} cases, seed {}, {:.1} s, no failure",
        rng_seed(),
        t.elapsed().as_secs_f64()
    );
}

// ---------------------------------------------------------------------------
// Hostile headers, by hand.
// ---------------------------------------------------------------------------

/// A header asking for 10⁹ × 10⁹ × 10⁹ voxels is refused before anything
/// that size is allocated, in every volume format.
#[test]
fn giga_dims_are_refused_without_allocating() {
    let dir = tempfile::tempdir().unwrap();
    let opts = ReadOptions::default();
    let nrrd = NRRD_HDR.replace("sizes: 3 2 2", "sizes: 1000000000 1000000000 1000000000");
    let mha = MHA_HDR.replace(
        "DimSize = 3 2 2",
        "DimSize = 1000000000 1000000000 1000000000",
    );
    let mut nii = nifti_seeds()[0].bytes.clone();
    for a in 0..3 {
        put_i16(&mut nii, 42 + 2 * a, i16::MAX, false);
    }
    for (name, bytes) in [
        ("g.nrrd", nrrd.into_bytes()),
        ("g.mha", mha.into_bytes()),
        ("g.nii", nii),
    ] {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        let (r, largest) = largest_allocation(|| io::read_volume(&p, &opts));
        let e = r.expect_err(name).to_string();
        assert!(e.contains("dim") || e.contains("size"), "{name}: {e}");
        assert!(largest < 4 << 20, "{name}: allocated {largest} bytes");
    }
}

/// The accounting the fuzzers rely on sees a large allocation, and refuses
/// one above the hard cap (so the bound checks above can fail).
#[test]
fn the_counting_allocator_records_and_caps() {
    let (v, largest) = largest_allocation(|| vec![1u8; 10 << 20]);
    assert_eq!(v.len(), 10 << 20);
    assert!(largest >= 10 << 20, "recorded {largest}");
    let (r, largest) = largest_allocation(|| {
        let mut v: Vec<u8> = Vec::new();
        v.try_reserve_exact(HARD_CAP + 1).map(|_| v.capacity())
    });
    assert!(r.is_err(), "an allocation above the cap went through");
    assert!(largest > HARD_CAP);
    assert!(volume_allocation_bound(0) < 10 << 20);
}
