//! Resuming a simulation from a captured step continues bit for bit as the original run,
//! whole-body and localised, in the middle of a cutting stroke.

use cutlab_sim::cut::{Blade, Cutter, CutterResume};
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::solver::SweepOrder;
use cutlab_sim::solver::{LocalisationSettings, ResumeState, Simulation, StaticSettings};
use cutlab_sim::{Point3, TetMesh, Vector3};

fn settled_wall() -> Simulation {
    let scene = Scene::load(
        "chest-wall",
        BuildOptions {
            min_tets: Some(1_500),
        },
    )
    .expect("chest wall");
    let mut sim = scene.simulation();
    assert!(sim.settle(StaticSettings::default()).converged);
    sim
}

/// Step `k` of the scripted stroke: the blade drawn along the wall, pressing the surface
/// around the tip, cutting, then one step.
fn stroke_step(sim: &mut Simulation, cutter: &mut Cutter, k: usize) {
    press_and_cut(sim, cutter, k);
    sim.step().expect("step");
}

/// [`stroke_step`] without its step.
fn press_and_cut(sim: &mut Simulation, cutter: &mut Cutter, k: usize) {
    let x = -0.02 + 0.04 * k as f64 / 800.0;
    let blade = Blade::normal_to_curved_slab(x, 0.0, 0.15, 0.008, 0.005);
    sim.clear_external_forces();
    sim.set_focus(&[blade.tip]);
    let near: Vec<u32> = sim
        .model
        .mesh
        .topology()
        .boundary_vertices()
        .into_iter()
        .filter(|&v| (sim.state.positions[v as usize] - blade.tip).norm() < 0.012)
        .collect();
    for v in near {
        sim.add_external_force(v, Vector3::new(0.0, 0.0, -0.02));
    }
    if k >= 100 {
        cutter.advance(sim, blade).expect("cut");
    }
}

type Captured = (TetMesh, cutlab_sim::model::State, ResumeState, CutterResume);

/// The captures: before the stroke, early in it and later in it.
const CAPTURES: [usize; 5] = [49, 149, 249, 349, 499];
const STEPS: usize = 700;

fn run_and_compare(localised: bool) {
    let mut sim = settled_wall();
    if localised {
        sim.settings.localisation = Some(LocalisationSettings::default());
    }
    let mut cutter = Cutter::default();
    let mut captured: Vec<(usize, Captured)> = Vec::new();
    let mut original = Vec::new();
    for k in 0..STEPS {
        stroke_step(&mut sim, &mut cutter, k);
        if CAPTURES.contains(&k) {
            // through JSON, as a recording's keyframe carries it
            let r: ResumeState =
                serde_json::from_str(&serde_json::to_string(&sim.resume_state()).expect("encode"))
                    .expect("decode");
            let c: CutterResume = serde_json::from_str(
                &serde_json::to_string(&cutter.resume_state()).expect("encode"),
            )
            .expect("decode");
            assert!(
                k < 100 || (!c.trail.is_empty() && !c.stroke.is_empty()),
                "captured mid-stroke"
            );
            assert_eq!(r.region.is_some(), localised);
            captured.push((k, (sim.model.mesh.clone(), sim.state.clone(), r, c)));
        }
        original.push((sim.state.bit_hash(), sim.model.mesh.tets().to_vec()));
    }
    assert!(
        sim.model.mesh.tet_count() > 1_600,
        "the stroke cut: {} tets",
        sim.model.mesh.tet_count()
    );

    for (at, (mesh, state, r, c)) in captured {
        let mut resumed = settled_wall();
        if localised {
            resumed.settings.localisation = Some(LocalisationSettings::default());
        }
        if at == 349 {
            // a resume state that does not fit is refused, and the simulation is left as it was
            let before = resumed.state.bit_hash();
            let mut short = state.clone();
            short.positions.pop();
            assert!(resumed.resume(mesh.clone(), short, &r).is_err());
            let mut bad = r.clone();
            bad.held.push(u32::MAX);
            assert!(resumed.resume(mesh.clone(), state.clone(), &bad).is_err());
            assert_eq!(resumed.state.bit_hash(), before);
        }
        resumed.resume(mesh, state, &r).expect("resume");
        let mut cutter = Cutter::default();
        cutter
            .resume(&c, resumed.model.vertex_count())
            .expect("cutter");
        for k in at + 1..STEPS {
            stroke_step(&mut resumed, &mut cutter, k);
            let (hash, tets) = &original[k];
            assert!(
                resumed.state.bit_hash() == *hash && resumed.model.mesh.tets() == &tets[..],
                "localised {localised}: resumed after step {at}, the run differs at step {k}"
            );
        }
    }
}

