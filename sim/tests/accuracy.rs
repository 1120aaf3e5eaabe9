//! The force models against problems with known answers (see `cutlab_sim::reference`), with
//! tolerances for the finite elements and the springs' errors stated (asserted where they show
//! a known defect, printed otherwise; `--nocapture` shows them).

use cutlab_sim::cut;
use cutlab_sim::fem::FemMaterial;
use cutlab_sim::generate::{GridCells, boxed};
use cutlab_sim::model::{Material, Model};
use cutlab_sim::reference::{
    self, Elasticity, IPC_BARS, IPC_UNIT_M, Solid, cantilever, ipc_dir, patch_test, read_bar,
    vibration, wound_opening,
};
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::solver::{Integrator, Simulation, SolverSettings, StaticSettings};
use cutlab_sim::{Point3, Vector3};

const SOLID: Solid = Solid::CHEST_WALL;

#[test]
fn patch_test_uniform_strain_and_lateral_contraction_to_round_off() {
    // (the quadratic elements contain the linear field too: on the edge middles as on the corners)
    for kind in [Elasticity::CorotationalFem, Elasticity::QuadraticFem] {
        for cells in [
            GridCells {
                nx: 4,
                ny: 3,
                nz: 3,
            },
            GridCells {
                nx: 5,
                ny: 2,
                nz: 4,
            },
        ] {
            let r = patch_test(kind, SOLID, cells, 1e-3).expect("patch test");
            println!("{} {cells:?}: {r:?}", kind.name());
            assert!(r.displacement_error < 1e-10, "{r:?}");
            assert!(r.lateral_force < 1e-10, "{r:?}");
            assert!(r.axial_force_error < 1e-10, "{r:?}");
        }
    }
    // The springs reproduce the uniform displacement (the lattice is uniform) but not the
    // stress: forces appear on the lateral faces, and the axial force is off.
    for kind in [Elasticity::SpringsUniform, Elasticity::SpringsYoungs] {
        let r = patch_test(
            kind,
            SOLID,
            GridCells {
                nx: 4,
                ny: 3,
                nz: 3,
            },
            1e-3,
        )
        .expect("patch test");
        println!("{}: {r:?}", kind.name());
        assert!(r.lateral_force > 0.1 && r.axial_force_error > 0.1, "{r:?}");
    }
}

/// The goal of the accuracy work: the finite elements within 5 % of Timoshenko at the finest
/// IPC bar. Quadratic elements on the same meshes carry the bending the linear ones lock in.
#[test]
fn quadratic_elements_reach_the_cantilever_within_five_percent_on_the_finest_bar() {
    let results = cantilevers(Elasticity::QuadraticFem);
    assert!(results[2].relative_error < 0.05, "{:?}", results[2]);
    assert!(
        results[0].relative_error > results[2].relative_error,
        "{results:?}"
    );
    let linear =
        cantilever(bar(IPC_BARS[2]), Elasticity::CorotationalFem, SOLID).expect("cantilever");
    assert!(
        results[2].relative_error < 0.5 * linear.relative_error,
        "{:?} vs linear {linear:?}",
        results[2]
    );
}

#[test]
fn quadratic_elements_open_the_wound_as_fracture_mechanics_says() {
    let r = wound_opening(Elasticity::QuadraticFem, SOLID, 0.01, 4).expect("wound");
    println!(
        "quadratic: {} tets, centre gap {:.4e} m vs {:.4e} m: {:.2} %, profile {:.1} %",
        r.tets,
        r.centre_gap_m,
        r.analytic_centre_gap_m,
        100.0 * r.centre_error,
        100.0 * r.profile_error
    );
    assert!(r.centre_error < 0.05, "{r:?}");
    assert!(r.profile_error < 0.15, "{r:?}");
    assert!(
        vibration(
            bar(IPC_BARS[0]),
            Elasticity::QuadraticFem,
            SOLID,
            Integrator::ImplicitEuler,
            1e-3
        )
        .is_err(),
        "static only"
    );
}

fn bar(name: &str) -> cutlab_sim::TetMesh {
    read_bar(&ipc_dir().join(name), IPC_UNIT_M).expect("IPC bar")
}

