//! The labelled abdominal contrast-CT phantom (`phantom:abdomen`): an upper
//! abdomen in the portal-venous phase, Hounsfield units (i16) **and** an
//! organ label per voxel ([`abdomen_labelled`]), for measuring region
//! growing against ground truth.
//!
//! Field of view 360 × 280 × 240 mm (x patient-left, y posterior, z
//! superior, LPS; centred on the world origin). Structures (world mm) and
//! their values, portal-venous phase (~70 s after injection); sources in the
//! "On contrast CT" section of docs/GUIDE.md:
//!
//! | label | structure | HU |
//! |---|---|---|
//! | [`label::AIR`] | outside the body, gas in the stomach | −1000 |
//! | [`label::FAT`] | subcutaneous and visceral fat | −100 / −90 |
//! | [`label::MUSCLE`] | body wall, paraspinal muscles, diaphragm | 55 |
//! | [`label::BONE`] | vertebral body (cancellous 350, cortex 800) | 350 / 800 |
//! | [`label::LUNG`] | lung bases above the diaphragm | −850 |
//! | [`label::LIVER`] | liver parenchyma (right upper quadrant) | 115 |
//! | [`label::SPLEEN`] | spleen (left upper quadrant) | 125 |
//! | [`label::KIDNEY_R`], [`label::KIDNEY_L`] | kidneys (nephrographic): cortex 180, medulla 165 | 180 / 165 |
//! | [`label::AORTA`] | abdominal aorta | 210 |
//! | [`label::IVC`] | inferior vena cava | 160 |
//! | [`label::PORTAL`] | portal vein, its intrahepatic branches, splenic vein | 185 |
//! | [`label::PANCREAS`] | pancreas, head at the portal vein to tail at the splenic hilum | 100 |
//! | [`label::STOMACH`] | stomach: wall 90, fluid content 15, gas cap −1000 | 90 / 15 |
//! | [`label::BOWEL`] | small-bowel loops: wall 90, fluid 20 | 90 / 20 |
//! | [`label::GALLBLADDER`] | gallbladder (bile) | 10 |
//!
//! Organs touch as in a patient: the liver lies against the right kidney,
//! the IVC, the stomach, the gallbladder, the body wall and the diaphragm;
//! the spleen against the left kidney, the pancreatic tail and the body
//! wall; the portal vein runs from the pancreas (via the splenic
//! vein) into the liver, where it branches.
//!
//! **Image formation.** Each voxel takes the value of the structure at its
//! centre (edges are sharp: no partial-volume blur, so every voxel has the
//! label it shows and the leak paths are the organs' contacts, not
//! partial-volume shells — a bright vessel blurred into fat passes through
//! liver values), then Gaussian noise with a spatial correlation of about
//! one voxel is added: white noise (deterministic, seeded by
//! [`NOISE_SEED`] and the voxel index) blurred by a separable
//! `[1, 2, 1] / 4` kernel along each axis and scaled to a standard
//! deviation of [`NOISE_SIGMA_HU`] (15 HU). The result is rounded to i16.
//! Deterministic: the same dims always give the same voxels.

use super::{Ellipsoid, PhantomKind, fill};
use crate::grid::Grid;
use crate::volume::{Volume, VoxelData};
use glam::DVec3;
use rayon::prelude::*;

/// Physical size of the abdomen phantom (mm) along x, y, z.
pub const ABDOMEN_SIZE_MM: DVec3 = DVec3::new(360.0, 280.0, 240.0);

/// Standard deviation of the added noise (HU), after its smoothing.
pub const NOISE_SIGMA_HU: f64 = 15.0;

/// Seed of the noise generator.
pub const NOISE_SEED: u64 = 0x5EED_AB0D;

