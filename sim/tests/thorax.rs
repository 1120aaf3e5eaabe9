//! The `thorax` scene (issue 62): a layered chest wall whose ribs, cartilages and sternum a
//! scalpel does not cut. A blade over a rib stops on it; in an intercostal space it goes
//! through to the pleura.

use cutlab_sim::cut::{self, Cutter};
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::{Point3, Vector3};

fn thorax() -> Scene {
    Scene::load("thorax", BuildOptions::default()).expect("the thorax scene")
}

#[test]
fn the_thorax_has_its_layers_and_its_ribs_on_the_grid() {
    let scene = thorax();
    let model = &scene.model;
    let mesh = &model.mesh;
    assert_eq!(model.uncuttable_regions, vec![6, 7, 8]);
    assert_eq!(mesh.region_ids(), (1..=9).collect::<Vec<u32>>());
    assert!(
        (15_000..40_000).contains(&mesh.tet_count()),
        "{}",
        mesh.tet_count()
    );
    let (lo, hi) = mesh.bounding_box();
    assert!(
        hi.z.abs() < 1e-12 && (lo.z + 0.040).abs() < 1e-12,
        "{lo} {hi}"
    );
    for (t, tet) in mesh.tets().iter().enumerate() {
        let region = mesh.regions()[t];
        if !(6..=8).contains(&region) {
            continue;
        }
        assert!(model.uncuttable(t));
        for &v in tet {
            let p = mesh.positions()[v as usize];
            // the bones fill the rib layer, their faces on the grid's planes
            assert!(
                (-0.039 - 1e-12..=-0.029 + 1e-12).contains(&p.z),
                "tet {t} of region {region} at {p}"
            );
        }
    }
    let rib_volume: f64 = mesh
        .tets()
        .iter()
        .enumerate()
        .filter(|(t, _)| mesh.regions()[*t] == 6)
        .map(|(_, tet)| {
            let p = tet.map(|v| mesh.positions()[v as usize]);
            cutlab_sim::mesh::tet_signed_volume(&p[0], &p[1], &p[2], &p[3]).abs()
        })
        .sum();
    // four ribs 75 x 10 x 10 mm
    assert!(
        (rib_volume - 4.0 * 75e-9 * 100.0).abs() < 1e-9,
        "{rib_volume}"
    );
}

/// Deepest point (most negative z) of the vertices the stroke created, and where the blade
/// last stopped.
fn stroke_across_at(y_m: f64) -> (f64, Option<u32>, usize) {
    let scene = thorax();
    let mut sim = scene.simulation();
    let mut cutter = Cutter::default();
    let (mut deepest, mut stop, mut stops) = (0.0f64, None, 0);
    for k in 0..=20 {
        // lateral of the cartilages: over bone or over the space between two ribs; the tip
        // 5 mm beyond the pleura, the edge 60 mm long
        let x = -0.010 + 0.002 * k as f64;
        let blade = cut::blade(Point3::new(x, y_m, -0.045), Vector3::z(), 0.06);
        let before = sim.model.clone();
        let event = cutter.advance(&mut sim, blade).expect("a cut");
        for t in &event.tets_removed {
            assert!(
                !before.uncuttable(*t as usize),
                "tet {t} of region {} was split at step {k}: {:?}; removed {:?}",
                before.mesh.regions()[*t as usize],
                before.mesh.tets()[*t as usize].map(|v| before.mesh.positions()[v as usize]),
                event.tets_removed.len()
            );
        }
        for v in &event.vertices_created {
            deepest = deepest.min(sim.model.mesh.positions()[v.id as usize].z);
        }
        if let Some(s) = cutter.stop() {
            stop = Some(s.region);
            stops += 1;
        }
    }
    (deepest, stop, stops)
}

#[test]
fn a_blade_over_a_rib_stops_on_it() {
    // over the 4th rib (y 5 to 15 mm), off the grid's planes
    let (deepest, stop, stops) = stroke_across_at(0.0115);
    assert_eq!(stop, Some(6), "the blade stopped on the rib");
    assert_eq!(stops, 21, "every pose");
    assert!(deepest < -0.020, "it cut the layers above: {deepest}");
    assert!(deepest > -0.029, "and not into the rib: {deepest}");
}

#[test]
fn a_blade_in_an_intercostal_space_cuts_through_the_pleura() {
    // the 3rd intercostal space (y 15 to 30 mm)
    let (deepest, stop, _) = stroke_across_at(0.0225);
    assert_eq!(stop, None);
    assert!(deepest < -0.0395, "through the pleura: {deepest}");
}

/// A retractor in an incision through the 4th space (y -10 to 5 mm) spreads the skin's edges
/// to its width at the middle, carries nothing in the rib layer nearer the ribs than its
/// clearance, and the body stays finite while it holds.
#[test]
fn a_retractor_spreads_the_wound_to_its_width_and_not_into_the_ribs() {
    use cutlab_sim::retractor::{BONE_CLEARANCE_M, Retractor};
    let scene = thorax();
    let mut sim = scene.simulation();
    let mut cutter = Cutter::default();
    let y = -0.0025;
    for k in 0..=50 {
        let x = -0.020 + 0.001 * k as f64;
        let blade = cut::blade(Point3::new(x, y, -0.045), Vector3::z(), 0.065);
        let _ = cutter.advance(&mut sim, blade);
        sim.step().expect("a step");
    }
    let retractor = Retractor {
        line_m: vec![Point3::new(-0.020, y, 0.0), Point3::new(0.030, y, 0.0)],
        up: Vector3::z(),
        width_m: 0.020,
    };
    let grip = retractor.open(&mut sim).expect("it opens");
    assert!(grip.vertices.len() > 20, "{} gripped", grip.vertices.len());
    let rest = sim.model.mesh.positions().to_vec();
    let skin_middle: Vec<f64> = grip
        .vertices
        .iter()
        .map(|&v| sim.state.positions[v as usize])
        .filter(|p| p.z > -0.003 && (p.x - 0.005).abs() < 0.003)
        .map(|p| p.y - y)
        .collect();
    let gap = skin_middle.iter().fold(0.0f64, |a, &b| a.max(b))
        - skin_middle.iter().fold(0.0f64, |a, &b| a.min(b));
    assert!((gap - 0.020).abs() < 0.001, "the skin opened to {gap} m");
    // the 4th space runs from y = -10 to 5 mm between the ribs' faces
    for (i, &v) in grip.vertices.iter().enumerate() {
        if rest[v as usize].z < -0.029 && rest[v as usize].z > -0.039 {
            let to = grip.to_m[i].y;
            assert!(
                to < 0.005 - BONE_CLEARANCE_M + 1e-9 && to > -0.010 + BONE_CLEARANCE_M - 1e-9,
                "particle {v} carried to y = {to} into a rib"
            );
        }
    }
    assert!(sim.state.is_finite());
    assert!(grip.vertices.iter().all(|&v| sim.model.held[v as usize]));
}
