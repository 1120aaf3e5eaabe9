//! Where a blade stops: on tissue a scalpel does not cut (bone, cartilage;
//! [`crate::model::Model::uncuttable_regions`]).
//!
//! The blade's cutting edge runs from its heel `H` (towards the handle) to its tip `T`. It
//! enters a tetrahedron at the parameter `s_in` of `P(s) = H + s (T - H)` found by clipping
//! the segment against the tetrahedron's four face planes (Cyrus and Beck 1978): with `n_f`
//! the outward normal of face `f` and `p_f` a point on it, the segment is inside where
//! `n_f . (P(s) - p_f) <= 0` for every face, so each face with `n_f . (T - H) < 0` raises the
//! entry to `s = n_f . (p_f - H) / n_f . (T - H)` and each with `n_f . (T - H) > 0` lowers
//! the exit. The blade stops at the smallest entry over the uncuttable tetrahedra, less a
//! margin, so that its swept surface never crosses them: their tetrahedra are never split.

use super::polygon::Blade;
use crate::model::Model;
use crate::{Point3, Vector3};

/// How far above an uncuttable surface the stopped tip stays, m, besides the cutter's
/// snapping distance (vertices that near the swept surface are moved onto it).
pub const STOP_MARGIN_M: f64 = 5e-4;

/// Where a blade met uncuttable tissue.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BladeStop {
    /// The blade, its tip drawn back along its edge to just above the tissue.
    pub blade: Blade,
    /// The region it met.
    pub region: u32,
}

/// The blade stopped on the first of `model`'s uncuttable tetrahedra its edge meets from the
/// heel, in the current positions `x`; `None` if it meets none. `margin_m` is kept between the
/// tip and the tissue (the tip never goes above the heel).
pub fn stop_on_uncuttable(
    model: &Model,
    x: &[Point3],
    blade: &Blade,
    margin_m: f64,
) -> Option<BladeStop> {
    if model.uncuttable_regions.is_empty() || !(blade.depth_m > 0.0) {
        return None;
    }
    let mesh = &model.mesh;
    let heel = blade.heel();
    let along = blade.tip - heel;
    let (lo, hi) = (heel.inf(&blade.tip), heel.sup(&blade.tip));
    let mut first: Option<(f64, u32)> = None;
    for (t, tet) in mesh.tets().iter().enumerate() {
        if !model.uncuttable(t) {
            continue;
        }
        let p = tet.map(|v| x[v as usize]);
        let (tlo, thi) = p[1..]
            .iter()
            .fold((p[0], p[0]), |(a, b), q| (a.inf(q), b.sup(q)));
        if (0..3).any(|i| thi[i] < lo[i] || tlo[i] > hi[i]) {
            continue;
        }
        if let Some(s) = entry(&p, &heel, &along)
            && first.is_none_or(|(f, _)| s < f)
        {
            first = Some((s, mesh.regions()[t]));
        }
    }
    let (s, region) = first?;
    let length = along.norm();
    let depth_m = (length * s - margin_m).clamp(0.0, blade.depth_m);
    let direction = -along / length.max(f64::MIN_POSITIVE);
    Some(BladeStop {
        blade: Blade {
            tip: heel - direction * depth_m,
            edge_direction: blade.edge_direction,
            depth_m,
        },
        region,
    })
}

/// The parameter in [0, 1] at which `heel + s along` enters the tetrahedron `p`, if it does.
fn entry(p: &[Point3; 4], heel: &Point3, along: &Vector3) -> Option<f64> {
    const FACES: [[usize; 4]; 4] = [[1, 2, 3, 0], [0, 3, 2, 1], [0, 1, 3, 2], [0, 2, 1, 3]];
    let (mut s_in, mut s_out) = (0.0f64, 1.0f64);
    for [a, b, c, opposite] in FACES {
        let mut n = (p[b] - p[a]).cross(&(p[c] - p[a]));
        if n.dot(&(p[opposite] - p[a])) > 0.0 {
            n = -n;
        }
        let (num, den) = (n.dot(&(p[a] - heel)), n.dot(along));
        if den.abs() <= f64::EPSILON * n.norm() * along.norm() {
            if num < 0.0 {
                return None; // parallel to the face and outside it
            }
        } else if den < 0.0 {
            s_in = s_in.max(num / den);
        } else {
            s_out = s_out.min(num / den);
        }
        if s_in > s_out {
            return None;
        }
    }
    Some(s_in)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::TetMesh;
    use crate::model::Material;

    /// A unit tetrahedron of region 7 with its top face at z = 0 (below it, down to z = -1),
    /// the regions `uncuttable`.
    fn bone(uncuttable: &[u32]) -> Model {
        let positions = vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
            Point3::new(0.0, 0.0, -1.0),
        ];
        let mesh = TetMesh::new(positions, vec![[0, 1, 3, 2]], vec![7]).expect("a tetrahedron");
        Model::new(mesh, &[(7, Material::default())], &[], Vector3::zeros())
            .expect("a model")
            .with_uncuttable_regions(uncuttable)
    }

    fn blade(x: f64, y: f64, tip_z: f64) -> Blade {
        Blade {
            tip: Point3::new(x, y, tip_z),
            edge_direction: Vector3::z(),
            depth_m: 2.0,
        }
    }

    #[test]
    fn a_blade_over_bone_stops_its_margin_above_it() {
        let model = bone(&[7]);
        let x = model.mesh.positions();
        let b = blade(0.2, 0.2, -0.5);
        let stop = stop_on_uncuttable(&model, x, &b, 0.1).expect("a stop");
        assert_eq!(stop.region, 7);
        assert!(
            (stop.blade.tip - Point3::new(0.2, 0.2, 0.1)).norm() < 1e-12,
            "{stop:?}"
        );
        assert!(
            (stop.blade.heel() - b.heel()).norm() < 1e-12,
            "the heel stays"
        );
        // drawn back 0.6 of its 2
        assert!((stop.blade.depth_m - 1.4).abs() < 1e-12);
        // beside the bone, above it, or with the region cuttable: no stop
        for (b, model) in [
            (blade(0.8, 0.8, -0.5), bone(&[7])),
            (blade(0.2, 0.2, 0.3), bone(&[7])),
            (blade(0.2, 0.2, -0.5), bone(&[3])),
        ] {
            assert_eq!(stop_on_uncuttable(&model, x, &b, 0.1), None);
        }
    }

    #[test]
    fn a_blade_whose_heel_is_in_bone_is_drawn_back_to_nothing() {
        let model = bone(&[7]);
        let b = Blade {
            tip: Point3::new(0.1, 0.1, -0.9),
            edge_direction: Vector3::z(),
            depth_m: 0.5,
        };
        let stop = stop_on_uncuttable(&model, model.mesh.positions(), &b, 0.1).expect("a stop");
        assert_eq!(stop.blade.depth_m, 0.0);
        assert!((stop.blade.tip - b.heel()).norm() < 1e-12);
    }
}
