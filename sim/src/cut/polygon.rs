//! The clipping surface C swept by the blade between two poses, as a planar polygon, and the
//! blade itself.

use crate::{Point3, Vector3};

/// A scalpel blade: the cutting edge runs from the tip along `edge_direction` for `depth_m`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Blade {
    /// The tip of the blade, in metres.
    pub tip: Point3,
    /// Unit vector from the tip along the cutting edge (towards the handle).
    pub edge_direction: Vector3,
    /// The length of the cutting edge, in metres.
    pub depth_m: f64,
}

impl Blade {
    /// A blade standing normal to the outer surface of a [`crate::generate::curved_slab`] of
    /// radius `radius_m` (the surface `z = sqrt(r^2 - x^2) - r`), at `x_m` along the slab and
    /// `y_m` across it, its tip `depth_m` below the surface and its edge reaching `above_m`
    /// above it: the demo's incision across the chest wall.
    pub fn normal_to_curved_slab(
        x_m: f64,
        y_m: f64,
        radius_m: f64,
        depth_m: f64,
        above_m: f64,
    ) -> Self {
        let z_top = (radius_m * radius_m - x_m * x_m).sqrt() - radius_m;
        let outward = Vector3::new(x_m, 0.0, z_top + radius_m).normalize();
        let tip = Point3::new(x_m, y_m, z_top) - outward * depth_m;
        super::blade(tip, outward, depth_m + above_m)
    }

    /// The far end of the cutting edge.
    pub fn heel(&self) -> Point3 {
        self.tip + self.edge_direction * self.depth_m
    }

    /// How far `p` is from the cutting edge (the segment from the tip to the heel), m.
    pub fn distance_to_edge(&self, p: &Point3) -> f64 {
        let edge = self.heel() - self.tip;
        let along = (p - self.tip).dot(&edge) / edge.norm_squared().max(f64::MIN_POSITIVE);
        (p - (self.tip + edge * along.clamp(0.0, 1.0))).norm()
    }

    /// True when every number is finite and the depth positive.
    pub fn is_finite(&self) -> bool {
        self.tip
            .iter()
            .chain(self.edge_direction.iter())
            .all(|c| c.is_finite())
            && self.depth_m.is_finite()
            && self.depth_m > 0.0
            && self.edge_direction.norm() > 0.0
    }
}

/// A planar convex or simple polygon C with its plane `n . x = offset` (`n` unit).
#[derive(Debug, Clone, PartialEq)]
pub struct CutPolygon {
    /// The corners in order round the polygon.
    pub corners: Vec<Point3>,
    /// The unit normal `n` of its plane.
    pub normal: Vector3,
    /// The plane's offset: `n . x = offset` on it.
    pub offset: f64,
    /// In-plane basis for point-in-polygon tests.
    u: Vector3,
    v: Vector3,
    corners_2d: Vec<[f64; 2]>,
    /// Length scale (longest side) for tolerances.
    pub scale: f64,
    /// How far the corners given lay from the plane, m: how far the swept surface the
    /// polygon stands for departs from it.
    pub flatness_m: f64,
}

impl CutPolygon {
    /// The polygon through `corners` projected onto their best-fit plane (Newell's normal
    /// through the centroid). None when the corners are non-finite or span no area.
    pub fn new(corners: &[Point3]) -> Option<Self> {
        if corners.len() < 3 || !corners.iter().all(|p| p.iter().all(|c| c.is_finite())) {
            return None;
        }
        let mut normal = Vector3::zeros();
        let mut centroid = Vector3::zeros();
        for (i, a) in corners.iter().enumerate() {
            let b = corners[(i + 1) % corners.len()];
            normal.x += (a.y - b.y) * (a.z + b.z);
            normal.y += (a.z - b.z) * (a.x + b.x);
            normal.z += (a.x - b.x) * (a.y + b.y);
            centroid += a.coords;
        }
        centroid /= corners.len() as f64;
        let scale = (0..corners.len())
            .map(|i| (corners[(i + 1) % corners.len()] - corners[i]).norm())
            .fold(0.0, f64::max);
        let area2 = normal.norm();
        if !(scale > 0.0) || !(area2 > 1e-12 * scale * scale) {
            return None;
        }
        let normal = normal / area2;
        let offset = normal.dot(&centroid);
        let projected: Vec<Point3> = corners
            .iter()
            .map(|p| p - normal * (normal.dot(&p.coords) - offset))
            .collect();
        let flatness_m = corners
            .iter()
            .map(|p| (normal.dot(&p.coords) - offset).abs())
            .fold(0.0, f64::max);
        let u = (projected[1] - projected[0]).normalize();
        let v = normal.cross(&u);
        let corners_2d = projected
            .iter()
            .map(|p| [u.dot(&p.coords), v.dot(&p.coords)])
            .collect();
        Some(Self {
            corners: projected,
            normal,
            offset,
            u,
            v,
            corners_2d,
            scale,
            flatness_m,
        })
    }

