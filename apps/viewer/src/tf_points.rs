//! The transfer function as the editor holds it: control points
//! (value → sRGB colour + opacity) kept sorted by value, their editing
//! (move, add, delete) and the mapping between values / opacities and
//! the editor's screen rectangle. No window needed: unit-tested below.

/// One control point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TfPoint {
    /// Data value (volume units, e.g. HU).
    pub value: f64,
    /// sRGB colour, 0–255.
    pub colour: [u8; 3],
    /// Opacity of a slab `opacity_unit_distance` thick (the raycast
    /// plugin's alpha), 0–1.
    pub opacity: f64,
}

impl TfPoint {
    /// The `[value, r, g, b, a]` row of the plugin's `points` (colour 0–1).
    pub fn row(&self) -> [f64; 5] {
        let c = |i: usize| f64::from(self.colour[i]) / 255.0;
        [self.value, c(0), c(1), c(2), self.opacity]
    }

    /// A point from a `[value, r, g, b, a]` row (colour 0–1); `None` when
    /// the row is not 5 finite numbers.
    pub fn from_row(row: &[f64]) -> Option<Self> {
        if row.len() != 5 || row.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let c = |v: f64| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
        Some(Self {
            value: row[0],
            colour: [c(row[1]), c(row[2]), c(row[3])],
            opacity: row[4].clamp(0.0, 1.0),
        })
    }
}

/// Control points sorted by value (equal values allowed: a step).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TfPoints {
    points: Vec<TfPoint>,
}

/// Fewest points the editor keeps (a delete below it is ignored).
pub const MIN_POINTS: usize = 2;

impl TfPoints {
    /// The points `points` sorted by value.
    pub fn new(mut points: Vec<TfPoint>) -> Self {
        points.sort_by(|a, b| a.value.total_cmp(&b.value));
        Self { points }
    }

    /// The points, by value.
    pub fn points(&self) -> &[TfPoint] {
        &self.points
    }

    /// A ramp over `[lo, hi]` (volume units): transparent black at `lo`,
    /// then warm and faint, light and half opaque, white and mostly
    /// opaque at `hi` — where "Custom" starts.
    pub fn ramp(lo: f64, hi: f64) -> Self {
        let at = |f: f64| lo + f * (hi - lo);
        Self::new(vec![
            TfPoint {
                value: lo,
                colour: [0, 0, 0],
                opacity: 0.0,
            },
            TfPoint {
                value: at(0.4),
                colour: [200, 120, 90],
                opacity: 0.0,
            },
            TfPoint {
                value: at(0.7),
                colour: [240, 220, 190],
                opacity: 0.3,
            },
            TfPoint {
                value: hi,
                colour: [255, 255, 255],
                opacity: 0.8,
            },
        ])
    }

    /// Moves point `i` to `value` and `opacity` (clamped to 0–1); the value
    /// is clamped between its neighbours' so the order holds and a drag
    /// never swaps points. Returns the index (unchanged), or `None` when
    /// there is no point `i`.
    pub fn move_point(&mut self, i: usize, value: f64, opacity: f64) -> Option<usize> {
        if i >= self.points.len() {
            return None;
        }
        let lo = i
            .checked_sub(1)
            .map_or(f64::NEG_INFINITY, |j| self.points[j].value);
        let hi = self.points.get(i + 1).map_or(f64::INFINITY, |p| p.value);
        let p = self.points.get_mut(i)?;
        p.value = value.clamp(lo, hi);
        p.opacity = opacity.clamp(0.0, 1.0);
        Some(i)
    }

    /// Adds a point at `value` with `opacity`, coloured as the function is
    /// there (interpolated between its neighbours); returns its index.
    pub fn add(&mut self, value: f64, opacity: f64) -> usize {
        let colour = self.colour_at(value);
        let i = self.points.partition_point(|p| p.value <= value);
        self.points.insert(
            i,
            TfPoint {
                value,
                colour,
                opacity: opacity.clamp(0.0, 1.0),
            },
        );
        i
    }