/// Organ labels of [`abdomen_labelled`] (u8 per voxel).
pub mod label {
    /// Outside the body, and gas in the stomach.
    pub const AIR: u8 = 0;
    /// Subcutaneous and visceral fat.
    pub const FAT: u8 = 1;
    /// Body-wall and paraspinal muscle, diaphragm.
    pub const MUSCLE: u8 = 2;
    /// Vertebral body.
    pub const BONE: u8 = 3;
    /// Lung bases.
    pub const LUNG: u8 = 4;
    /// Liver parenchyma.
    pub const LIVER: u8 = 5;
    /// Spleen.
    pub const SPLEEN: u8 = 6;
    /// Right kidney (cortex and medulla).
    pub const KIDNEY_R: u8 = 7;
    /// Left kidney (cortex and medulla).
    pub const KIDNEY_L: u8 = 8;
    /// Aorta.
    pub const AORTA: u8 = 9;
    /// Inferior vena cava.
    pub const IVC: u8 = 10;
    /// Portal vein, intrahepatic portal branches, splenic vein.
    pub const PORTAL: u8 = 11;
    /// Pancreas.
    pub const PANCREAS: u8 = 12;
    /// Stomach (wall and content).
    pub const STOMACH: u8 = 13;
    /// Small-bowel loops (wall and content).
    pub const BOWEL: u8 = 14;
    /// Gallbladder.
    pub const GALLBLADDER: u8 = 15;
    /// Names, indexed by label.
    pub const NAMES: [&str; 16] = [
        "air",
        "fat",
        "muscle",
        "bone",
        "lung",
        "liver",
        "spleen",
        "right kidney",
        "left kidney",
        "aorta",
        "ivc",
        "portal",
        "pancreas",
        "stomach",
        "bowel",
        "gallbladder",
    ];
}

/// Seed points (world mm) well inside three organs, away from vessels:
/// `(name, label, point)`.
pub const SEEDS: [(&str, u8, DVec3); 3] = [
    ("liver", label::LIVER, DVec3::new(-95.0, -10.0, 30.0)),
    ("spleen", label::SPLEEN, DVec3::new(95.0, 40.0, 45.0)),
    ("kidney", label::KIDNEY_R, DVec3::new(-70.0, 70.0, -45.0)),
];

/// The abdomen phantom with its labels.
#[derive(Clone, Debug)]
pub struct LabelledVolume {
    /// Hounsfield units (i16).
    pub volume: Volume,
    /// One label per voxel (same grid and order as `volume`), see [`label`].
    pub labels: Vec<u8>,
}

impl LabelledVolume {
    /// Voxels carrying `label`.
    pub fn count(&self, label: u8) -> usize {
        self.labels.iter().filter(|&&l| l == label).count()
    }
}

/// A finite cylinder (segment `a`–`b`, radius `r`, mm).
#[derive(Clone, Copy)]
struct Tube {
    a: DVec3,
    b: DVec3,
    r: f64,
}

impl Tube {
    const fn new(a: DVec3, b: DVec3, r: f64) -> Self {
        Self { a, b, r }
    }
    fn contains(&self, p: DVec3) -> bool {
        let ab = self.b - self.a;
        let t = ((p - self.a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0);
        (p - (self.a + t * ab)).length_squared() <= self.r * self.r
    }
}

/// An elliptic cylinder along z (centre and semi-axes in x, y, mm).
#[derive(Clone, Copy)]
struct Column {
    cx: f64,
    cy: f64,
    ax: f64,
    ay: f64,
}

impl Column {
    fn contains(&self, p: DVec3) -> bool {
        let (u, v) = ((p.x - self.cx) / self.ax, (p.y - self.cy) / self.ay);
        u * u + v * v <= 1.0
    }
    fn shrunk(&self, t: f64) -> Self {
        Self {
            ax: self.ax - t,
            ay: self.ay - t,
            ..*self
        }
    }
}

const fn v3(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z)
}