#[test]
fn a_whole_body_run_resumed_mid_stroke_continues_bit_for_bit() {
    run_and_compare(false);
}

#[test]
fn a_localised_run_resumed_mid_stroke_continues_bit_for_bit() {
    run_and_compare(true);
}

#[test]
fn a_whole_body_run_captured_between_a_cut_and_its_step_resumes_bit_for_bit() {
    // the sweep order then covers fewer particles than the mesh (the cut's new ones get their
    // parts at the next step), and must still be accepted and continued as the run does
    let mut sim = settled_wall();
    let mut cutter = Cutter::default();
    for k in 0..140 {
        stroke_step(&mut sim, &mut cutter, k);
    }
    let before = sim.model.vertex_count();
    let mut k = 140;
    while sim.model.vertex_count() == before {
        sim.step().expect("step");
        k += 1;
        press_and_cut(&mut sim, &mut cutter, k);
    }
    let r: ResumeState =
        serde_json::from_str(&serde_json::to_string(&sim.resume_state()).expect("encode"))
            .expect("decode");
    let parts = r
        .sweep_order
        .as_ref()
        .expect("a whole-body step laid the sweep order out")
        .parts
        .len();
    assert!(
        parts < sim.model.vertex_count(),
        "{parts} parts for {} particles",
        sim.model.vertex_count()
    );
    let c = cutter.resume_state();
    let mut resumed = settled_wall();
    resumed
        .resume(sim.model.mesh.clone(), sim.state.clone(), &r)
        .expect("resume");
    let mut resumed_cutter = Cutter::default();
    resumed_cutter
        .resume(&c, resumed.model.vertex_count())
        .expect("cutter");
    // (the press is the session's input, not state: both step without it once)
    sim.clear_external_forces();
    sim.step().expect("step");
    resumed.step().expect("step");
    assert!(
        resumed.state.bit_hash() == sim.state.bit_hash(),
        "differs at the step after the cut"
    );
    for j in k + 1..k + 60 {
        stroke_step(&mut sim, &mut cutter, j);
        stroke_step(&mut resumed, &mut resumed_cutter, j);
        assert!(
            resumed.state.bit_hash() == sim.state.bit_hash()
                && resumed.model.mesh.tets() == sim.model.mesh.tets(),
            "differs at step {j}"
        );
    }
}

