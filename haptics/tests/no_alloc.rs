//! The servo loop's per-tick work allocates nothing in steady state: device read, force
//! rendering, device write and the exchange through the lock-free queue and triple buffer,
//! run under an allocator that counts every allocation made while forbidden.

use assert_no_alloc::{AllocDisabler, assert_no_alloc, reset_violation_count, violation_count};
use cutlab_haptics::device::{HapticDevice, IgtlDevice, Plan, Skill, SyntheticTrainee};
use cutlab_haptics::render::{ContactModel, ForceRenderer, RenderSettings};
use cutlab_haptics::servo::ServoSample;
use cutlab_haptics::{Point3, Vector3};

#[global_allocator]
static ALLOCATOR: AllocDisabler = AllocDisabler;

#[test]
fn a_servo_tick_does_not_allocate() {
    let plan = Plan {
        line_m: vec![Point3::new(-0.03, 0.0, 0.0), Point3::new(0.03, 0.0, 0.0)],
        normals: vec![Vector3::z(); 2],
        depth_m: 0.005,
        approach_height_m: 0.015,
    };
    let mut trainee =
        SyntheticTrainee::new("novice", plan, Skill::preset("novice").expect("preset"), 1)
            .expect("trainee");
    let mut network =
        IgtlDevice::listen_on("127.0.0.1:0".parse().expect("address")).expect("listen");
    let mut renderer = ForceRenderer::new(RenderSettings::default());
    let (mut contact_in, mut contact_out) = triple_buffer::triple_buffer(&ContactModel::default());
    let (mut samples_in, mut samples_out) = rtrb::RingBuffer::<ServoSample>::new(64);
    let mut tick_body = |tick: u64| {
        let contact = *contact_out.read();
        let time_s = tick as f64 * 1e-3;
        let read = trainee.read(tick, time_s);
        let _ = network.read(tick, time_s);
        let out = renderer.update(tick, read, &contact);
        let _ = trainee.write_force(out.force_newtons);
        let _ = network.write_force(out.force_newtons);
        let _ = samples_in.push(ServoSample {
            tick,
            pose: read.unwrap_or_default(),
            render: out,
        });
        // the simulation side, here in the same thread: take the sample, publish a model
        if let Ok(s) = samples_out.pop() {
            contact_in.write(ContactModel {
                published: true,
                source_tick: s.tick,
                at_heel: false,
                valid: true,
                plane_point: Point3::origin(),
                plane_normal: Vector3::z(),
                stiffness_newtons_per_m: 300.0,
                cut_entry: None,
            });
        }
        out
    };
    for tick in 0..10 {
        tick_body(tick);
    }
    reset_violation_count();
    let mut max_force = 0.0f64;
    assert_no_alloc(|| {
        for tick in 10..15_000 {
            max_force = max_force.max(tick_body(tick).force_newtons.norm());
        }
    });
    assert_eq!(violation_count(), 0, "allocations during servo ticks");
    assert!(
        max_force > 0.5,
        "the trainee pressed on the plane: {max_force}"
    );
}
