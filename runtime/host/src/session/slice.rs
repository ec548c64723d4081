//! [`SliceImage`]: one slice of the session's volume as an 8-bit image,
//! one pixel per voxel, oriented as `voxflex_io::png` documents, with
//! the mapping between pixels and world millimetres (for clicks).

use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_core::opacity_map::OpacityMap;
use voxflex_io::png::{GrayImage, SliceAxis};

/// A rendered slice and where its pixels lie.
#[derive(Clone, Debug, PartialEq)]
pub struct SliceImage {
    /// The gray pixels (one per voxel of the slice), top row first.
    pub image: GrayImage,
    /// The axis the slice is across.
    pub axis: SliceAxis,
    /// The slice's voxel index along `axis`.
    pub index: usize,
    /// The grid of the volume it was cut from (world mm).
    pub grid: Grid,
}

impl SliceImage {
    /// The voxel index (i, j, k) shown at pixel (`column`, `row`); `None`
    /// outside the image.
    pub fn pixel_to_voxel(&self, column: usize, row: usize) -> Option<[usize; 3]> {
        if column >= self.image.width || row >= self.image.height {
            return None;
        }
        let nz = self.grid.dims[2];
        Some(match self.axis {
            SliceAxis::Axial => [column, row, self.index],
            SliceAxis::Coronal => [column, self.index, nz - 1 - row],
            SliceAxis::Sagittal => [self.index, column, nz - 1 - row],
        })
    }

    /// The world point (mm) at the centre of pixel (`column`, `row`):
    /// where a click on the image lands; `None` outside the image.
    pub fn pixel_to_world(&self, column: usize, row: usize) -> Option<DVec3> {
        let [i, j, k] = self.pixel_to_voxel(column, row)?;
        Some(
            self.grid
                .index_to_world(DVec3::new(i as f64, j as f64, k as f64)),
        )
    }

    /// The pixel (`column`, `row`) showing the voxel nearest world point
    /// `p` (mm), when that voxel lies on this slice; `None` otherwise.
    pub fn world_to_pixel(&self, p: DVec3) -> Option<[usize; 2]> {
        let f = self.grid.world_to_index(p).round();
        let v = [f.x, f.y, f.z];
        if v.iter()
            .zip(self.grid.dims)
            .any(|(&x, d)| !(x >= 0.0 && x < d as f64))
        {
            return None;
        }
        let [i, j, k] = v.map(|x| x as usize);
        let nz = self.grid.dims[2];
        let (index, pixel) = match self.axis {
            SliceAxis::Axial => (k, [i, j]),
            SliceAxis::Coronal => (j, [i, nz - 1 - k]),
            SliceAxis::Sagittal => (i, [j, nz - 1 - k]),
        };
        (index == self.index).then_some(pixel)
    }

    /// The opacity (in [0, 1]) of ROI map `map` at every pixel of this
    /// slice, row-major, top row first (`map.outside` off its box): a
    /// map drawn over the slice. `map` must be a map of this slice's grid.
    pub fn overlay(&self, map: &OpacityMap) -> Vec<f32> {
        let (w, h) = (self.image.width, self.image.height);
        let mut out = Vec::with_capacity(w * h);
        for row in 0..h {
            for column in 0..w {
                let o = self
                    .pixel_to_voxel(column, row)
                    .map_or(0.0, |[i, j, k]| map.get(i, j, k));
                out.push(o);
            }
        }
        out
    }

    /// The world point (mm) at continuous pixel coordinates (`column`,
    /// `row`), pixel centres at whole numbers, anywhere in the slice's
    /// plane (inside the image or not): where a drag in the view lands.
    pub fn point_to_world(&self, column: f64, row: f64) -> DVec3 {
        let top = (self.grid.dims[2] as f64 - 1.0) - row;
        let index = self.index as f64;
        let f = match self.axis {
            SliceAxis::Axial => DVec3::new(column, row, index),
            SliceAxis::Coronal => DVec3::new(column, index, top),
            SliceAxis::Sagittal => DVec3::new(index, column, top),
        };
        self.grid.index_to_world(f)
    }

    /// The continuous pixel coordinates `[column, row]` of world point `p`
    /// (mm) projected onto the slice's plane; the inverse of
    /// [`Self::point_to_world`] (a crosshair through `p`).
    pub fn world_to_point(&self, p: DVec3) -> [f64; 2] {
        let f = self.grid.world_to_index(p);
        let top = self.grid.dims[2] as f64 - 1.0;
        match self.axis {
            SliceAxis::Axial => [f.x, f.y],
            SliceAxis::Coronal => [f.x, top - f.z],
            SliceAxis::Sagittal => [f.y, top - f.z],
        }
    }

    /// The size of one pixel, mm, as `[width, height]` (the voxel spacing
    /// along the image's column and row axes): draw the slice in these
    /// proportions to show it in true millimetres.
    pub fn pixel_mm(&self) -> [f64; 2] {
        let s = self.grid.spacing;
        match self.axis {
            SliceAxis::Axial => [s.x, s.y],
            SliceAxis::Coronal => [s.x, s.z],
            SliceAxis::Sagittal => [s.y, s.z],
        }
    }
}
