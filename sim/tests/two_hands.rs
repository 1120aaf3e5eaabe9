//! The second hand's instruments on the gauze (issue 66): a grasper holds and pulls, scissors
//! shear, a scalpel cuts the thin pad through in one pass.

use cutlab_sim::cut::{Cutter, Scissors, Specimen};
use cutlab_sim::grasp::{Grasp, GraspError, GraspSettings};
use cutlab_sim::mesh::pieces;
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::solver::{Simulation, StaticSettings};
use cutlab_sim::{Point3, Vector3};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};

/// Settled to a billionth of the largest spring force (the default's 1e-12 is round-off on
/// the slack pad between its clips).
const SETTLED: StaticSettings = StaticSettings {
    relative_force_tolerance: 1e-9,
    max_newton_iterations: 100,
};

/// The built-in gauze, settled.
fn gauze() -> Simulation {
    let scene = Scene::load("gauze", BuildOptions::default()).expect("the gauze scene");
    let mut sim = scene.simulation();
    assert!(sim.settle(SETTLED).converged);
    sim
}

/// The jaws at `p` (m), not turned.
fn jaws_at(p: Point3) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::from(p.coords), UnitQuaternion::identity())
}

/// The mid-plane of the 0.8 mm pad.
const MID_Z: f64 = 0.0004;

/// Lifts the jaws from `from` by `lift_m` along z over `steps` steps.
fn lift(sim: &mut Simulation, grasp: &mut Grasp, from: Point3, lift_m: f64, steps: usize) {
    for k in 1..=steps {
        let at = from + Vector3::z() * (lift_m * k as f64 / steps as f64);
        assert!(grasp.carry(sim, jaws_at(at)));
        sim.step().expect("a step");
    }
}

#[test]
fn held_gauze_follows_the_jaws_and_pulls_back_as_the_clips_hold_it() {
    let mut sim = gauze();
    let centre = Point3::new(0.05, 0.05, MID_Z);
    let clips: Vec<u32> = (0..sim.model.vertex_count() as u32)
        .filter(|&v| sim.model.held[v as usize])
        .collect();
    let mut grasp = Grasp::close(&mut sim, jaws_at(centre), GraspSettings::default())
        .expect("the jaws close on the pad");
    // through the pad's whole thickness, a 3 mm bite
    assert!(grasp.vertices().len() >= 6, "{:?}", grasp.vertices());
    let before: Vec<Point3> = grasp
        .vertices()
        .iter()
        .map(|&v| sim.state.positions[v as usize])
        .collect();
    let mut pulls = Vec::new();
    for lift_m in [0.004, 0.008] {
        let (from, by) = (grasp_centre(&grasp), lift_m - lifted(&grasp, centre));
        lift(&mut sim, &mut grasp, from, by, 100);
        assert!(sim.settle(SETTLED).converged);
        // every held particle where the jaws carry it: moved up by the lift, nothing else
        for (&v, b) in grasp.vertices().iter().zip(&before) {
            let d = sim.state.positions[v as usize] - b;
            assert!((d - Vector3::z() * lift_m).norm() < 1e-12, "{v}: {d:?}");
        }
        let forces = sim.particle_forces();
        let pull = grasp.pull_newtons(&sim);
        let on_clips: Vector3 = clips.iter().map(|&v| forces[v as usize]).sum();
        // the tissue pulls the jaws back down, towards the pad (and a little along the mesh's
        // diagonals, which all run one way in its cells)
        assert!(
            pull.z < 0.0 && pull.z.abs() > 2.0 * pull.xy().norm(),
            "{pull:?}"
        );
        // at rest and weightless, the jaws and the clips hold the pad against each other
        assert!(
            (pull + on_clips).norm() <= 1e-6 * pull.norm(),
            "pull {pull:?} clips {on_clips:?}"
        );
        pulls.push(pull.z.abs());
    }
    // lifted twice as far, pulled harder (a pre-tensioned membrane stiffens as it is drawn)
    assert!(pulls[1] > 1.5 * pulls[0], "{pulls:?}");
}

