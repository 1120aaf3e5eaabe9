//! The surgical field through an opened wound, wherever the incision was made (issue 62):
//! what of a target behind the tissue the surgeon sees from the viewpoint, and how wide an
//! instrument reaches it. Nothing here refers to a planned line: an incision placed elsewhere
//! that opens as well measures as well.
//!
//! The target is an ellipsoid `((x - c_x)/a)^2 + ((y - c_y)/b)^2 + ((z - c_z)/c)^2 = 1` (a scene's
//! `[[targets]]`). Its surface is sampled on a grid of the parameters `theta` (from the +z pole)
//! and `phi`, at the cells' midpoints, `p = c + (a sin(theta) cos(phi), b sin(theta) sin(phi),
//! c cos(theta))`, each standing for the patch `|dp/dtheta x dp/dphi| dtheta dphi`.
//!
//! - **The target region** is the part of the surface that faces the eye `e`: where the outward
//!   normal `(p - c)` scaled by `(1/a^2, 1/b^2, 1/c^2)` has a positive dot product with
//!   `e - p`. For a sphere of radius `r` seen from `D` away its area is the cap
//!   `2 pi r^2 (1 - r / D)`.
//! - **Visible**: a facing sample whose segment from the eye meets no triangle of the tissue's
//!   surface before it ([`super::field::seen`]). The visible area is the sum of
//!   the visible samples' patches; the visible fraction is that over the region's area.
//! - **Working width**: the widest straight instrument that reaches a visible point from the
//!   eye's side: at a visible sample `p`, a cylinder of radius `r` along `e - p` is clear when
//!   [`RING_RAYS`] rays parallel to its axis, on its surface, from beside `p` to the eye's
//!   distance, meet no triangle; `r` is found by bisection to [`WIDTH_RESOLUTION_M`]. The
//!   metric is twice the largest `r` over up to [`WIDTH_SAMPLES`] visible samples.

use nalgebra::{Point3, Vector3};
use parry3d_f64::math::Vector as PVec;
use parry3d_f64::query::{Ray, RayCast};
use parry3d_f64::shape::TriMesh;

use super::field::seen;

/// Rays on an instrument's surface per test of a radius.
pub const RING_RAYS: usize = 12;
/// The bisection of the working width stops at this radius step (m).
pub const WIDTH_RESOLUTION_M: f64 = 1e-4;
/// The widest instrument looked for (m): a retracted mini-thoracotomy's opening is narrower.
pub const WIDTH_MAX_M: f64 = 0.08;
/// Visible samples whose working width is measured, at most (spread evenly over them).
pub const WIDTH_SAMPLES: usize = 64;

/// An axis-aligned ellipsoid: a target behind the tissue.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ellipsoid {
    /// Its centre (m).
    pub centre_m: Point3<f64>,
    /// Its semi-axes along x, y and z (m).
    pub radii_m: Vector3<f64>,
}

impl Ellipsoid {
    /// Whether `p` lies inside or on it: `|(p - c) / r| <= 1`.
    pub fn contains(&self, p: &Point3<f64>) -> bool {
        (p - self.centre_m)
            .component_div(&self.radii_m)
            .norm_squared()
            <= 1.0
    }
}

/// What the opening shows of a target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Exposure {
    /// The area of the target facing the eye (m^2).
    pub region_area_m2: f64,
    /// The area of it seen through the opening (m^2).
    pub visible_area_m2: f64,
    /// `visible_area_m2 / region_area_m2`.
    pub visible_fraction: f64,
    /// The widest straight instrument that reaches a visible point (m); 0 when none is seen.
    pub working_width_m: f64,
    /// The area-weighted centre of what is seen (m); none when nothing is.
    pub visible_centroid_m: Option<Point3<f64>>,
}

/// One sample of the target's surface: where, its patch's area, and whether it faces the eye.
#[derive(Debug, Clone, Copy)]
struct Sample {
    at: Point3<f64>,
    area_m2: f64,
}

