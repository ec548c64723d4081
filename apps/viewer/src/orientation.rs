//! LPS orientation labels of the slice views: which patient direction
//! each image edge faces (world +x left, +y posterior, +z superior).

use voxflex_runtime::session::SliceAxis;

/// The labels at the (left, right, top, bottom) edges of a slice across
/// `axis`, as `voxflex_io::png` orients it: axial +x to the right and +y
/// down; coronal +x right, +z up; sagittal +y right, +z up.
pub fn edge_labels(axis: SliceAxis) -> [&'static str; 4] {
    match axis {
        SliceAxis::Axial => ["R", "L", "A", "P"],
        SliceAxis::Coronal => ["R", "L", "S", "I"],
        SliceAxis::Sagittal => ["A", "P", "S", "I"],
    }
}

/// The view's title.
pub fn axis_name(axis: SliceAxis) -> &'static str {
    match axis {
        SliceAxis::Axial => "Axial",
        SliceAxis::Coronal => "Coronal",
        SliceAxis::Sagittal => "Sagittal",
    }
}

/// The world axis (0 = x, 1 = y, 2 = z) a slice across `axis` fixes.
pub fn normal_axis(axis: SliceAxis) -> usize {
    match axis {
        SliceAxis::Axial => 2,
        SliceAxis::Coronal => 1,
        SliceAxis::Sagittal => 0,
    }
}