/// How far the jaws have been lifted from `centre`, m.
fn lifted(grasp: &Grasp, centre: Point3) -> f64 {
    grasp.world_from_jaw().translation.vector.z - centre.z
}

/// Where the jaws are.
fn grasp_centre(grasp: &Grasp) -> Point3 {
    Point3::from(grasp.world_from_jaw().translation.vector)
}

#[test]
fn released_gauze_relaxes_back_into_its_plane() {
    let mut sim = gauze();
    let centre = Point3::new(0.05, 0.05, MID_Z);
    let rest = sim.state.positions.clone();
    let mut grasp =
        Grasp::close(&mut sim, jaws_at(centre), GraspSettings::default()).expect("closed");
    lift(&mut sim, &mut grasp, centre, 0.006, 200);
    let held = grasp.vertices().to_vec();
    let off = |sim: &Simulation| {
        held.iter()
            .map(|&v| (sim.state.positions[v as usize] - rest[v as usize]).norm())
            .fold(0.0, f64::max)
    };
    assert!((off(&sim) - 0.006).abs() < 1e-9);
    grasp.release(&mut sim);
    assert!(held.iter().all(|&v| !sim.model.held[v as usize]));
    assert!(held.iter().all(|&v| sim.model.inv_mass[v as usize] > 0.0));
    for _ in 0..2000 {
        sim.step().expect("a step");
    }
    // back within a twentieth of the lift after 2 s
    assert!(off(&sim) < 0.05 * 0.006, "{} m off", off(&sim));
}

#[test]
fn the_pad_slips_out_of_the_jaws_past_the_slip_force() {
    let mut sim = gauze();
    let centre = Point3::new(0.05, 0.05, MID_Z);
    let settings = GraspSettings {
        slip_force_newtons: 0.1,
        ..GraspSettings::default()
    };
    let mut grasp = Grasp::close(&mut sim, jaws_at(centre), settings).expect("closed");
    assert!(!grasp.slips(&grasp.pull_newtons(&sim)));
    let mut slipped_at = None;
    for k in 1..=600 {
        let at = centre + Vector3::z() * (0.00005 * k as f64);
        grasp.carry(&mut sim, jaws_at(at));
        sim.step().expect("a step");
        if grasp.slips(&grasp.pull_newtons(&sim)) {
            slipped_at = Some(at.z - centre.z);
            break;
        }
    }
    let lifted_m = slipped_at.expect("a 30 mm lift pulls harder than 0.1 N");
    assert!(lifted_m > 0.004, "slipped at {lifted_m} m");
}

#[test]
fn jaws_on_nothing_or_at_no_place_take_nothing_and_change_nothing() {
    let mut sim = gauze();
    let before = sim.model.held.clone();
    let above = jaws_at(Point3::new(0.05, 0.05, 0.02));
    assert_eq!(
        Grasp::close(&mut sim, above, GraspSettings::default()),
        Err(GraspError::NothingInJaws { radius_mm: 3.0 })
    );
    let nowhere = jaws_at(Point3::new(f64::NAN, 0.05, MID_Z));
    assert_eq!(
        Grasp::close(&mut sim, nowhere, GraspSettings::default()),
        Err(GraspError::Invalid)
    );
    assert_eq!(sim.model.held, before);
    // a NaN pose while holding: the jaws stay where they were
    let centre = jaws_at(Point3::new(0.05, 0.05, MID_Z));
    let mut grasp = Grasp::close(&mut sim, centre, GraspSettings::default()).expect("closed");
    let x = sim.state.positions.clone();
    assert!(!grasp.carry(&mut sim, nowhere));
    assert_eq!(sim.state.positions, x);
    assert_eq!(grasp.world_from_jaw(), &centre);
}

/// Closures round a regular polygon of `sides` about the pad's centre, radius `r_m`, each
/// from one corner to the next (a millimetre past it); steps between cuts as a hand closes.
fn cut_polygon_with_scissors(sim: &mut Simulation, sides: usize, r_m: f64) -> (usize, usize) {
    let (freed, closures) = cut_polygon(sim, None, sides, r_m);
    (freed.len(), closures)
}