#[test]
fn a_resume_state_is_checked_against_its_mesh() {
    let mut sim = settled_wall();
    sim.settings.localisation = Some(LocalisationSettings::default());
    sim.set_focus(&[Point3::new(0.0, 0.0, 0.0)]);
    sim.step().expect("step");
    let r = sim.resume_state();
    let region = r.region.clone().expect("localised");
    let (mesh, state) = (sim.model.mesh.clone(), sim.state.clone());
    let n = mesh.vertex_count() as u32;
    let cases: Vec<(&str, ResumeState)> = vec![
        (
            "awake out of range",
            ResumeState {
                region: Some(cutlab_sim::solver::RegionResume {
                    awake: vec![n],
                    ..region.clone()
                }),
                ..r.clone()
            },
        ),
        (
            "sub-body unsorted",
            ResumeState {
                region: Some(cutlab_sim::solver::RegionResume {
                    sub_body: region.sub_body.iter().rev().copied().collect(),
                    ..region.clone()
                }),
                ..r.clone()
            },
        ),
        (
            "warm start too long",
            ResumeState {
                warm_start: cutlab_sim::solver::WarmStart {
                    count: 1,
                    rows: vec![[Vector3::zeros(); 4]; n as usize + 1],
                    cg_residual_ratio: 0.0,
                },
                ..r.clone()
            },
        ),
        (
            "warm start count",
            ResumeState {
                warm_start: cutlab_sim::solver::WarmStart {
                    count: 5,
                    rows: Vec::new(),
                    cg_residual_ratio: 0.0,
                },
                ..r.clone()
            },
        ),
        (
            "CG residual ratio",
            ResumeState {
                warm_start: cutlab_sim::solver::WarmStart {
                    cg_residual_ratio: f64::NAN,
                    ..r.warm_start.clone()
                },
                ..r.clone()
            },
        ),
        (
            "sweep order too long",
            ResumeState {
                sweep_order: Some(SweepOrder {
                    parts: vec![0; n as usize + 1],
                    separator_when_dissected: 0,
                }),
                ..r.clone()
            },
        ),
        (
            "sweep order part",
            ResumeState {
                sweep_order: Some(SweepOrder {
                    parts: vec![3; n as usize],
                    separator_when_dissected: 0,
                }),
                ..r.clone()
            },
        ),
        (
            "sweep order separator",
            ResumeState {
                sweep_order: Some(SweepOrder {
                    parts: vec![0; n as usize],
                    separator_when_dissected: usize::MAX,
                }),
                ..r.clone()
            },
        ),
    ];
    for (what, bad) in cases {
        let mut s = sim.clone();
        let err = s.resume(mesh.clone(), state.clone(), &bad);
        assert!(err.is_err(), "{what}: accepted");
    }
    let mut nan = state.clone();
    nan.velocities[0].x = f64::NAN;
    assert!(
        sim.clone().resume(mesh.clone(), nan, &r).is_err(),
        "a non-finite velocity"
    );
    sim.clone()
        .resume(mesh, state, &r)
        .expect("the captured state itself");
}

#[test]
fn a_run_resumed_while_the_blade_is_lifted_rejoins_the_stroke_bit_for_bit() {
    // the blade cuts, is lifted for 40 steps and pressed again where it was: captured while
    // it is out, the resumed run continues the same stroke as the original
    let blade_at = |k: usize| {
        let x =
            -0.02 + 0.04 * k.min(399) as f64 / 800.0 + 0.04 * k.saturating_sub(440) as f64 / 800.0;
        Blade::normal_to_curved_slab(x, 0.0, 0.15, 0.008, 0.005)
    };
    let run = |sim: &mut Simulation, cutter: &mut Cutter, k: usize| {
        if (100..400).contains(&k) || k >= 440 {
            cutter.advance(sim, blade_at(k)).expect("cut");
        } else if k == 400 {
            cutter.end_stroke();
        }
        sim.step().expect("step");
    };
    let mut sim = settled_wall();
    let mut cutter = Cutter::default();
    let mut original = Vec::new();
    let mut captured = None;
    for k in 0..600 {
        run(&mut sim, &mut cutter, k);
        if k == 420 {
            let c: CutterResume = serde_json::from_str(
                &serde_json::to_string(&cutter.resume_state()).expect("encode"),
            )
            .expect("decode");
            assert!(
                c.trail.is_empty() && c.ended.is_some(),
                "captured with the blade out"
            );
            captured = Some((
                sim.model.mesh.clone(),
                sim.state.clone(),
                sim.resume_state(),
                c,
            ));
        }
        original.push((sim.state.bit_hash(), sim.model.mesh.tets().to_vec()));
    }
    let (mesh, state, r, c) = captured.expect("captured");
    let mut resumed = settled_wall();
    resumed.resume(mesh, state, &r).expect("resume");
    let mut cutter = Cutter::default();
    cutter
        .resume(&c, resumed.model.vertex_count())
        .expect("cutter");
    for k in 421..600 {
        run(&mut resumed, &mut cutter, k);
        assert!(
            resumed.state.bit_hash() == original[k].0
                && resumed.model.mesh.tets() == &original[k].1[..],
            "resumed with the blade out, the run differs at step {k}"
        );
    }
    // an ended stroke naming a vertex the mesh does not have is refused
    let mut bad = cutter.resume_state();
    bad.ended = Some(cutlab_sim::cut::EndedStroke {
        trail: Vec::new(),
        stroke: vec![u32::MAX],
    });
    assert!(
        Cutter::default()
            .resume(&bad, resumed.model.vertex_count())
            .is_err()
    );
}