/// The facing samples of `target` seen from `eye`, `n_theta` by `2 n_theta` of them in all.
fn facing_samples(target: &Ellipsoid, eye: &Point3<f64>, n_theta: usize) -> Vec<Sample> {
    let (c, r) = (target.centre_m, target.radii_m);
    let n_phi = 2 * n_theta;
    let (d_theta, d_phi) = (
        std::f64::consts::PI / n_theta as f64,
        std::f64::consts::TAU / n_phi as f64,
    );
    let mut out = Vec::new();
    for i in 0..n_theta {
        let theta = (i as f64 + 0.5) * d_theta;
        let (st, ct) = theta.sin_cos();
        for j in 0..n_phi {
            let phi = (j as f64 + 0.5) * d_phi;
            let (sp, cp) = phi.sin_cos();
            let at = c + Vector3::new(r.x * st * cp, r.y * st * sp, r.z * ct);
            let normal = (at - c).component_div(&r.component_mul(&r));
            if normal.dot(&(eye - at)) <= 0.0 {
                continue;
            }
            let d_dtheta = Vector3::new(r.x * ct * cp, r.y * ct * sp, -r.z * st);
            let d_dphi = Vector3::new(-r.x * st * sp, r.y * st * cp, 0.0);
            let area_m2 = d_dtheta.cross(&d_dphi).norm() * d_theta * d_phi;
            out.push(Sample { at, area_m2 });
        }
    }
    out
}

/// The ray from `from` along `along`, in parry's types.
pub(crate) fn ray(from: &Point3<f64>, along: &Vector3<f64>) -> Ray {
    Ray::new(
        PVec::new(from.x, from.y, from.z),
        PVec::new(along.x, along.y, along.z),
    )
}

