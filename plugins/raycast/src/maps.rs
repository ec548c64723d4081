//! Combining several spatial opacity maps into one.
//!
//! **Decision (paper: "Spatial opacity maps", CEIG 2016):** the opacity
//! factor of a voxel is the **max** over the maps, each map giving its
//! value inside its box and its `outside` value (o_min) elsewhere. The
//! renderer combines the maps once per change into a single map whose box is
//! the union of the boxes clipped to the volume and whose `outside` is the
//! largest `outside` — exactly the voxelwise max, at the cost of one lookup
//! per sample corner whatever the number of maps. Between voxel centres the
//! combined factor is interpolated trilinearly (or taken from the nearest
//! voxel, `opacity_map_interpolation = "nearest"`).

use rayon::prelude::*;
use voxflex_core::error::ModelError;
use voxflex_core::opacity_map::OpacityMap;

/// Checks that every map's values fill its box.
pub fn validate(maps: &[OpacityMap]) -> Result<(), ModelError> {
    for (n, m) in maps.iter().enumerate() {
        let need = m
            .dims
            .iter()
            .try_fold(1usize, |acc, &d| acc.checked_mul(d))
            .ok_or_else(|| ModelError(format!("opacity map {n}: dims {:?} overflow", m.dims)))?;
        if m.values.len() != need {
            return Err(ModelError(format!(
                "opacity map {n}: {} values but its box {:?} needs {need}",
                m.values.len(),
                m.dims
            )));
        }
    }
    Ok(())
}

/// The voxelwise max of `maps` over a volume of `dims` voxels, as one map
/// (`None` when there is no map: every factor is 1).
pub fn combine(maps: &[OpacityMap], dims: [usize; 3]) -> Option<OpacityMap> {
    if maps.is_empty() {
        return None;
    }
    let outside = maps.iter().map(|m| m.outside).max().unwrap_or(0);
    // Union of the non-empty boxes, clipped to the volume.
    let mut lo = [usize::MAX; 3];
    let mut hi = [0usize; 3];
    let mut any = false;
    for m in maps {
        if m.dims.contains(&0) {
            continue;
        }
        let mut inside = true;
        let mut l = [0; 3];
        let mut h = [0; 3];
        for a in 0..3 {
            l[a] = m.origin[a];
            h[a] = m.origin[a].saturating_add(m.dims[a]).min(dims[a]);
            if l[a] >= h[a] {
                inside = false;
            }
        }
        if inside {
            any = true;
            for a in 0..3 {
                lo[a] = lo[a].min(l[a]);
                hi[a] = hi[a].max(h[a]);
            }
        }
    }
    if !any {
        return Some(OpacityMap {
            origin: [0; 3],
            dims: [0; 3],
            outside,
            values: Vec::new(),
        });
    }
    let size = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    let mut values = vec![0u16; size[0] * size[1] * size[2]];
    values
        .par_chunks_mut(size[0] * size[1])
        .enumerate()
        .for_each(|(z, plane)| {
            let k = lo[2] + z;
            for y in 0..size[1] {
                let j = lo[1] + y;
                for x in 0..size[0] {
                    let i = lo[0] + x;
                    let mut q = 0u16;
                    for m in maps {
                        let (a, b, c) = (
                            i.wrapping_sub(m.origin[0]),
                            j.wrapping_sub(m.origin[1]),
                            k.wrapping_sub(m.origin[2]),
                        );
                        let v = if a < m.dims[0] && b < m.dims[1] && c < m.dims[2] {
                            m.values[a + m.dims[0] * (b + m.dims[1] * c)]
                        } else {
                            m.outside
                        };
                        q = q.max(v);
                    }
                    plane[x + size[0] * y] = q;
                }
            }
        });
    Some(OpacityMap {
        origin: lo,
        dims: size,
        outside,
        values,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxflex_core::opacity_map::to_fixed;

    fn boxed(origin: [usize; 3], dims: [usize; 3], inside: f32, outside: f32) -> OpacityMap {
        OpacityMap {
            origin,
            dims,
            outside: to_fixed(outside),
            values: vec![to_fixed(inside); dims.iter().product()],
        }
    }

    #[test]
    fn combination_is_the_voxelwise_max() {
        let dims = [12, 10, 9];
        let maps = [
            boxed([1, 1, 1], [4, 4, 4], 0.2, 0.1),
            boxed([3, 2, 2], [20, 3, 3], 0.7, 0.0),
        ];
        let c = combine(&maps, dims).unwrap();
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let want = maps[0].get(i, j, k).max(maps[1].get(i, j, k));
                    assert_eq!(c.get(i, j, k), want, "{i} {j} {k}");
                }
            }
        }
        // The box is clipped to the volume.
        assert_eq!(c.origin, [1, 1, 1]);
        assert_eq!(c.dims, [11, 4, 4]);
    }

    #[test]
    fn no_maps_and_empty_boxes() {
        assert!(combine(&[], [4, 4, 4]).is_none());
        let c = combine(&[boxed([9, 9, 9], [2, 2, 2], 1.0, 0.25)], [4, 4, 4]).unwrap();
        assert_eq!(c.dims, [0; 3]);
        assert!((c.get(0, 0, 0) - 0.25).abs() < 1e-4);
    }

    #[test]
    fn validation_checks_lengths() {
        let mut m = boxed([0; 3], [2, 2, 2], 1.0, 0.0);
        assert!(validate(std::slice::from_ref(&m)).is_ok());
        m.values.pop();
        assert!(validate(&[m]).unwrap_err().0.contains("opacity map 0"));
    }
}