/// The cantilever of `kind` on every IPC bar, printed.
fn cantilevers(kind: Elasticity) -> Vec<reference::CantileverResult> {
    let results: Vec<_> = IPC_BARS
        .iter()
        .map(|b| cantilever(bar(b), kind, SOLID).expect("cantilever"))
        .collect();
    for r in &results {
        println!(
            "{}: {} tets, delta {:.4e} m vs Timoshenko {:.4e} m, error {:.2} %",
            kind.name(),
            r.tets,
            r.deflection_m,
            r.analytic_m,
            100.0 * r.relative_error
        );
    }
    results
}

#[test]
fn cantilever_error_shrinks_with_refinement_on_the_ipc_bars() {
    let results = cantilevers(Elasticity::CorotationalFem);
    // linear tetrahedra are too stiff in bending (shear locking): the error falls like h^2
    assert!(results[0].relative_error > results[1].relative_error);
    assert!(results[1].relative_error > results[2].relative_error);
    assert!(results[2].relative_error < 0.30, "{:?}", results[2]);
    assert!(
        results.iter().all(|r| r.deflection_m < r.analytic_m),
        "too stiff, never too soft"
    );
    // Richardson extrapolation of the two finest (error ~ h^2, h ~ tets^(-1/3)) is within 5 %.
    let extrapolated = reference::richardson(&results[1], &results[2]);
    let error = (extrapolated - results[2].analytic_m).abs() / results[2].analytic_m;
    println!(
        "fem extrapolated: {extrapolated:.4e} m, error {:.1} %",
        100.0 * error
    );
    assert!(error < 0.05, "{error}");
    for kind in [Elasticity::SpringsUniform, Elasticity::SpringsYoungs] {
        cantilevers(kind);
    }
}

#[test]
fn wound_opening_of_a_prestressed_sheet_matches_fracture_mechanics() {
    let r = wound_opening(Elasticity::CorotationalFem, SOLID, 0.01, 8).expect("wound");
    println!(
        "fem: {} tets, centre gap {:.4e} m vs {:.4e} m: {:.1} %, profile {:.1} %",
        r.tets,
        r.centre_gap_m,
        r.analytic_centre_gap_m,
        100.0 * r.centre_error,
        100.0 * r.profile_error
    );
    assert!(r.centre_error < 0.05, "{r:?}");
    // the largest deviation is next to the tips, where the opening has its square-root
    // singularity and the elements are of the tip's size
    assert!(r.profile_error < 0.15, "{r:?}");
    for (x, gap, analytic) in &r.profile {
        if x.abs() < 0.5 * r.half_length_m {
            assert!(
                (gap - analytic).abs() < 0.05 * r.analytic_centre_gap_m,
                "x {x}: {gap} vs {analytic}"
            );
        }
    }
    let springs = wound_opening(Elasticity::SpringsUniform, SOLID, 0.01, 8).expect("wound");
    println!(
        "springs-uniform: centre {:.1} %, profile {:.1} %",
        100.0 * springs.centre_error,
        100.0 * springs.profile_error
    );
    // uniform springs on a graded mesh: far off
    assert!(springs.centre_error > 0.2);
}

#[test]
fn first_longitudinal_frequency_of_a_fixed_free_bar() {
    let mut errors = Vec::new();
    for b in &IPC_BARS[..2] {
        let r = vibration(
            bar(b),
            Elasticity::CorotationalFem,
            SOLID,
            Integrator::ImplicitEuler,
            1e-4,
        )
        .expect("vibration");
        println!(
            "fem: {} tets, f1 {:.3} Hz vs {:.3} Hz: {:.2} %",
            r.tets,
            r.frequency_hz,
            r.analytic_hz,
            100.0 * r.relative_error
        );
        errors.push(r.relative_error);
    }
    assert!(errors[1] < errors[0]);
    assert!(errors[1] < 0.03, "{errors:?}");
    let r = vibration(
        bar(IPC_BARS[1]),
        Elasticity::CorotationalFem,
        SOLID,
        Integrator::SymplecticEuler,
        1e-4,
    )
    .expect("vibration");
    println!("fem, symplectic: {:.2} %", 100.0 * r.relative_error);
    assert!(r.relative_error < 0.03, "{r:?}");
    let r = vibration(
        bar(IPC_BARS[1]),
        Elasticity::SpringsYoungs,
        SOLID,
        Integrator::ImplicitEuler,
        1e-4,
    )
    .expect("vibration");
    println!("springs-youngs: {:.2} %", 100.0 * r.relative_error);
}

