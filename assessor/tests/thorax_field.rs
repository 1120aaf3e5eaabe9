//! The field measured on the opened wound of the `thorax` (issue 62): an incision through the
//! 4th intercostal space, opened by the layers' tension, shows the heart; the same stroke over
//! a rib, where the blade stops on the bone, shows nothing. Neither refers to a plan.

use cutlab_assessor::metrics::exposure::{Ellipsoid, Exposure, exposure};
use cutlab_sim::cut::{self, Cutter};
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::{Point3, Vector3};
use parry3d_f64::math::Vector as PVec;
use parry3d_f64::shape::TriMesh;

/// A 50 mm stroke across the chest at `y_m`, the blade's tip 5 mm beyond the pleura, then half
/// a second for the wound to open; what the surgeon sees of the heart from the viewpoint.
fn field_after_stroke_at(y_m: f64) -> Exposure {
    let scene = Scene::load("thorax", BuildOptions::default()).expect("the thorax");
    let mut sim = scene.simulation();
    let mut cutter = Cutter::default();
    for k in 0..=50 {
        let x = -0.020 + 0.001 * k as f64;
        let blade = cut::blade(Point3::new(x, y_m, -0.045), Vector3::z(), 0.06);
        cutter.advance(&mut sim, blade).expect("a cut");
        sim.step().expect("a step");
    }
    cutter.end_stroke();
    for _ in 0..100 {
        sim.step().expect("a step");
    }
    let vertices: Vec<PVec> = sim
        .state
        .positions
        .iter()
        .map(|p| PVec::new(p.x, p.y, p.z))
        .collect();
    let surface =
        TriMesh::new(vertices, sim.model.mesh.topology().boundary.clone()).expect("the surface");
    let target = &scene.targets[0];
    let heart = Ellipsoid {
        centre_m: Point3::from(target.centre_mm) * 1e-3,
        radii_m: Vector3::from(target.radii_mm) * 1e-3,
    };
    let view = scene.viewpoint.as_ref().expect("a viewpoint");
    exposure(&surface, &heart, &(Point3::from(view.eye_mm) * 1e-3), 60)
}

#[test]
fn an_incision_through_an_intercostal_space_shows_the_heart_and_one_over_a_rib_does_not() {
    // the 4th space lies between y = -10 and 5 mm; the 4th rib between 5 and 15 mm
    let space = field_after_stroke_at(-0.0025);
    let rib = field_after_stroke_at(0.0115);
    eprintln!("through the space: {space:?}\nover the rib: {rib:?}");
    assert!(space.visible_area_m2 > 1e-5, "{space:?}");
    assert!(space.working_width_m > 1e-3, "{space:?}");
    assert_eq!(rib.visible_area_m2, 0.0, "{rib:?}");
    assert_eq!(rib.working_width_m, 0.0, "{rib:?}");
}
