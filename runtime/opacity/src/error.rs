//! [`OpacityError`]: what can go wrong when growing an opacity map. Every
//! message names the value at fault and says what to do.

use voxflex_core::error::GpuError;

/// An opacity-map request was refused or a GPU call failed. Nothing is
/// half-done: a refused request leaves the growth as it was.
#[derive(Debug, Clone, thiserror::Error)]
pub enum OpacityError {
    /// The volume has no voxel.
    #[error("the volume is empty (dims {dims:?}); load a volume before seeding an opacity map")]
    EmptyVolume {
        /// Volume dimensions.
        dims: [usize; 3],
    },
    /// The volume has more voxels than the 32-bit indices of the growth can
    /// name.
    #[error(
        "the volume has {voxels} voxels (dims {dims:?}), more than the 2³² the opacity growth \
         can index; crop or downsample the volume"
    )]
    VolumeTooLarge {
        /// Volume dimensions.
        dims: [usize; 3],
        /// Voxels.
        voxels: u64,
    },
    /// A volume view whose value count differs from its grid's voxel count.
    #[error("the volume has {actual} values but its dims {dims:?} need {expected}")]
    DataLength {
        /// Grid dimensions.
        dims: [usize; 3],
        /// Values the grid needs.
        expected: usize,
        /// Values supplied.
        actual: usize,
    },
    /// A volume of another size than the one the growth was seeded in.
    #[error(
        "the growth was seeded in a volume of dims {expected:?} but is stepped with one of dims \
         {actual:?}; pass the same volume to every call"
    )]
    VolumeMismatch {
        /// Dimensions at seeding time.
        expected: [usize; 3],
        /// Dimensions passed now.
        actual: [usize; 3],
    },
    /// A seed coordinate is NaN or infinite.
    #[error("seed {seed} is not finite; pass a point inside the volume")]
    SeedNotFinite {
        /// The seed as given.
        seed: String,
    },
    /// The seed lies outside the volume.
    #[error("seed {seed} lies outside the volume: {detail}")]
    SeedOutside {
        /// The seed as given.
        seed: String,
        /// Which coordinate is out of range and the valid range.
        detail: String,
    },
    /// The seed's neighbourhood holds NaN or infinite values, so its mean and
    /// standard deviation are undefined.
    #[error(
        "the neighbourhood of seed voxel {voxel:?} holds non-finite values (mean {mean}, standard \
         deviation {std}); seed on finite data"
    )]
    SeedStatsNotFinite {
        /// Seed voxel index.
        voxel: [usize; 3],
        /// Mean of the neighbourhood.
        mean: f64,
        /// Standard deviation of the neighbourhood.
        std: f64,
    },
    /// `lambda` is not a positive finite number.
    #[error("lambda = {lambda} must be a positive finite number (the paper's default is 30)")]
    BadLambda {
        /// The value given.
        lambda: f32,
    },
    /// `o_min`/`o_max` are outside [0, 1], non-finite, or not `o_min < o_max`
    /// after rounding to the map's 1/65535 steps.
    #[error(
        "opacity range o_min = {o_min}, o_max = {o_max} is invalid: both must lie in [0, 1] and \
         o_min < o_max by at least 1/65535 (defaults 0.03 and 1)"
    )]
    BadOpacityRange {
        /// The `o_min` given.
        o_min: f32,
        /// The `o_max` given.
        o_max: f32,
    },
    /// `connectivity` is neither 6 nor 26.
    #[error(
        "connectivity = {connectivity} must be 6 (faces) or 26 (faces, edges and corners; the paper's)"
    )]
    BadConnectivity {
        /// The value given.
        connectivity: u32,
    },
    /// `seed_radius` is outside 1 ..= [`crate::MAX_SEED_RADIUS`].
    #[error(
        "seed_radius = {seed_radius} must be between 1 (the paper's 1-ring) and {max} voxels (default 2)",
        max = crate::MAX_SEED_RADIUS
    )]
    BadSeedRadius {
        /// The value given.
        seed_radius: u32,
    },
    /// `sigma_floor` is not a positive finite number.
    #[error("sigma_floor = {sigma_floor} must be a positive finite number (default 1e-3)")]
    BadSigmaFloor {
        /// The value given.
        sigma_floor: f32,
    },
    /// `λ·σ_s` is so small that the extinction scale `65535 / (λ σ_s)`
    /// overflows f32.
    #[error(
        "lambda·sigma = {lambda}·{sigma} is too small: the extinction scale overflows; raise \
         lambda or sigma_floor"
    )]
    ExtinctionOverflow {
        /// λ.
        lambda: f32,
        /// σ_s as used (after the floor).
        sigma: f32,
    },
    /// A map was asked of a path-cost scan at a λ it did not run to the end.
    #[error(
        "lambda = {lambda} is not a candidate the automatic lambda's scan ran to the end \
         ({scanned} phases run); the automatic lambda takes one of 1, 1.41, 2, … 32 \
         (powers of sqrt 2): set lambda = \"auto\" again, or give lambda as a number"
    )]
    LambdaNotScanned {
        /// λ asked for.
        lambda: f32,
        /// Phases the scan ran.
        scanned: usize,
    },
    /// A GPU buffer would exceed the device's largest buffer.
    #[error(
        "{what} needs {bytes} bytes in one GPU buffer but the GPU allows {limit}; use the CPU \
         path or crop the volume"
    )]
    BufferTooLarge {
        /// The buffer at fault.
        what: &'static str,
        /// Bytes needed.
        bytes: u64,
        /// The device limit, bytes.
        limit: u64,
    },
    /// A GPU buffer would exceed the device's storage-binding limit.
    #[error(
        "{what} needs {bytes} bytes in one storage binding but the GPU allows {limit}; use the \
         CPU path, bound the region (`intensity`, `max_distance_mm`) or crop the volume"
    )]
    BindingTooLarge {
        /// The buffer at fault.
        what: &'static str,
        /// Bytes needed.
        bytes: u64,
        /// The device limit, bytes.
        limit: u64,
    },
    /// A [`crate::gpu::GpuOpacityVolume`] of another grid than the
    /// growth's.
    #[error(
        "the GPU volume has dims {actual:?} but the growth was seeded in dims {expected:?}; \
         upload the same volume"
    )]
    GpuVolumeMismatch {
        /// Dimensions at seeding time.
        expected: [usize; 3],
        /// Dimensions of the GPU volume.
        actual: [usize; 3],
    },
    /// `intensity = [lo, hi]` is not two finite values with `lo ≤ hi`.
    #[error(
        "intensity = [{lo}, {hi}] must be two finite values (the volume's units) with lo ≤ hi; \
         voxels outside the window never rise above o_min"
    )]
    BadIntensityWindow {
        /// Lower bound given.
        lo: f32,
        /// Upper bound given.
        hi: f32,
    },
    /// `max_distance_mm` is not a positive finite number.
    #[error(
        "max_distance_mm = {max_distance_mm} must be a positive finite distance in mm (Euclidean, \
         from the seed voxel's centre)"
    )]
    BadMaxDistance {
        /// The value given.
        max_distance_mm: f64,
    },
    /// The seed voxel's own value lies outside the intensity window.
    #[error(
        "the seed voxel {voxel:?} holds {value}, outside intensity = [{lo}, {hi}]; widen the \
         window or move the seed"
    )]
    SeedOutsideWindow {
        /// Seed voxel index.
        voxel: [usize; 3],
        /// Its value.
        value: f32,
        /// Window lower bound.
        lo: f32,
        /// Window upper bound.
        hi: f32,
    },
    /// A GPU service call failed.
    #[error(transparent)]
    Gpu(#[from] GpuError),
}
