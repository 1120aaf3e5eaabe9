//! Geometry the metrics share that nalgebra does not provide: polylines (closest point,
//! length, point at arc length), projection onto a plane, and a unit vector and angle that
//! are `None` for degenerate input. Positions are [`Point3<f64>`], directions
//! [`Vector3<f64>`]; the crate's public and serialized data stay `[f64; 3]` and are converted
//! where the metrics read them (`Point3::from(a)`, `Vector3::from(a)`, `.into()`).

use nalgebra::{Point3, Vector3};

/// `a / |a|`, or `None` for a (nearly) zero or non-finite vector.
///
/// Unlike [`Vector3::try_normalize`], a vector with an infinite or NaN component gives `None`
/// rather than a non-finite "unit" vector.
pub(crate) fn unit(a: Vector3<f64>) -> Option<Vector3<f64>> {
    let n = a.norm();
    (n > 1e-12 && n.is_finite()).then(|| a * (1.0 / n))
}

/// Two unit vectors `(u, v)` spanning the plane normal to `normal` (`+z` when it has no
/// direction), with `u x v` along it: `u` is `n x x` (`n x y` when `n` is along `x`).
pub(crate) fn plane_basis(normal: [f64; 3]) -> (Vector3<f64>, Vector3<f64>) {
    let n = unit(normal.into()).unwrap_or_else(Vector3::z);
    let u = unit(n.cross(&Vector3::x()))
        .or_else(|| unit(n.cross(&Vector3::y())))
        .unwrap_or_else(Vector3::x);
    (u, n.cross(&u))
}

/// Whether every number of `a` is finite.
pub(crate) fn finite(a: &[f64]) -> bool {
    a.iter().all(|x| x.is_finite())
}

/// The angle between two vectors (rad), `atan2(|a x b|, a . b)` of their unit vectors; `None`
/// if either is (nearly) zero or not finite.
///
/// Not [`Vector3::angle`]: that takes the `acos` of the cosine, which loses precision near 0
/// and pi (~1e-8 rad), and gives 0 for a zero vector.
pub(crate) fn angle(a: Vector3<f64>, b: Vector3<f64>) -> Option<f64> {
    let (a, b) = (unit(a)?, unit(b)?);
    Some(a.cross(&b).norm().atan2(a.dot(&b)))
}

/// Projection onto the plane through the origin perpendicular to the unit normal `n`:
/// `P(x) = x - (x . n) n`. Distances between projected points are distances "seen from above".
pub(crate) fn project(x: Point3<f64>, n: &Vector3<f64>) -> Point3<f64> {
    x - n * x.coords.dot(n)
}