/// Whether a cylinder of radius `r` from `p` towards `eye` (as far as the eye) is clear.
fn clear(tissue: &TriMesh, eye: &Point3<f64>, p: &Point3<f64>, r: f64) -> bool {
    let axis = eye - p;
    let helper = if axis.x.abs() < 0.9 * axis.norm() {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let (Some(u), Some(v)) = (
        axis.cross(&helper).try_normalize(1e-15),
        axis.cross(&axis.cross(&helper)).try_normalize(1e-15),
    ) else {
        return false;
    };
    (0..RING_RAYS).all(|k| {
        let angle = std::f64::consts::TAU * k as f64 / RING_RAYS as f64;
        let from = p + (u * angle.cos() + v * angle.sin()) * r;
        tissue
            .cast_local_ray(&ray(&from, &axis), 1.0, false)
            .is_none()
    })
}

/// The largest clear radius at `p` (0 when not even a thin instrument passes).
fn clear_radius(tissue: &TriMesh, eye: &Point3<f64>, p: &Point3<f64>) -> f64 {
    if !clear(tissue, eye, p, WIDTH_RESOLUTION_M) {
        return 0.0;
    }
    let (mut lo, mut hi) = (WIDTH_RESOLUTION_M, WIDTH_MAX_M / 2.0);
    if clear(tissue, eye, p, hi) {
        return hi;
    }
    while hi - lo > WIDTH_RESOLUTION_M {
        let mid = 0.5 * (lo + hi);
        if clear(tissue, eye, p, mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// What `tissue`'s opening shows of `target` from `eye`, its surface sampled `n_theta` by
/// `2 n_theta` (see the module documentation).
pub fn exposure(
    tissue: &TriMesh,
    target: &Ellipsoid,
    eye: &Point3<f64>,
    n_theta: usize,
) -> Exposure {
    let samples = facing_samples(target, eye, n_theta.max(2));
    // (folded from +0: an empty sum of floats is -0)
    let region_area_m2 = samples.iter().fold(0.0, |a, s| a + s.area_m2);
    let visible: Vec<&Sample> = samples
        .iter()
        .filter(|s| seen(tissue, eye, &s.at))
        .collect();
    let visible_area_m2 = visible.iter().fold(0.0, |a, s| a + s.area_m2);
    let visible_centroid_m = (visible_area_m2 > 0.0).then(|| {
        Point3::from(
            visible
                .iter()
                .fold(Vector3::zeros(), |a, s| a + s.at.coords * s.area_m2)
                / visible_area_m2,
        )
    });
    let stride = visible.len().div_ceil(WIDTH_SAMPLES).max(1);
    let working_width_m = 2.0
        * visible
            .iter()
            .step_by(stride)
            .map(|s| clear_radius(tissue, eye, &s.at))
            .fold(0.0, f64::max);
    Exposure {
        region_area_m2,
        visible_area_m2,
        visible_fraction: if region_area_m2 > 0.0 {
            visible_area_m2 / region_area_m2
        } else {
            0.0
        },
        working_width_m,
        visible_centroid_m,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat wall at z = 0 over [-0.1, 0.1]^2 with a rectangular hole `|x| < w/2`, `|y| < l/2`
    /// (none when `w` is 0), as four rectangles of two triangles each.
    fn wall_with_hole(w: f64, l: f64) -> TriMesh {
        let (e, hx, hy) = (0.1, w / 2.0, l / 2.0);
        let rects = if w > 0.0 {
            vec![
                [-e, -e, e, -hy],
                [-e, hy, e, e],
                [-e, -hy, -hx, hy],
                [hx, -hy, e, hy],
            ]
        } else {
            vec![[-e, -e, e, e]]
        };
        let mut vertices = Vec::new();
        let mut triangles = Vec::new();
        for [x0, y0, x1, y1] in rects {
            let k = vertices.len() as u32;
            for (x, y) in [(x0, y0), (x1, y0), (x1, y1), (x0, y1)] {
                vertices.push(PVec::new(x, y, 0.0));
            }
            triangles.push([k, k + 1, k + 2]);
            triangles.push([k, k + 2, k + 3]);
        }
        TriMesh::new(vertices, triangles).expect("a wall")
    }

    fn heart() -> Ellipsoid {
        Ellipsoid {
            centre_m: Point3::new(0.0, 0.0, -0.06),
            radii_m: Vector3::new(0.04, 0.04, 0.04),
        }
    }

    #[test]
    fn the_region_is_the_cap_a_sphere_shows_an_eye_and_converges_to_it() {
        let eye = Point3::new(0.0, 0.0, 0.14);
        let (r, d) = (0.04, 0.2);
        let cap = std::f64::consts::TAU * r * r * (1.0 - r / d);
        let error = |n: usize| {
            let area: f64 = facing_samples(&heart(), &eye, n)
                .iter()
                .map(|s| s.area_m2)
                .sum();
            (area / cap - 1.0).abs()
        };
        let (coarse, fine) = (error(20), error(80));
        assert!(fine < 0.01, "{fine}");
        assert!(fine < coarse, "{fine} against {coarse}");
    }

    #[test]
    fn a_closed_wall_shows_nothing_and_a_hole_shows_what_its_rays_pass() {
        let eye = Point3::new(0.0, 0.0, 0.14);
        let closed = exposure(&wall_with_hole(0.0, 0.0), &heart(), &eye, 40);
        assert_eq!(closed.visible_area_m2, 0.0);
        assert_eq!(closed.working_width_m, 0.0);
        let (w, l) = (0.02, 0.05);
        let open = exposure(&wall_with_hole(w, l), &heart(), &eye, 40);
        // the same samples judged by where their rays cross the wall's plane
        let expected: f64 = facing_samples(&heart(), &eye, 40)
            .iter()
            .filter(|s| {
                let t = eye.z / (eye.z - s.at.z);
                let x = eye + (s.at - eye) * t;
                x.x.abs() < w / 2.0 && x.y.abs() < l / 2.0
            })
            .map(|s| s.area_m2)
            .sum();
        assert!(
            (open.visible_area_m2 / expected - 1.0).abs() < 0.02,
            "{} against {expected}",
            open.visible_area_m2
        );
        assert!(open.visible_fraction > 0.05 && open.visible_fraction < 0.5);
        // a straight instrument through a 20 mm slot is at most 20 mm wide
        assert!(
            (open.working_width_m - w).abs() < 0.002,
            "{}",
            open.working_width_m
        );
    }

    #[test]
    fn a_longer_or_wider_opening_shows_more() {
        let eye = Point3::new(0.0, 0.0, 0.14);
        let seen = |w: f64, l: f64| exposure(&wall_with_hole(w, l), &heart(), &eye, 30);
        let (short, long, wide) = (seen(0.01, 0.03), seen(0.01, 0.06), seen(0.02, 0.06));
        assert!(short.visible_area_m2 < long.visible_area_m2);
        assert!(long.visible_area_m2 < wide.visible_area_m2);
        assert!(long.working_width_m < wide.working_width_m);
    }
}
