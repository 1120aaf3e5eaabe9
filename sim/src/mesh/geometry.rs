//! Elementary geometry of tetrahedra, triangles and point sets.

use crate::{Point3, Vector3};

/// Axis-aligned bounding box `(min, max)` of `points` (infinite and inverted when empty).
pub fn bounding_box<'a>(points: impl IntoIterator<Item = &'a Point3>) -> (Point3, Point3) {
    let mut lo = Point3::new(f64::INFINITY, f64::INFINITY, f64::INFINITY);
    let mut hi = Point3::new(f64::NEG_INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
    for p in points {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    (lo, hi)
}

/// Signed volume `det(b - a, c - a, d - a) / 6`; positive when `d` lies on the side of the
/// triangle `(a, b, c)` towards which its right-hand normal points.
#[inline]
pub fn tet_signed_volume(a: &Point3, b: &Point3, c: &Point3, d: &Point3) -> f64 {
    (b - a).cross(&(c - a)).dot(&(d - a)) / 6.0
}

/// Gradients of [`tet_signed_volume`] with respect to each corner: `V` is linear in each
/// corner, `V(p_l + d) = V + g_l . d` exactly, with `g_3 = (b - a) x (c - a) / 6`,
/// `g_2 = (d - a) x (b - a) / 6`, `g_1 = (c - a) x (d - a) / 6` and `g_0 = -(g_1 + g_2 + g_3)`.
#[inline]
pub fn tet_volume_gradients(p: &[Point3; 4]) -> [Vector3; 4] {
    let [a, b, c, d] = p;
    let g3 = (b - a).cross(&(c - a)) / 6.0;
    let g2 = (d - a).cross(&(b - a)) / 6.0;
    let g1 = (c - a).cross(&(d - a)) / 6.0;
    [-(g1 + g2 + g3), g1, g2, g3]
}

/// Right-hand normal `(b - a) x (c - a)` of a triangle (length = twice its area).
#[inline]
pub fn triangle_normal(a: &Point3, b: &Point3, c: &Point3) -> Vector3 {
    (b - a).cross(&(c - a))
}

/// The six interior dihedral angles (radians) of a tetrahedron, one per edge in the order of
/// [`super::TET_EDGES`]. The angle at edge (i, j) is between the two faces containing it:
/// theta = pi - angle(n_k, n_l) where n_k, n_l are the outward normals of the faces opposite
/// the other two vertices k and l. Degenerate tetrahedra give NaN-free values (0 or pi).
pub fn dihedral_angles(p: &[Point3; 4]) -> [f64; 6] {
    // Outward normals of the faces opposite each vertex (see `TET_FACES`), for a positively
    // oriented tetrahedron; for a negative one all flip, which leaves the angles unchanged.
    let faces = super::TET_FACES;
    let n = faces.map(|f| triangle_normal(&p[f[0]], &p[f[1]], &p[f[2]]));
    let mut out = [0.0; 6];
    for (e, &[i, j]) in super::TET_EDGES.iter().enumerate() {
        // the two vertices not on edge (i, j)
        let mut others = (0..4).filter(|&v| v != i && v != j);
        let (Some(k), Some(l)) = (others.next(), others.next()) else {
            unreachable!()
        };
        let (nk, nl) = (n[k], n[l]);
        let denom = nk.norm() * nl.norm();
        out[e] = if denom > 0.0 {
            let cos = (nk.dot(&nl) / denom).clamp(-1.0, 1.0);
            std::f64::consts::PI - cos.acos()
        } else {
            0.0
        };
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regular_tet_angles_are_arccos_one_third() {
        let p = [
            Point3::new(1.0, 1.0, 1.0),
            Point3::new(1.0, -1.0, -1.0),
            Point3::new(-1.0, 1.0, -1.0),
            Point3::new(-1.0, -1.0, 1.0),
        ];
        let expected = (1.0f64 / 3.0).acos();
        for a in dihedral_angles(&p) {
            assert!((a - expected).abs() < 1e-12, "{a} vs {expected}");
        }
    }

    #[test]
    fn corner_tet_has_right_and_acute_angles() {
        let p = [
            Point3::origin(),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
            Point3::new(0.0, 0.0, 1.0),
        ];
        assert!((tet_signed_volume(&p[0], &p[1], &p[2], &p[3]) - 1.0 / 6.0).abs() < 1e-15);
        let a = dihedral_angles(&p);
        // edges at the origin meet at right angles
        for e in 0..3 {
            assert!((a[e] - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        }
        // edges of the slanted face: arccos(1/sqrt 3)
        for e in 3..6 {
            assert!((a[e] - (1.0 / 3.0f64.sqrt()).acos()).abs() < 1e-12);
        }
    }
}