fn fem_chest_wall(min_tets: usize, material: FemMaterial) -> Simulation {
    let scene = Scene::load(
        "chest-wall",
        BuildOptions {
            min_tets: Some(min_tets),
        },
    )
    .expect("built-in scene");
    let model = scene.model.clone().with_fem(&[(0, material)]).expect("fem");
    Simulation::new(model, scene.spec.solver)
}

#[test]
fn held_pretensioned_fem_body_stays_at_rest() {
    // explicit: without stiffness-proportional damping (beta K makes symplectic Euler take
    // thousands of sub-steps; the implicit integrator is the one to use with it)
    let cases = [
        (Integrator::ImplicitEuler, FemMaterial::CHEST_WALL),
        (
            Integrator::SymplecticEuler,
            FemMaterial {
                rayleigh_stiffness_s: 0.0,
                ..FemMaterial::CHEST_WALL
            },
        ),
    ];
    for (integrator, material) in cases {
        let mut sim = fem_chest_wall(2_000, material);
        sim.edit(|_, settings| settings.integrator = integrator);
        let report = sim.settle(StaticSettings::default());
        assert!(report.converged, "{report:?}");
        let moved = sim
            .state
            .positions
            .iter()
            .zip(sim.model.mesh.positions())
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(
            moved > 1e-4,
            "pre-tension moved the tissue by {moved} m only"
        );
        let start = sim.state.positions.clone();
        let mut max_speed = 0.0f64;
        for _ in 0..2_000 {
            sim.step().expect("step");
            max_speed = max_speed.max(sim.state.max_speed());
        }
        let drift = sim
            .state
            .positions
            .iter()
            .zip(&start)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        println!(
            "{}: max speed {max_speed:.2e} m/s, drift {drift:.2e} m",
            integrator.name()
        );
        assert!(max_speed < 1e-9, "{integrator:?}: max speed {max_speed}");
        assert!(drift < 1e-9, "{integrator:?}: drift {drift}");
    }
}

#[test]
fn fem_keeps_working_through_a_cut_and_the_wound_opens() {
    let g = boxed(
        Point3::origin(),
        [0.04, 0.04, 0.01],
        GridCells {
            nx: 8,
            ny: 8,
            nz: 2,
        },
    )
    .expect("slab");
    let material = Material {
        pretension: 0.04,
        ..Material::PAPER_CHEST_WALL
    };
    let model = Model::new(g.mesh, &[(0, material)], &g.rim, Vector3::zeros())
        .expect("model")
        .with_fem(&[(0, FemMaterial::CHEST_WALL)])
        .expect("fem");
    let mut sim = Simulation::new(model, SolverSettings::default());
    assert!(sim.settle(StaticSettings::default()).converged);
    let before = sim.state.positions.clone();
    let mut cutter = cut::Cutter::default();
    for k in 0..=12 {
        let next = cut::blade(
            Point3::new(0.008 + 0.002 * k as f64, 0.0223, -0.003),
            Vector3::z(),
            0.015,
        );
        cutter.advance(&mut sim, next).expect("cut");
        let fem = sim.model.fem.as_ref().expect("still finite elements");
        assert_eq!(
            fem.len(),
            sim.model.mesh.tet_count(),
            "elements rebuilt with the mesh"
        );
        for _ in 0..5 {
            sim.step().expect("stable after the cut");
        }
    }
    // the new elements got the pre-strained rest shape: a reference-shaped tet has F = I / (1 - s)
    let fem = sim.model.fem.as_ref().expect("fem");
    let x_ref = sim.model.mesh.positions();
    for t in 0..fem.len() {
        if fem.rest_volume_m3[t] > 0.0 {
            let f = fem.deformation_gradient(t, x_ref);
            assert!(
                (f - nalgebra::Matrix3::identity() / 0.96).norm() < 1e-6,
                "tet {t}: {f}"
            );
        }
    }
    let report = sim.settle(StaticSettings::default());
    assert!(report.converged, "{report:?}");
    assert!(
        sim.state
            .positions
            .iter()
            .all(|p| p.iter().all(|c| c.is_finite()))
    );
    // the wound gapes: vertices on either side of the cut plane y = 22.3 mm moved apart
    let n0 = before.len();
    let mut widest = 0.0f64;
    for ev in 0..sim.model.vertex_count() {
        let p = sim.state.positions[ev];
        if ev < n0 && (p.x - 0.02).abs() < 0.004 {
            widest = widest.max((p.y - before[ev].y).abs());
        }
    }
    assert!(widest > 1e-4, "the wound did not open: {widest} m");
}
