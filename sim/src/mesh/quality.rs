//! Mesh quality: dihedral angles.

use super::{TetMesh, dihedral_angles};

/// Dihedral-angle statistics (degrees) over the tetrahedra of a mesh.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct QualityStats {
    /// The smallest dihedral angle of any tetrahedron.
    pub min_dihedral_deg: f64,
    /// The largest dihedral angle of any tetrahedron.
    pub max_dihedral_deg: f64,
    /// Mean over tetrahedra of `max dihedral / min dihedral` (the paper's mu; 1.0 would
    /// be ideal, a regular tetrahedron has 1.0).
    pub mean_mu: f64,
    /// Worst (largest) `max / min` dihedral ratio of any tetrahedron.
    pub max_mu: f64,
}

/// The paper's pattern indicator for one tetrahedron: `mu = max(theta) / min(theta)`.
pub fn tet_mu(angles: &[f64; 6]) -> f64 {
    let (lo, hi) = angles.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &a| {
        (lo.min(a), hi.max(a))
    });
    if lo > 0.0 { hi / lo } else { f64::INFINITY }
}

pub(super) fn quality(mesh: &TetMesh) -> QualityStats {
    let mut s = QualityStats {
        min_dihedral_deg: f64::INFINITY,
        max_dihedral_deg: 0.0,
        mean_mu: 0.0,
        max_mu: 0.0,
    };
    for t in 0..mesh.tet_count() {
        let a = dihedral_angles(&mesh.tet_corners(t));
        for &x in &a {
            s.min_dihedral_deg = s.min_dihedral_deg.min(x.to_degrees());
            s.max_dihedral_deg = s.max_dihedral_deg.max(x.to_degrees());
        }
        let mu = tet_mu(&a);
        s.mean_mu += mu;
        s.max_mu = s.max_mu.max(mu);
    }
    s.mean_mu /= mesh.tet_count().max(1) as f64;
    s
}