/// Label and noiseless HU of the object at world point `p` (mm).
fn object(p: DVec3) -> (u8, f32) {
    use label::*;
    let body = Column {
        cx: 0.0,
        cy: 0.0,
        ax: 170.0,
        ay: 125.0,
    };
    if !body.contains(p) {
        return (AIR, -1000.0);
    }
    if !body.shrunk(4.0).contains(p) {
        return (MUSCLE, 55.0); // skin
    }
    if !body.shrunk(20.0).contains(p) {
        return (FAT, -100.0);
    }
    if !body.shrunk(32.0).contains(p) {
        return (MUSCLE, 55.0); // abdominal wall
    }
    // Spine and paraspinal muscles, posterior midline.
    let vertebra = Column {
        cx: 0.0,
        cy: 62.0,
        ax: 22.0,
        ay: 20.0,
    };
    if vertebra.contains(p) {
        return (
            BONE,
            if vertebra.shrunk(3.0).contains(p) {
                350.0
            } else {
                800.0
            },
        );
    }
    for cx in [-42.0, 42.0] {
        let m = Column {
            cx,
            cy: 72.0,
            ax: 22.0,
            ay: 20.0,
        };
        if m.contains(p) {
            return (MUSCLE, 55.0);
        }
    }
    // Lung bases above a domed diaphragm (5 mm of muscle).
    for cx in [-85.0, 85.0] {
        let lung = Ellipsoid::new(v3(cx, 15.0, 185.0), v3(80.0, 85.0, 90.0));
        let diaphragm = Ellipsoid::new(lung.centre, lung.semi + DVec3::splat(5.0));
        if lung.contains(p) {
            return (LUNG, -850.0);
        }
        if diaphragm.contains(p) {
            return (MUSCLE, 55.0);
        }
    }
    // Great vessels along z.
    if (Column {
        cx: 18.0,
        cy: 32.0,
        ax: 12.0,
        ay: 12.0,
    })
    .contains(p)
    {
        return (AORTA, 210.0);
    }
    if (Column {
        cx: -26.0,
        cy: 28.0,
        ax: 14.0,
        ay: 12.0,
    })
    .contains(p)
        && p.z < 110.0
    {
        return (IVC, 160.0);
    }
    // Kidneys: cortex 6 mm over medulla.
    for (lab, cx, cz) in [(KIDNEY_R, -70.0, -45.0), (KIDNEY_L, 72.0, -30.0)] {
        let k = Ellipsoid::new(v3(cx, 70.0, cz), v3(30.0, 24.0, 55.0));
        if k.contains(p) {
            return (
                lab,
                if k.shrunk(6.0).contains(p) {
                    165.0
                } else {
                    180.0
                },
            );
        }
    }
    // Portal system: trunk from the pancreatic neck into the liver hilum,
    // intrahepatic branches, splenic vein to the splenic hilum.
    const PORTAL_TUBES: [Tube; 6] = [
        Tube::new(v3(8.0, 5.0, -20.0), v3(-45.0, 10.0, 15.0), 7.0),
        Tube::new(v3(-45.0, 10.0, 15.0), v3(-90.0, 15.0, 45.0), 4.5),
        Tube::new(v3(-45.0, 10.0, 15.0), v3(-70.0, -40.0, 40.0), 4.5),
        Tube::new(v3(-90.0, 15.0, 45.0), v3(-130.0, 20.0, 60.0), 3.0),
        Tube::new(v3(-70.0, -40.0, 40.0), v3(-60.0, -75.0, 55.0), 3.0),
        Tube::new(v3(8.0, 5.0, -20.0), v3(88.0, 32.0, 15.0), 5.0),
    ];
    if PORTAL_TUBES.iter().any(|t| t.contains(p)) {
        return (PORTAL, 185.0);
    }
    // Gallbladder under the liver.
    if Ellipsoid::new(v3(-45.0, -55.0, -20.0), v3(16.0, 18.0, 30.0)).contains(p) {
        return (GALLBLADDER, 10.0);
    }
    // Stomach (left upper quadrant, anterior): wall 4 mm, gas cap anterior.
    let stomach = Ellipsoid::new(v3(45.0, -30.0, 40.0), v3(50.0, 38.0, 50.0));
    if stomach.contains(p) {
        let inner = stomach.shrunk(4.0);
        return if !inner.contains(p) {
            (STOMACH, 90.0)
        } else if p.y < -45.0 && p.z > 45.0 {
            (AIR, -1000.0)
        } else {
            (STOMACH, 15.0)
        };
    }
    // Spleen, posterior left, against the diaphragm and the left kidney.
    if Ellipsoid::new(v3(95.0, 40.0, 40.0), v3(28.0, 38.0, 55.0)).contains(p) {
        return (SPLEEN, 125.0);
    }
    // Pancreas along the splenic vein, from the portal confluence to the
    // splenic hilum.
    if (Tube::new(v3(8.0, -5.0, -25.0), v3(85.0, 28.0, 10.0), 13.0)).contains(p) {
        return (PANCREAS, 100.0);
    }
    // Liver: right upper quadrant, dome under the diaphragm, left lobe
    // across the midline in front of the stomach.
    let liver = Ellipsoid::new(v3(-70.0, 0.0, 40.0), v3(90.0, 85.0, 80.0));
    let left_lobe = Ellipsoid::new(v3(0.0, -55.0, 55.0), v3(45.0, 30.0, 40.0));
    if (liver.contains(p) || left_lobe.contains(p)) && body.shrunk(32.0).contains(p) {
        return (LIVER, 115.0);
    }
    // Small-bowel loops in the lower abdomen.
    for (cx, cy) in [(-60.0, -40.0), (0.0, -60.0), (60.0, -40.0), (30.0, 0.0)] {
        let loop_ = Ellipsoid::new(v3(cx, cy, -80.0), v3(22.0, 22.0, 30.0));
        if loop_.contains(p) {
            return (
                BOWEL,
                if loop_.shrunk(3.0).contains(p) {
                    20.0
                } else {
                    90.0
                },
            );
        }
    }
    (FAT, -90.0)
}