/// As [`cut_polygon_with_scissors`], the jaws holding `grasp` meanwhile when there is one (the
/// cutter told before each closure, the grasp taking the copies the closure split off what
/// it holds and a piece freed in it whole, as the session's stepper does): the specimens
/// freed, and the closures made.
fn cut_polygon(
    sim: &mut Simulation,
    mut grasp: Option<&mut Grasp>,
    sides: usize,
    r_m: f64,
) -> (Vec<Specimen>, usize) {
    let corner = |k: usize| {
        let a = std::f64::consts::TAU * k as f64 / sides as f64;
        Point3::new(0.05 + r_m * a.cos(), 0.05 + r_m * a.sin(), MID_Z)
    };
    let mut cutter = Cutter::default();
    let (mut freed, mut closures) = (Vec::new(), 0);
    for k in 0..sides {
        let (a, b) = (corner(k), corner(k + 1));
        let mut scissors = Scissors::laparoscopic(a, b - a, Vector3::z().cross(&(b - a)));
        scissors.blade_length_m = (b - a).norm() + 0.001;
        if let Some(g) = grasp.as_deref() {
            cutter.hold_in_jaws(g.vertices());
        }
        let events = scissors
            .close(sim, &mut cutter, 2)
            .expect("the closure cuts");
        for e in &events {
            if let Some(g) = grasp.as_deref_mut() {
                g.adopt_cut(sim, e);
                for s in e.specimens.iter().filter(|s| s.in_jaws) {
                    g.take_hold_of(sim, &s.vertices);
                }
            }
            freed.extend(e.specimens.iter().cloned());
        }
        closures += 1;
    }
    (freed, closures)
}

/// FLS pattern cutting as it is done: the grasper holds the disc while the scissors go round
/// it. The jaws anchor nothing: the last closure frees the disc, once, which stays in the
/// jaws where it was (not set aside), is taken into them whole and rises with them; the pad
/// stays on its clips.
#[test]
fn a_disc_held_in_the_jaws_is_freed_and_stays_in_them() {
    let mut sim = gauze();
    let centre = Point3::new(0.05, 0.05, MID_Z);
    let mut grasp = Grasp::close(&mut sim, jaws_at(centre), GraspSettings::default())
        .expect("the jaws close on the pad");
    let (freed, closures) = cut_polygon(&mut sim, Some(&mut grasp), 10, 0.02);
    assert_eq!(closures, 10);
    assert_eq!(freed.len(), 1, "one disc freed by ten closures: {freed:?}");
    let disc = &freed[0];
    assert!(disc.in_jaws && disc.lift_m == [0.0; 3], "{disc:?}");
    assert!(
        grasp
            .vertices()
            .iter()
            .all(|v| disc.vertices.binary_search(v).is_ok()),
        "the jaws hold the disc"
    );
    assert_eq!(
        grasp.vertices(),
        &disc.vertices[..],
        "the jaws took the disc whole"
    );
    let in_disc = |v: u32| disc.vertices.binary_search(&v).is_ok();
    let mean_z = |sim: &Simulation, disc: bool| {
        let zs: Vec<f64> = (0..sim.model.vertex_count() as u32)
            .filter(|&v| in_disc(v) == disc)
            .map(|v| sim.state.positions[v as usize].z)
            .collect();
        zs.iter().sum::<f64>() / zs.len() as f64
    };
    let (disc_z, pad_z) = (mean_z(&sim, true), mean_z(&sim, false));
    lift(&mut sim, &mut grasp, centre, 0.01, 20);
    for _ in 0..40 {
        sim.step().expect("a step");
    }
    assert!(sim.state.is_finite());
    let rose_m = mean_z(&sim, true) - disc_z;
    assert!(
        (rose_m - 0.01).abs() < 1e-9,
        "the disc rose {} mm with the jaws' 10 mm",
        rose_m * 1e3
    );
    let pad_m = (mean_z(&sim, false) - pad_z).abs();
    assert!(pad_m < 0.0005, "the pad moved {} mm", pad_m * 1e3);
}