    /// Deletes point `i`, unless only [`MIN_POINTS`] are left; true when
    /// deleted.
    pub fn delete(&mut self, i: usize) -> bool {
        if self.points.len() <= MIN_POINTS || i >= self.points.len() {
            return false;
        }
        self.points.remove(i);
        true
    }

    /// Sets point `i`'s colour.
    pub fn set_colour(&mut self, i: usize, colour: [u8; 3]) {
        if let Some(p) = self.points.get_mut(i) {
            p.colour = colour;
        }
    }

    /// The sRGB colour the function gives `value` (piecewise linear,
    /// constant beyond the ends, as the plugin interpolates).
    pub fn colour_at(&self, value: f64) -> [u8; 3] {
        let (Some(first), Some(last)) = (self.points.first(), self.points.last()) else {
            return [255, 255, 255];
        };
        if value <= first.value {
            return first.colour;
        }
        if value >= last.value {
            return last.colour;
        }
        let i = self.points.partition_point(|p| p.value <= value);
        let (a, b) = (self.points[i - 1], self.points[i]);
        let t = (value - a.value) / (b.value - a.value).max(f64::MIN_POSITIVE);
        let mix = |c: usize| {
            (f64::from(a.colour[c]) + t * (f64::from(b.colour[c]) - f64::from(a.colour[c]))).round()
                as u8
        };
        [mix(0), mix(1), mix(2)]
    }

    /// The point nearest screen position `pos` within `radius` points, on
    /// `axes`.
    pub fn hit(&self, axes: &TfAxes, pos: [f32; 2], radius: f32) -> Option<usize> {
        self.points
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let [x, y] = axes.to_screen(p.value, p.opacity);
                (i, (x - pos[0]).hypot(y - pos[1]))
            })
            .filter(|(_, d)| *d <= radius)
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i)
    }
}

/// The editor's axes: values `lo..=hi` (volume units) across the screen
/// span `left..=right`, opacity 0 at `bottom` and 1 at `top` (screen
/// points, y down).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TfAxes {
    /// Value at the left edge (volume units).
    pub lo: f64,
    /// Value at the right edge (volume units).
    pub hi: f64,
    /// Left edge, screen points.
    pub left: f32,
    /// Right edge, screen points.
    pub right: f32,
    /// Top edge (opacity 1), screen points.
    pub top: f32,
    /// Bottom edge (opacity 0), screen points.
    pub bottom: f32,
}

impl TfAxes {
    /// Screen x of `value` (beyond the range: beyond the edges).
    pub fn value_to_x(&self, value: f64) -> f32 {
        let span = (self.hi - self.lo).max(f64::MIN_POSITIVE);
        self.left + ((value - self.lo) / span) as f32 * (self.right - self.left)
    }

    /// The value at screen x, clamped to the range.
    pub fn x_to_value(&self, x: f32) -> f64 {
        let f = ((x - self.left) / (self.right - self.left).max(f32::MIN_POSITIVE)).clamp(0.0, 1.0);
        self.lo + f64::from(f) * (self.hi - self.lo)
    }

    /// Screen y of `opacity`.
    pub fn opacity_to_y(&self, opacity: f64) -> f32 {
        self.bottom - opacity.clamp(0.0, 1.0) as f32 * (self.bottom - self.top)
    }

    /// The opacity at screen y, clamped to 0–1.
    pub fn y_to_opacity(&self, y: f32) -> f64 {
        f64::from(
            ((self.bottom - y) / (self.bottom - self.top).max(f32::MIN_POSITIVE)).clamp(0.0, 1.0),
        )
    }

