//! The physics model against known answers: masses, rest after settling, determinism,
//! quarantine of non-finite values, and the stability estimate.

use cutlab_sim::Vector3;
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::solver::{Integrator, StaticSettings, StepError};

fn chest_wall(min_tets: usize) -> Scene {
    Scene::load(
        "chest-wall",
        BuildOptions {
            min_tets: Some(min_tets),
        },
    )
    .expect("built-in scene")
}

#[test]
fn lumped_masses_sum_to_density_times_volume() {
    let scene = chest_wall(2_000);
    let m = &scene.model;
    let expected = 900.0 * m.mesh.volume();
    assert!(
        (m.total_mass() - expected).abs() <= 1e-12 * expected,
        "{} vs {expected}",
        m.total_mass()
    );
}

#[test]
fn pretension_shortens_rest_lengths_by_s() {
    let scene = chest_wall(2_000);
    let s = &scene.model.springs;
    let pos = scene.model.mesh.positions();
    for e in 0..s.len() {
        let [a, b] = s.ends[e];
        let d = (pos[b as usize] - pos[a as usize]).norm();
        assert!((s.rest_length[e] - 0.96 * d).abs() <= 1e-15 * d);
        assert_eq!(s.stiffness[e], 100.0);
    }
}

#[test]
fn settled_scene_stays_at_rest_for_ten_seconds() {
    for integrator in Integrator::ALL {
        let scene = chest_wall(10_000);
        let mut sim = scene.simulation();
        sim.edit(|_, settings| settings.integrator = integrator);
        let report = sim.settle(StaticSettings::default());
        assert!(report.converged, "{report:?}");
        // the pre-tension really moved the tissue
        let moved = sim
            .state
            .positions
            .iter()
            .zip(scene.model.mesh.positions())
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(moved > 1e-4, "settling moved at most {moved} m");
        let mut max_speed = 0.0f64;
        for _ in 0..10_000 {
            sim.step().expect("step");
            max_speed = max_speed.max(sim.state.max_speed());
        }
        assert!(
            max_speed < 1e-9,
            "{integrator:?}: max speed {max_speed} m/s"
        );
    }
}

/// The free vertex closest to the top centre of the slab.
fn free_vertex_near_centre(scene: &Scene) -> usize {
    let pos = scene.model.mesh.positions();
    (0..pos.len())
        .filter(|&i| !scene.model.held[i])
        .min_by(|&a, &b| pos[a].coords.norm().total_cmp(&pos[b].coords.norm()))
        .expect("a free vertex")
}

fn run_pressed(integrator: Integrator, steps: usize) -> u64 {
    let scene = chest_wall(1_000);
    let mut sim = scene.simulation();
    sim.edit(|_, settings| settings.integrator = integrator);
    sim.settle(StaticSettings::default());
    let top = free_vertex_near_centre(&scene);
    for k in 0..steps {
        sim.external_forces_mut()[top] = Vector3::new(0.0, 0.0, -0.01 * (k as f64 * 0.05).sin());
        sim.step().expect("step");
    }
    sim.state.bit_hash()
}

#[test]
fn same_inputs_give_bit_identical_states() {
    for integrator in Integrator::ALL {
        let a = run_pressed(integrator, 200);
        let b = run_pressed(integrator, 200);
        assert_eq!(a, b, "{integrator:?}");
        assert_ne!(
            a,
            run_pressed(integrator, 199),
            "the hash must see the state"
        );
    }
}

#[test]
fn non_finite_force_is_rejected_and_state_kept() {
    let scene = chest_wall(1_000);
    let mut sim = scene.simulation();
    sim.settle(StaticSettings::default());
    let before = sim.state.bit_hash();
    let v = free_vertex_near_centre(&scene);
    sim.external_forces_mut()[v] = Vector3::new(f64::NAN, 0.0, 0.0);
    match sim.step() {
        Err(StepError::NonFiniteInput { vertices }) => assert_eq!(vertices, vec![v as u32]),
        other => panic!("expected a rejection, got {other:?}"),
    }
    assert_eq!(sim.state.bit_hash(), before);
    // A finite but absurd force that blows the explicit scheme up is quarantined too.
    sim.settings.integrator = Integrator::SymplecticEuler;
    sim.clear_external_forces();
    sim.external_forces_mut()[v] = Vector3::new(f64::MAX, f64::MAX, 0.0);
    let before = sim.state.bit_hash();
    assert!(matches!(sim.step(), Err(StepError::NonFinite { .. })));
    assert_eq!(sim.state.bit_hash(), before);
    sim.clear_external_forces();
    sim.step()
        .expect("the simulation keeps running after a rejected step");
}

#[test]
fn explicit_substeps_keep_an_unsettled_start_bounded() {
    let scene = chest_wall(1_000);
    let mut sim = scene.simulation();
    sim.edit(|_, settings| settings.integrator = Integrator::SymplecticEuler);
    let n = sim.explicit_substeps();
    assert!(n > 1);
    // Unsettled start: the pre-tension sets everything in motion; stays bounded.
    for _ in 0..500 {
        sim.step().expect("stable");
    }
    assert!(sim.state.max_speed() < 1.0);
}