    /// Signed distance of `p` from the plane.
    #[inline]
    pub fn signed_distance(&self, p: &Point3) -> f64 {
        self.normal.dot(&p.coords) - self.offset
    }

    /// True when the projection of `p` onto the plane lies inside the polygon or within `tol`
    /// of its boundary.
    pub fn contains_projection(&self, p: &Point3, tol: f64) -> bool {
        let q = [self.u.dot(&p.coords), self.v.dot(&p.coords)];
        let n = self.corners_2d.len();
        // crossing-number test, then a distance test for points close to the boundary
        let mut inside = false;
        for i in 0..n {
            let (a, b) = (self.corners_2d[i], self.corners_2d[(i + 1) % n]);
            if (a[1] > q[1]) != (b[1] > q[1]) {
                let x = a[0] + (q[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
                if q[0] < x {
                    inside = !inside;
                }
            }
        }
        inside
            || (0..n).any(|i| {
                segment_distance_2d(q, self.corners_2d[i], self.corners_2d[(i + 1) % n]) <= tol
            })
    }

    /// True when the projection of `p` onto the plane lies within `tol` of side `i` (from
    /// corner `i` to the next).
    pub fn near_side(&self, p: &Point3, i: usize, tol: f64) -> bool {
        let n = self.corners_2d.len();
        let q = [self.u.dot(&p.coords), self.v.dot(&p.coords)];
        segment_distance_2d(q, self.corners_2d[i % n], self.corners_2d[(i + 1) % n]) <= tol
    }

    /// Axis-aligned bounds of the polygon.
    pub fn bounds(&self) -> (Point3, Point3) {
        crate::mesh::bounding_box(&self.corners)
    }
}

fn segment_distance_2d(q: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let ab = [b[0] - a[0], b[1] - a[1]];
    let aq = [q[0] - a[0], q[1] - a[1]];
    let len2 = ab[0] * ab[0] + ab[1] * ab[1];
    let t = if len2 > 0.0 {
        ((aq[0] * ab[0] + aq[1] * ab[1]) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let d = [aq[0] - t * ab[0], aq[1] - t * ab[1]];
    (d[0] * d[0] + d[1] * d[1]).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The unit square in the plane z = 1.
    fn unit_square() -> CutPolygon {
        CutPolygon::new(&[
            Point3::new(0.0, 0.0, 1.0),
            Point3::new(1.0, 0.0, 1.0),
            Point3::new(1.0, 1.0, 1.0),
            Point3::new(0.0, 1.0, 1.0),
        ])
        .unwrap()
    }

    #[test]
    fn square_contains_its_inside_only() {
        let c = unit_square();
        assert!((c.normal.z.abs() - 1.0).abs() < 1e-15);
        assert!(c.contains_projection(&Point3::new(0.5, 0.5, 7.0), 0.0));
        assert!(!c.contains_projection(&Point3::new(1.5, 0.5, 1.0), 0.0));
        assert!(c.contains_projection(&Point3::new(1.05, 0.5, 1.0), 0.1));
        assert!((c.signed_distance(&Point3::new(0.3, 0.3, 3.0)).abs() - 2.0).abs() < 1e-15);
        assert!(
            CutPolygon::new(&[
                Point3::origin(),
                Point3::new(1.0, 0.0, 0.0),
                Point3::new(2.0, 0.0, 0.0)
            ])
            .is_none()
        );
    }

    #[test]
    fn near_side_measures_from_one_side_only() {
        let c = unit_square();
        // side 1 runs from (1, 0) to (1, 1): 0.05 past it is near, 0.05 past side 3 is not
        let past_side_1 = Point3::new(1.05, 0.5, 4.0);
        assert!(c.near_side(&past_side_1, 1, 0.1));
        assert!(!c.near_side(&past_side_1, 1, 0.01));
        assert!(!c.near_side(&past_side_1, 3, 0.1));
        assert!(c.near_side(&Point3::new(-0.05, 0.5, 1.0), 3, 0.1));
        // beyond a corner the distance is to the corner
        assert!(!c.near_side(&Point3::new(1.08, 1.08, 1.0), 1, 0.1));
        assert!(c.near_side(&Point3::new(1.05, 1.05, 1.0), 1, 0.1));
    }
}