/// The closest point to `p` on segment `ab`: `(point, parameter in [0, 1])`.
pub(crate) fn closest_on_segment(
    p: Point3<f64>,
    a: Point3<f64>,
    b: Point3<f64>,
) -> (Point3<f64>, f64) {
    let ab = b - a;
    let l2 = ab.norm_squared();
    let t = if l2 > 0.0 {
        ((p - a).dot(&ab) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + ab * t, t)
}

/// Where `p` is closest to a polyline: the distance, and the arc-length coordinate of the
/// closest point with the polyline extended straight beyond both ends: before the start it is
/// `(p - line_0) . t_0 <= 0`, past the end `L + (p - line_n) . t_n >= L` (`t` the end
/// segments' unit tangents, `L` the length).
#[derive(Debug, Clone, Copy)]
pub(crate) struct OnLine {
    pub distance: f64,
    pub arc: f64,
}

/// The closest point to `p` on the polyline `line` (at least 2 points).
pub(crate) fn closest_on_polyline(p: Point3<f64>, line: &[Point3<f64>]) -> OnLine {
    let mut best = OnLine {
        distance: f64::INFINITY,
        arc: 0.0,
    };
    let (mut acc, last) = (0.0, line.len().saturating_sub(2));
    for (i, w) in line.windows(2).enumerate() {
        let len = nalgebra::distance(&w[0], &w[1]);
        let (q, t) = closest_on_segment(p, w[0], w[1]);
        let d = nalgebra::distance(&p, &q);
        if d < best.distance {
            let tangent = unit(w[1] - w[0]).unwrap_or_else(Vector3::zeros);
            let arc = match (i, t) {
                (0, t) if t <= 0.0 => (p - w[0]).dot(&tangent),
                (i, t) if i == last && t >= 1.0 => acc + len + (p - w[1]).dot(&tangent),
                _ => acc + t * len,
            };
            best = OnLine { distance: d, arc };
        }
        acc += len;
    }
    best
}

/// The length of a polyline.
pub(crate) fn polyline_length(line: &[Point3<f64>]) -> f64 {
    line.windows(2)
        .map(|w| nalgebra::distance(&w[0], &w[1]))
        .sum()
}

/// The measure of the union of the intervals `spans` (each `(a, b)` with `a <= b`).
pub(crate) fn union_length(mut spans: Vec<(f64, f64)>) -> f64 {
    spans.sort_by(|x, y| x.0.total_cmp(&y.0));
    let mut total = 0.0;
    let mut current: Option<(f64, f64)> = None;
    for (a, b) in spans {
        current = match current {
            Some((c0, c1)) if a <= c1 => Some((c0, c1.max(b))),
            Some((c0, c1)) => {
                total += c1 - c0;
                Some((a, b))
            }
            None => Some((a, b)),
        };
    }
    total + current.map_or(0.0, |(a, b)| b - a)
}

/// The point at arc length `s` along the polyline (clamped to its ends) and the unit tangent
/// of the segment it is on (+x for a zero-length segment).
pub(crate) fn point_at_arc(line: &[Point3<f64>], s: f64) -> (Point3<f64>, Vector3<f64>) {
    let mut acc = 0.0;
    let last = line.len().saturating_sub(2);
    for (i, w) in line.windows(2).enumerate() {
        let len = nalgebra::distance(&w[0], &w[1]);
        if acc + len >= s || i == last {
            let t = if len > 0.0 {
                ((s - acc) / len).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let tangent = unit(w[1] - w[0]).unwrap_or_else(Vector3::x);
            return (w[0] + (w[1] - w[0]) * t, tangent);
        }
        acc += len;
    }
    (line[0], Vector3::x())
}

/// Mean, RMS and max of a non-empty list.
pub(crate) fn mean_rms_max(v: &[f64]) -> (f64, f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let rms = (v.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
    let max = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    (mean, rms, max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn polyline_projection_and_arc() {
        let line = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(1.0, 1.0, 0.0),
        ];
        let on = closest_on_polyline(Point3::new(1.5, 0.5, 0.0), &line);
        assert!((on.distance - 0.5).abs() < 1e-12);
        assert!((polyline_length(&line) - 2.0).abs() < 1e-12);
        let (p, t) = point_at_arc(&line, 1.25);
        assert!(nalgebra::distance(&p, &Point3::new(1.0, 0.25, 0.0)) < 1e-12);
        assert!((t - Vector3::new(0.0, 1.0, 0.0)).norm() < 1e-12);
        assert!(
            (angle(Vector3::new(1.0, 0.0, 0.0), Vector3::new(1.0, 1.0, 0.0)).unwrap()
                - std::f64::consts::FRAC_PI_4)
                .abs()
                < 1e-12
        );
        assert_eq!(
            project(Point3::new(1.0, 2.0, 3.0), &Vector3::new(0.0, 0.0, 1.0)),
            Point3::new(1.0, 2.0, 0.0)
        );
    }

    #[test]
    fn arc_coordinates_extend_beyond_the_ends_and_spans_unite() {
        let line = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(1.0, 1.0, 0.0),
        ];
        for (p, s) in [
            ((0.5, 0.2), 0.5),
            ((-0.3, 0.1), -0.3),
            ((1.2, 0.5), 1.5),
            ((1.1, 1.4), 2.4),
            ((0.0, 0.0), 0.0),
        ] {
            let got = closest_on_polyline(Point3::new(p.0, p.1, 0.0), &line).arc;
            assert!((got - s).abs() < 1e-12, "{p:?}: {got}, expected {s}");
        }
        assert!(
            (union_length(vec![(2.0, 3.0), (0.0, 1.0), (0.5, 1.5), (1.5, 1.5)]) - 2.5).abs()
                < 1e-12
        );
        assert_eq!(union_length(Vec::new()), 0.0);
    }

    #[test]
    fn unit_and_angle_reject_zero_and_non_finite_vectors() {
        assert!(
            (unit(Vector3::new(0.0, 3.0, 4.0)).unwrap() - Vector3::new(0.0, 0.6, 0.8)).norm()
                < 1e-15
        );
        assert_eq!(unit(Vector3::zeros()), None);
        assert_eq!(unit(Vector3::new(1e-13, 0.0, 0.0)), None);
        assert_eq!(unit(Vector3::new(f64::NAN, 0.0, 1.0)), None);
        assert_eq!(unit(Vector3::new(f64::INFINITY, 0.0, 1.0)), None);
        assert_eq!(angle(Vector3::zeros(), Vector3::x()), None);
        assert!((angle(Vector3::x(), -Vector3::x()).unwrap() - std::f64::consts::PI).abs() < 1e-15);
    }
}
