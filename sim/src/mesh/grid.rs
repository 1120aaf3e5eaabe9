//! A uniform grid of points for ball queries: the spatial index of the localised step (which
//! particles lie near the scalpel). Cells are cubes of a fixed side, kept in a sorted list of
//! `(cell, point)` pairs, so a query visits only the cells its ball overlaps and the result
//! comes out in ascending point order (deterministic).

use crate::Point3;

/// Points binned in cubic cells of side `cell_m`.
#[derive(Debug, Clone, Default)]
pub struct PointGrid {
    cell_m: f64,
    /// `(cell key, point id)`, sorted.
    entries: Vec<(u64, u32)>,
    /// The positions the points had when binned.
    binned: Vec<Point3>,
}

/// Cell coordinates are offset by this so that they stay positive in a `u64` key (21 bits
/// per axis: a million cells on each side).
const OFFSET: i64 = 1 << 20;

fn key(c: [i64; 3]) -> u64 {
    let [x, y, z] = c.map(|v| (v + OFFSET).clamp(0, (1 << 21) - 1) as u64);
    (x << 42) | (y << 21) | z
}

impl PointGrid {
    /// Bins `points` in cells of side `cell_m` (> 0).
    pub fn build(points: &[Point3], cell_m: f64) -> Self {
        let mut grid = Self {
            cell_m,
            entries: Vec::new(),
            binned: points.to_vec(),
        };
        let mut entries: Vec<(u64, u32)> = points
            .iter()
            .enumerate()
            .map(|(i, p)| (key(grid.cell_of(p)), i as u32))
            .collect();
        entries.sort_unstable();
        grid.entries = entries;
        grid
    }

    /// Bins the points of `points` from [`Self::len`] on (those added since), where they are
    /// now; the others keep their binned positions.
    pub fn extend(&mut self, points: &[Point3]) {
        let from = self.binned.len();
        if points.len() <= from {
            return;
        }
        self.binned.extend_from_slice(&points[from..]);
        let mut added: Vec<(u64, u32)> = (from..points.len())
            .map(|i| (key(self.cell_of(&points[i])), i as u32))
            .collect();
        added.sort_unstable();
        let old = std::mem::take(&mut self.entries);
        let mut merged = Vec::with_capacity(old.len() + added.len());
        let mut rest = old.as_slice();
        for a in added {
            let at = rest.partition_point(|e| *e < a);
            merged.extend_from_slice(&rest[..at]);
            merged.push(a);
            rest = &rest[at..];
        }
        merged.extend_from_slice(rest);
        self.entries = merged;
    }

    /// Side of a cell, m.
    pub fn cell_m(&self) -> f64 {
        self.cell_m
    }

    /// Number of points binned.
    pub fn len(&self) -> usize {
        self.binned.len()
    }

    /// Whether no point was binned.
    pub fn is_empty(&self) -> bool {
        self.binned.is_empty()
    }

    /// Where point `i` was when binned.
    pub fn binned_position(&self, i: usize) -> Point3 {
        self.binned[i]
    }

    fn cell_of(&self, p: &Point3) -> [i64; 3] {
        [p.x, p.y, p.z].map(|c| {
            let q = (c / self.cell_m).floor();
            if q.is_finite() {
                q.clamp(-(OFFSET as f64), OFFSET as f64) as i64
            } else {
                0
            }
        })
    }

    /// Calls `visit(i)` for every point whose binned position lies within `radius_m` of
    /// `centre`, in ascending order of `i` within each cell and by cell key across cells.
    pub fn for_each_within(&self, centre: &Point3, radius_m: f64, mut visit: impl FnMut(u32)) {
        if !(radius_m >= 0.0) || !centre.iter().all(|c| c.is_finite()) {
            return;
        }
        let lo = self.cell_of(&(centre - crate::Vector3::repeat(radius_m)));
        let hi = self.cell_of(&(centre + crate::Vector3::repeat(radius_m)));
        let r2 = radius_m * radius_m;
        for x in lo[0]..=hi[0] {
            for y in lo[1]..=hi[1] {
                // the cells of one (x, y) column are consecutive keys: one range per column
                let (from, to) = (key([x, y, lo[2]]), key([x, y, hi[2]]));
                let start = self.entries.partition_point(|e| e.0 < from);
                for &(k, i) in &self.entries[start..] {
                    if k > to {
                        break;
                    }
                    if (self.binned[i as usize] - centre).norm_squared() <= r2 {
                        visit(i);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ball_query_finds_exactly_the_points_within_the_radius() {
        // a jittered lattice, negative coordinates included
        let points: Vec<Point3> = (0..2000)
            .map(|i| {
                let f = i as f64;
                Point3::new(
                    (f * 0.618).sin() * 0.05,
                    (f * 0.377).cos() * 0.04 - 0.01,
                    (f * 0.131).sin() * 0.02,
                )
            })
            .collect();
        let grid = PointGrid::build(&points, 0.007);
        for (centre, r) in [
            (Point3::origin(), 0.01),
            (Point3::new(-0.03, 0.02, 0.0), 0.025),
            (Point3::new(1.0, 1.0, 1.0), 0.1),
        ] {
            let mut found = Vec::new();
            grid.for_each_within(&centre, r, |i| found.push(i));
            found.sort_unstable();
            let expected: Vec<u32> = (0..points.len() as u32)
                .filter(|&i| (points[i as usize] - centre).norm() <= r)
                .collect();
            assert_eq!(found, expected);
        }
        let mut none = 0;
        grid.for_each_within(&Point3::new(f64::NAN, 0.0, 0.0), 1.0, |_| none += 1);
        assert_eq!(none, 0);
    }

    #[test]
    fn extending_a_grid_bins_the_new_points_as_building_it_anew_would() {
        let points: Vec<Point3> = (0..3000)
            .map(|i| {
                Point3::new(
                    (i as f64 * 0.618).sin() * 0.05,
                    (i as f64 * 0.377).cos() * 0.04,
                    (i as f64 * 0.131).sin() * 0.02,
                )
            })
            .collect();
        let mut grid = PointGrid::build(&points[..2000], 0.006);
        grid.extend(&points[..1500]); // nothing new: unchanged
        assert_eq!(grid.len(), 2000);
        grid.extend(&points);
        let built = PointGrid::build(&points, 0.006);
        assert_eq!(grid.entries, built.entries);
        assert_eq!(grid.binned, built.binned);
    }
}
