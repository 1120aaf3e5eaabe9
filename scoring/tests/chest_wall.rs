//! The metrics on a really cut chest wall: the demo's scripted incision (60 mm along x, 8 mm
//! deep, the blade normal to the curved surface) on the default `chest-wall` (12.8k tets), assessed against the built-in plan. The opening width from
//! ray casts must agree with the gap between the split vertices' copies, and the plan's target
//! (the incision open to half its depth) is hidden before the cut and seen after it.

use cutlab_scoring::metrics::value_of;
use cutlab_scoring::{AttemptData, CutSample, ExercisePlan, SurfaceMesh};
use cutlab_sim::cut;
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::solver::StaticSettings;

#[test]
fn the_demo_incision_scores_well_and_its_opening_matches_the_vertex_gap() {
    let scene = Scene::load("chest-wall", BuildOptions { min_tets: None }).expect("scene");
    let mut sim = scene.simulation();
    assert!(sim.settle(StaticSettings::default()).converged);
    let plan = ExercisePlan::chest_wall().expect("plan");
    // the settled tissue, not cut: the incision's target is hidden
    let uncut = AttemptData {
        surface: Some(surface(&sim)),
        ..AttemptData::default()
    };
    let before = plan.assess(&uncut).expect("assess the uncut tissue");
    assert_eq!(
        value_of(&before, "target_visible_fraction"),
        Some(0.0),
        "{before:?}"
    );
    let depth = 0.008;
    let steps = 1500;
    let mut cutter = cut::Cutter::default();
    let mut data = AttemptData::default();
    for k in 0..steps + 500 {
        if k <= steps {
            let x = -0.03 + 0.06 * k as f64 / steps as f64;
            let blade = cut::Blade::normal_to_curved_slab(x, 0.0003, 0.15, depth, 0.005);
            let (tip, outward) = (blade.tip, blade.edge_direction);
            if cutter.advance(&mut sim, blade).is_ok() && k % 12 == 0 {
                data.cuts.push(CutSample {
                    t_s: k as f64 * 1e-3,
                    tip_m: [tip.x, tip.y, tip.z],
                    edge_dir: [outward.x, outward.y, outward.z],
                    depth_m: depth,
                    stroke: None,
                });
            }
        }
        sim.step().expect("step");
    }
    assert!(sim.settle(StaticSettings::default()).converged);
    let widest_gap = cut::wound_gaps(&sim)
        .into_iter()
        .map(|(_, gap)| gap)
        .fold(0.0, f64::max);
    data.surface = Some(surface(&sim));

    let m = plan.assess(&data).expect("assess");
    let get = |k: &str| value_of(&m, k).unwrap_or_else(|| panic!("{k} missing: {m:?}"));
    let width = get("opening_width_m");
    println!(
        "opening width {:.2} mm, area {:.1} mm^2, widest vertex gap {:.2} mm",
        width * 1e3,
        get("opening_area_m2") * 1e6,
        widest_gap * 1e3
    );
    assert!(widest_gap > 5e-4, "the wound opens: {widest_gap}");
    // the ray-cast width is measured at half the planned depth, the vertex gap anywhere
    assert!(
        width > 0.4 * widest_gap && width < 1.5 * widest_gap + 3e-4,
        "width {width} vs gap {widest_gap}"
    );
    assert!(
        get("opening_area_m2") > 0.3 * width * 0.06,
        "open along most of the line"
    );
    // the incision lies open to half its depth along its middle: the target is seen
    let visible = get("target_visible_fraction");
    println!("target visible {:.0} %", visible * 100.0);
    assert!(visible > 0.5, "{visible}");
    assert!(get("lateral_max_m") < 5e-4);
    assert!(get("fraction_cut_in_tolerance") > 0.98);
    assert!(get("entry_error_m") < 1e-3 && get("exit_error_m") < 1e-3);
    assert!(get("direction_error_deg") < 1.0);
}

/// The boundary of `sim`'s mesh at its current positions.
fn surface(sim: &cutlab_sim::solver::Simulation) -> SurfaceMesh {
    SurfaceMesh::of(sim)
}
