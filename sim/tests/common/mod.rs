//! Checks shared by the cutting tests.

use cutlab_sim::solver::Simulation;

/// The cut mesh is valid (shape-degenerate tets allowed, none of zero or negative volume at
/// rest), its surface manifold, the mass conserved to 1e-12 and the rest volume to 1e-9
/// (relative), and the state finite.
pub fn check_invariants(sim: &Simulation, mass0: f64, volume0: f64) {
    let mesh = &sim.model.mesh;
    let report = mesh.validate();
    // Shape-degenerate tets (normalised volume < 1e-8) can appear after many crossing cuts of
    // the same region; every tet must still have positive volume in the rest configuration.
    let structural = cutlab_sim::mesh::ValidationReport {
        degenerate_tets: Vec::new(),
        ..report.clone()
    };
    assert!(structural.is_ok(), "{report}");
    for t in 0..mesh.tet_count() {
        assert!(
            mesh.tet_volume(t) > 0.0,
            "tet {t} has volume {}",
            mesh.tet_volume(t)
        );
    }
    let bad = mesh.topology().boundary_non_manifold_edges();
    assert!(bad.is_empty(), "non-manifold surface edges {bad:?}");
    let mass = sim.model.total_mass();
    assert!(
        (mass - mass0).abs() <= 1e-12 * mass0,
        "mass {mass} vs {mass0}"
    );
    let volume = mesh.volume();
    assert!(
        (volume - volume0).abs() <= 1e-9 * volume0,
        "volume {volume} vs {volume0}"
    );
    assert!(
        sim.state
            .positions
            .iter()
            .all(|p| p.iter().all(|c| c.is_finite()))
    );
}
