//! Small vector helpers on `[f64; 3]` and polylines, shared by the metrics.

pub(crate) type V3 = [f64; 3];

pub(crate) fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub(crate) fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
pub(crate) fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}
pub(crate) fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub(crate) fn cross(a: V3, b: V3) -> V3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
pub(crate) fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}
pub(crate) fn dist(a: V3, b: V3) -> f64 {
    norm(sub(a, b))
}
/// `a / |a|`, or `None` for a (nearly) zero or non-finite vector.
pub(crate) fn unit(a: V3) -> Option<V3> {
    let n = norm(a);
    (n > 1e-12 && n.is_finite()).then(|| scale(a, 1.0 / n))
}
pub(crate) fn finite(a: &[f64]) -> bool {
    a.iter().all(|x| x.is_finite())
}
/// The angle between two vectors (rad); `None` if either is zero.
pub(crate) fn angle(a: V3, b: V3) -> Option<f64> {
    let (a, b) = (unit(a)?, unit(b)?);
    Some(norm(cross(a, b)).atan2(dot(a, b)))
}

/// Projection onto the plane through the origin perpendicular to the unit normal `n`:
/// `P(x) = x - (x . n) n`. Distances between projected points are distances "seen from above".
pub(crate) fn project(x: V3, n: V3) -> V3 {
    sub(x, scale(n, dot(x, n)))
}

/// The closest point to `p` on segment `ab`: `(point, parameter in [0, 1])`.
pub(crate) fn closest_on_segment(p: V3, a: V3, b: V3) -> (V3, f64) {
    let ab = sub(b, a);
    let l2 = dot(ab, ab);
    let t = if l2 > 0.0 { (dot(sub(p, a), ab) / l2).clamp(0.0, 1.0) } else { 0.0 };
    (add(a, scale(ab, t)), t)
}

/// Where `p` is closest to a polyline: the distance.
#[derive(Debug, Clone, Copy)]
pub(crate) struct OnLine {
    pub distance: f64,
}

/// The closest point to `p` on the polyline `line` (at least 2 points).
pub(crate) fn closest_on_polyline(p: V3, line: &[V3]) -> OnLine {
    let mut best = OnLine { distance: f64::INFINITY };
    for w in line.windows(2) {
        let d = dist(p, closest_on_segment(p, w[0], w[1]).0);
        if d < best.distance {
            best = OnLine { distance: d };
        }
    }
    best
}

/// The length of a polyline.
pub(crate) fn polyline_length(line: &[V3]) -> f64 {
    line.windows(2).map(|w| dist(w[0], w[1])).sum()
}

/// The point at arc length `s` along the polyline (clamped to its ends) and the unit tangent
/// of the segment it is on.
pub(crate) fn point_at_arc(line: &[V3], s: f64) -> (V3, V3) {
    let mut acc = 0.0;
    let last = line.len().saturating_sub(2);
    for (i, w) in line.windows(2).enumerate() {
        let len = dist(w[0], w[1]);
        if acc + len >= s || i == last {
            let t = if len > 0.0 { ((s - acc) / len).clamp(0.0, 1.0) } else { 0.0 };
            let tangent = unit(sub(w[1], w[0])).unwrap_or([1.0, 0.0, 0.0]);
            return (add(w[0], scale(sub(w[1], w[0]), t)), tangent);
        }
        acc += len;
    }
    (line[0], [1.0, 0.0, 0.0])
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
        let line = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]];
        let on = closest_on_polyline([1.5, 0.5, 0.0], &line);
        assert!((on.distance - 0.5).abs() < 1e-12);
        assert!((polyline_length(&line) - 2.0).abs() < 1e-12);
        let (p, t) = point_at_arc(&line, 1.25);
        assert!(dist(p, [1.0, 0.25, 0.0]) < 1e-12);
        assert!(dist(t, [0.0, 1.0, 0.0]) < 1e-12);
        assert!((angle([1.0, 0.0, 0.0], [1.0, 1.0, 0.0]).unwrap() - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
        assert_eq!(project([1.0, 2.0, 3.0], [0.0, 0.0, 1.0]), [1.0, 2.0, 0.0]);
    }
}