/// SplitMix64: one well-mixed 64-bit hash per input.
fn splitmix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A standard normal deviate for voxel `l` (Box–Muller on two hashes).
fn gauss(l: usize) -> f64 {
    let h1 = splitmix(NOISE_SEED ^ (l as u64).wrapping_mul(2));
    let h2 = splitmix(NOISE_SEED ^ (l as u64).wrapping_mul(2).wrapping_add(1));
    let u1 = ((h1 >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    let u2 = (h2 >> 11) as f64 / (1u64 << 53) as f64;
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// `[1, 2, 1] / 4` along each axis in turn (edges clamped), in place.
fn blur121(data: &mut [f32], dims: [usize; 3]) {
    let [nx, ny, _] = dims;
    let stride = [1, nx, nx * ny];
    for a in 0..3 {
        let n = dims[a];
        if n < 2 {
            continue;
        }
        let src = data.to_vec();
        data.par_chunks_mut((nx * ny).max(1))
            .enumerate()
            .for_each(|(k, slab)| {
                for (o, v) in slab.iter_mut().enumerate() {
                    let c = [o % nx, o / nx, k][a];
                    let l = o + k * nx * ny;
                    let lo = if c > 0 { l - stride[a] } else { l };
                    let hi = if c + 1 < n { l + stride[a] } else { l };
                    *v = 0.25 * src[lo] + 0.5 * src[l] + 0.25 * src[hi];
                }
            });
    }
}

/// Standard deviation of white noise after [`blur121`] on every axis, per
/// unit input σ: `(6/16)^(3/2)` (each pass keeps `(1 + 4 + 1)/16` of the
/// variance), ignoring edges.
const BLUR_NOISE_GAIN: f64 = 0.229_639_16;

/// The abdomen phantom (i16 HU) and its labels at `dims` voxels (spacing
/// `360 × 280 × 240 mm / dims`). See the module docs.
///
/// `dims` are not checked here; [`super::phantom`] refuses empty or
/// oversized dims.
pub fn abdomen_labelled(dims: [usize; 3]) -> LabelledVolume {
    let grid: Grid = PhantomKind::Abdomen.grid(dims);
    let both = fill(&grid, |p| {
        let (l, v) = object(p);
        (l, v)
    });
    let labels: Vec<u8> = both.iter().map(|&(l, _)| l).collect();
    let clean: Vec<f32> = both.iter().map(|&(_, v)| v).collect();
    drop(both);
    let mut noise: Vec<f32> = (0..grid.len())
        .into_par_iter()
        .map(|l| (gauss(l) * NOISE_SIGMA_HU / BLUR_NOISE_GAIN) as f32)
        .collect();
    blur121(&mut noise, dims);
    let data: Vec<i16> = clean
        .par_iter()
        .zip(&noise)
        .map(|(&c, &n)| (c + n).round().clamp(-1024.0, 3071.0) as i16)
        .collect();
    LabelledVolume {
        volume: Volume {
            grid,
            data: VoxelData::I16(data),
        },
        labels,
    }
}

/// The abdomen phantom's values only (see [`abdomen_labelled`]).
pub fn abdomen(dims: [usize; 3]) -> Volume {
    abdomen_labelled(dims).volume
}

/// Dice coefficient `2|A ∩ B| / (|A| + |B|)` of the voxels where `a` holds
/// and where `labels == label` (1 when both are empty).
pub fn dice(a: impl IntoIterator<Item = bool>, labels: &[u8], label: u8) -> f64 {
    let (mut both, mut na, mut nb) = (0usize, 0usize, 0usize);
    for (x, &l) in a.into_iter().zip(labels) {
        let y = l == label;
        na += x as usize;
        nb += y as usize;
        both += (x && y) as usize;
    }
    if na + nb == 0 {
        1.0
    } else {
        2.0 * both as f64 / (na + nb) as f64
    }
}

/// [`dice`] of an ROI opacity map's `opacity ≥ 0.5` (voxels beyond its box
/// at its `outside` value) against `labels == label`, over a volume of
/// `dims` voxels (x fastest, like `labels`).
pub fn map_dice(
    map: &crate::opacity_map::OpacityMap,
    dims: [usize; 3],
    labels: &[u8],
    label: u8,
) -> f64 {
    let half = crate::opacity_map::to_fixed(0.5);
    dice(
        map.dense(dims).into_iter().map(|q| q >= half),
        labels,
        label,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn organs_sit_where_documented_and_touch() {
        let ph = abdomen_labelled([90, 70, 60]);
        let g = ph.volume.grid;
        assert_eq!(g.spacing, DVec3::splat(4.0));
        let at = |p: DVec3| {
            let i = g.world_to_index(p).round();
            ph.labels[g.linear(i.x as usize, i.y as usize, i.z as usize)]
        };
        for (name, l, p) in SEEDS {
            assert_eq!(at(p), l, "{name} seed");
        }
        assert_eq!(at(v3(0.0, 62.0, 0.0)), label::BONE);
        assert_eq!(at(v3(18.0, 32.0, -60.0)), label::AORTA);
        assert_eq!(at(v3(0.0, 0.0, 115.0)), label::FAT);
        assert_eq!(at(v3(-85.0, 15.0, 110.0)), label::LUNG);
        assert_eq!(at(v3(176.0, 0.0, 0.0)), label::AIR);
        // Contacts: some liver voxel has a kidney / IVC / stomach / muscle /
        // portal neighbour; some spleen voxel a kidney / pancreas / muscle one.
        let touching = |a: u8, b: u8| {
            let [nx, ny, _] = g.dims;
            (0..g.len()).any(|l| {
                ph.labels[l] == a
                    && [1, nx, nx * ny].iter().any(|&s| {
                        ph.labels.get(l + s) == Some(&b) || (l >= s && ph.labels[l - s] == b)
                    })
            })
        };
        for b in [
            label::KIDNEY_R,
            label::IVC,
            label::STOMACH,
            label::MUSCLE,
            label::PORTAL,
        ] {
            assert!(
                touching(label::LIVER, b),
                "liver–{}",
                label::NAMES[b as usize]
            );
        }
        for b in [label::KIDNEY_L, label::PANCREAS, label::MUSCLE] {
            assert!(
                touching(label::SPLEEN, b),
                "spleen–{}",
                label::NAMES[b as usize]
            );
        }
        assert!(touching(label::PANCREAS, label::PORTAL));
    }

    #[test]
    fn noise_has_the_stated_sigma_and_organs_their_means() {
        let ph = abdomen_labelled([90, 70, 60]);
        let v = ph.volume.view().data.to_f32_vec();
        // Interior voxels of the liver: all 6 neighbours liver too (no blur).
        let g = ph.volume.grid;
        let [nx, ny, _] = g.dims;
        let interior = |l: usize, lab: u8| {
            l > nx * ny
                && l + nx * ny < g.len()
                && [1, nx, nx * ny]
                    .iter()
                    .all(|&s| ph.labels[l + s] == lab && ph.labels[l - s] == lab)
        };
        for (lab, hu) in [(label::LIVER, 115.0), (label::SPLEEN, 125.0)] {
            let xs: Vec<f64> = (0..g.len())
                .filter(|&l| ph.labels[l] == lab && interior(l, lab))
                .map(|l| v[l] as f64)
                .collect();
            assert!(xs.len() > 500, "{}", xs.len());
            let m = xs.iter().sum::<f64>() / xs.len() as f64;
            let s = (xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / xs.len() as f64).sqrt();
            assert!((m - hu).abs() < 1.5, "mean {m} vs {hu}");
            assert!((s - NOISE_SIGMA_HU).abs() < 1.5, "σ {s}");
        }
        // Deterministic.
        assert_eq!(abdomen([20, 16, 12]).data, abdomen([20, 16, 12]).data);
    }

    #[test]
    fn dice_counts() {
        let labels = [1u8, 1, 0, 0];
        assert_eq!(dice([true, true, false, false], &labels, 1), 1.0);
        assert_eq!(dice([true, false, true, false], &labels, 1), 0.5);
        assert_eq!(dice([false; 4], &labels, 7), 1.0);
    }
}