#[test]
fn scissors_cut_a_disc_out_of_the_gauze_a_closure_a_side() {
    let mut sim = gauze();
    let (freed, closures) = cut_polygon_with_scissors(&mut sim, 10, 0.02);
    assert_eq!(closures, 10);
    assert_eq!(freed, 1, "one disc freed by ten closures");
    assert_eq!(pieces(&sim.model.mesh, &sim.model.held).len(), 2);
    assert!(sim.state.is_finite());
}

#[test]
fn one_closure_shears_the_pad_along_the_blades_only() {
    let mut sim = gauze();
    let pivot = Point3::new(0.04, 0.05, MID_Z);
    let scissors = Scissors::laparoscopic(pivot, Vector3::x(), Vector3::y());
    // the open blades stand further from the axis than the pad is thick
    assert!(scissors.gap_m() > 0.0008);
    let mut cutter = Cutter::default();
    let events = scissors
        .close(&mut sim, &mut cutter, 2)
        .expect("the closure cuts");
    let split: Vec<Point3> = events
        .iter()
        .flat_map(|e| e.vertices_split.iter())
        .map(|s| sim.state.positions[s.original as usize])
        .collect();
    assert!(!split.is_empty());
    // the pad parted where the blades met it, from the pivot to the tips and nowhere else
    let xs = split.iter().map(|p| p.x);
    let (lo, hi) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| {
        (l.min(x), h.max(x))
    });
    assert!(lo >= 0.04 - 0.0025 && hi <= 0.055 + 0.0025, "{lo}..{hi}");
    // (the pad's vertices stand 2 mm apart)
    assert!(
        hi - lo >= 0.015 - 2.0 * 0.002,
        "parted over {} mm",
        (hi - lo) * 1e3
    );
    assert!(split.iter().all(|p| (p.y - 0.05).abs() < 0.0025));
    // a closure with the scissors at no place cuts nothing
    let bad = Scissors {
        pivot_m: Point3::new(f64::NAN, 0.0, 0.0),
        ..scissors
    };
    let tets = sim.model.mesh.tet_count();
    assert!(bad.close(&mut sim, &mut cutter, 2).is_err());
    assert_eq!(sim.model.mesh.tet_count(), tets);
}

/// The disc freed in the jaws and let go of is a free piece of the mesh; later cuts, beside
/// it on the pad or through it, do not free it (or its halves) again.
#[test]
fn a_disc_let_go_of_is_not_freed_again_by_later_cuts() {
    let mut sim = gauze();
    let centre = Point3::new(0.05, 0.05, MID_Z);
    let mut grasp = Grasp::close(&mut sim, jaws_at(centre), GraspSettings::default())
        .expect("the jaws close on the pad");
    let (freed, _) = cut_polygon(&mut sim, Some(&mut grasp), 10, 0.02);
    assert_eq!(freed.len(), 1, "the disc freed once");
    grasp.release(&mut sim);
    for _ in 0..5 {
        sim.step().expect("a step");
    }
    let mut cutter = Cutter::default();
    // beside the disc on the pad, then across the disc's middle
    for (pivot, along) in [
        (Point3::new(0.08, 0.015, MID_Z), Vector3::y()),
        (Point3::new(0.04, 0.05, MID_Z), Vector3::x()),
    ] {
        let scissors = Scissors::laparoscopic(pivot, along, Vector3::z().cross(&along));
        let events = scissors
            .close(&mut sim, &mut cutter, 2)
            .expect("the closure cuts");
        assert!(
            events.iter().any(|e| !e.vertices_split.is_empty()),
            "it cut"
        );
        let again: Vec<f64> = events
            .iter()
            .flat_map(|e| &e.specimens)
            .map(|s| s.volume_m3 * 1e9)
            .collect();
        assert!(again.is_empty(), "freed again, mm^3: {again:?}");
    }
    assert!(sim.state.is_finite());
}