    /// Screen position of (`value`, `opacity`), the value clamped to the
    /// edges (a point beyond the range sits on its edge).
    pub fn to_screen(&self, value: f64, opacity: f64) -> [f32; 2] {
        let x = self.value_to_x(value).clamp(self.left, self.right);
        [x, self.opacity_to_y(opacity)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn axes() -> TfAxes {
        TfAxes {
            lo: -1000.0,
            hi: 1000.0,
            left: 10.0,
            right: 210.0,
            top: 0.0,
            bottom: 100.0,
        }
    }

    fn three() -> TfPoints {
        TfPoints::new(vec![
            TfPoint {
                value: 500.0,
                colour: [255, 255, 255],
                opacity: 1.0,
            },
            TfPoint {
                value: -1000.0,
                colour: [0, 0, 0],
                opacity: 0.0,
            },
            TfPoint {
                value: 0.0,
                colour: [200, 100, 0],
                opacity: 0.5,
            },
        ])
    }

    #[test]
    fn values_and_opacities_map_to_the_screen_and_back() {
        let a = axes();
        assert_eq!(a.value_to_x(-1000.0), 10.0);
        assert_eq!(a.value_to_x(0.0), 110.0);
        assert_eq!(a.x_to_value(210.0), 1000.0);
        assert_eq!(a.x_to_value(500.0), 1000.0, "clamped to the range");
        assert_eq!(a.opacity_to_y(1.0), 0.0);
        assert_eq!(a.y_to_opacity(75.0), 0.25);
        assert_eq!(a.y_to_opacity(-5.0), 1.0);
        for v in [-1000.0, -250.0, 0.0, 730.0] {
            assert!((a.x_to_value(a.value_to_x(v)) - v).abs() < 1e-3, "{v}");
        }
        assert_eq!(
            a.to_screen(3000.0, 0.0),
            [210.0, 100.0],
            "beyond the range: on the edge"
        );
    }

    #[test]
    fn points_stay_sorted_and_a_drag_never_passes_a_neighbour() {
        let mut p = three();
        let values: Vec<f64> = p.points().iter().map(|p| p.value).collect();
        assert_eq!(values, [-1000.0, 0.0, 500.0]);
        p.move_point(1, 900.0, 2.0).unwrap();
        assert_eq!(p.points()[1].value, 500.0, "stopped at the next point");
        assert_eq!(p.points()[1].opacity, 1.0, "opacity clamped");
        p.move_point(1, -200.0, 0.2).unwrap();
        assert_eq!((p.points()[1].value, p.points()[1].opacity), (-200.0, 0.2));
        assert_eq!(p.move_point(7, 0.0, 0.0), None);
    }

    #[test]
    fn an_added_point_takes_the_colour_there_and_deletes_stop_at_two() {
        let mut p = three();
        let i = p.add(-500.0, 0.3);
        assert_eq!(i, 1);
        assert_eq!(p.points()[1].colour, [100, 50, 0], "halfway black → orange");
        assert_eq!(p.points().len(), 4);
        assert!(p.delete(1));
        assert!(p.delete(0));
        assert!(!p.delete(0), "two points are kept");
        assert_eq!(p.points().len(), MIN_POINTS);
        p.set_colour(0, [1, 2, 3]);
        assert_eq!(p.points()[0].colour, [1, 2, 3]);
    }

    #[test]
    fn a_click_hits_the_nearest_point_within_the_radius() {
        let p = three();
        let a = axes();
        let [x, y] = a.to_screen(0.0, 0.5);
        assert_eq!(p.hit(&a, [x + 3.0, y - 2.0], 6.0), Some(1));
        assert_eq!(p.hit(&a, [x + 30.0, y], 6.0), None);
    }

    #[test]
    fn rows_round_trip_and_bad_rows_are_refused() {
        let q = TfPoint {
            value: 40.0,
            colour: [255, 0, 51],
            opacity: 0.25,
        };
        assert_eq!(q.row(), [40.0, 1.0, 0.0, 0.2, 0.25]);
        assert_eq!(TfPoint::from_row(&q.row()), Some(q));
        assert_eq!(TfPoint::from_row(&[1.0, 0.0, 0.0, 0.0]), None);
        assert_eq!(TfPoint::from_row(&[f64::NAN, 0.0, 0.0, 0.0, 0.0]), None);
    }
}
