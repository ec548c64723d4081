//! [`SharedVolume`]: voxel values a host lends a renderer instead of
//! handing over a copy.
//!
//! A renderer keeps the volume it draws between calls. Handed a
//! [`crate::volume::VolumeView`], it must copy it, since the view lives
//! only for the call: for a 512 × 512 × 133 CT that copy is 70 MB of fresh
//! pages, about a fifth of the CPU ray caster's first frame on two cores,
//! and the renderer then holds the volume twice. A volume that will not
//! change (a loaded file, a session's source) can instead be shared: the
//! values stay where the host put them, and whoever holds a clone of the
//! `SharedVolume` keeps them alive.
//!
//! The values are immutable for as long as any clone exists; a host that
//! changes its volume hands over a new one (or a view, which is copied).

use crate::volume::{Volume, VolumeView};
use std::fmt;
use std::sync::Arc;

/// Immutable voxel values and their grid, kept alive by whoever holds a
/// clone (cloning is a reference count, not a copy of the values).
#[derive(Clone)]
pub struct SharedVolume {
    /// The values, borrowed for as long as `owner` lives.
    view: VolumeView<'static>,
    /// Keeps `view`'s values alive and unchanged.
    owner: Arc<dyn Send + Sync>,
}

impl SharedVolume {
    /// Shares `volume` (no copy): its values stay alive while a clone of
    /// the result does.
    pub fn new(volume: Arc<Volume>) -> Self {
        let view = volume.view();
        // SAFETY: the values belong to `volume`, which `owner` keeps alive;
        // a `Volume` behind an `Arc` has no interior mutability, so nobody
        // can change them while it lives.
        let view = unsafe { extend(view) };
        Self {
            view,
            owner: volume,
        }
    }

    /// Values that `owner` keeps alive, e.g. a host's buffer lent across
    /// the plugin boundary with a release callback in `owner`'s `Drop`.
    ///
    /// # Safety
    /// `view`'s values must stay alive and unchanged until `owner` is
    /// dropped (its last clone, from any thread).
    pub unsafe fn from_raw(view: VolumeView<'_>, owner: Arc<dyn Send + Sync>) -> Self {
        Self {
            // SAFETY: guaranteed by the caller.
            view: unsafe { extend(view) },
            owner,
        }
    }

    /// The values and their grid (world millimetres ↔ voxel indices).
    pub fn view(&self) -> VolumeView<'_> {
        self.view
    }

    /// True when `self` and `other` share the same values (one owner).
    pub fn same_values(&self, other: &SharedVolume) -> bool {
        Arc::ptr_eq(&self.owner, &other.owner)
    }
}

impl fmt::Debug for SharedVolume {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("SharedVolume")
            .field("dims", &self.view.grid.dims)
            .field("scalar_type", &self.view.data.scalar_type())
            .finish()
    }
}

/// `view` with its lifetime widened to `'static`.
///
/// # Safety
/// The values must outlive every use of the result.
unsafe fn extend(view: VolumeView<'_>) -> VolumeView<'static> {
    // SAFETY: only the lifetime changes; the caller guarantees it.
    unsafe { std::mem::transmute::<VolumeView<'_>, VolumeView<'static>>(view) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Grid;
    use crate::volume::VoxelData;
    use glam::DVec3;

    fn volume() -> Arc<Volume> {
        let grid = Grid::new([3, 2, 2], DVec3::splat(0.5), DVec3::ZERO);
        let data = VoxelData::I16((0..12).map(|v| v * 100 - 300).collect());
        Arc::new(Volume::new(grid, data).unwrap())
    }

    /// The shared values are the volume's own (not a copy), and outlive
    /// every other handle on them.
    #[test]
    fn shares_the_values_without_copying_and_keeps_them_alive() {
        let v = volume();
        let shared = SharedVolume::new(v.clone());
        assert_eq!(
            shared.view().data.as_bytes().as_ptr(),
            v.view().data.as_bytes().as_ptr()
        );
        assert_eq!(Arc::strong_count(&v), 2);
        let copy = shared.clone();
        assert!(copy.same_values(&shared));
        assert!(!copy.same_values(&SharedVolume::new(volume())));
        drop(shared);
        let want = v.view().data.to_f32_vec();
        drop(v);
        assert_eq!(copy.view().data.to_f32_vec(), want);
        assert_eq!(copy.view().grid.dims, [3, 2, 2]);
    }

    /// A lent buffer's owner is dropped exactly once, with the last clone.
    #[test]
    fn the_owner_goes_with_the_last_clone() {
        struct Release(Arc<std::sync::atomic::AtomicUsize>);
        impl Drop for Release {
            fn drop(&mut self) {
                self.0.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            }
        }
        let released = Arc::new(std::sync::atomic::AtomicUsize::new(0));
        let v = volume();
        // SAFETY: `v` outlives the shared volume below.
        let shared =
            unsafe { SharedVolume::from_raw(v.view(), Arc::new(Release(released.clone()))) };
        let second = shared.clone();
        drop(shared);
        assert_eq!(released.load(std::sync::atomic::Ordering::SeqCst), 0);
        drop(second);
        assert_eq!(released.load(std::sync::atomic::Ordering::SeqCst), 1);
    }
}
