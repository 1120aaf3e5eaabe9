//! The servo loop's per-tick work allocates nothing in steady state: device read, force
//! rendering, device write and the exchange through the lock-free queue and triple buffer,
//! run under an allocator that counts every allocation made while forbidden.

use assert_no_alloc::{AllocDisabler, assert_no_alloc, reset_violation_count, violation_count};
use cutlab_haptics::device::{HapticDevice, IgtlDevice, Skill, SyntheticTrainee};
use cutlab_haptics::plan::Plan;
use cutlab_haptics::render::{ContactModel, ForceRenderer, RenderSettings};
use cutlab_haptics::servo::{GrasperTick, ServoSample};
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
        viewpoint_m: None,
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
        let second = network.read(tick, time_s).ok().map(|pose| GrasperTick {
            pose,
            pull_newtons: contact.grasp_pull_newtons,
        });
        let out = renderer.update(tick, read, &contact);
        let _ = trainee.write_force(out.force_newtons);
        let _ = network.write_force(out.force_newtons);
        let _ = samples_in.push(ServoSample {
            tick,
            pose: read.unwrap_or_default(),
            render: out,
            grasper: second,
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
                grasp_pull_newtons: Vector3::new(0.0, 0.0, -0.2),
                ..ContactModel::default()
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

#[test]
fn a_pointer_tick_does_not_allocate_while_a_page_pushes() {
    use cutlab_haptics::device::{PointerDevice, PointerOptions, PointerSample};
    let (mut pointer, feed) = PointerDevice::new(PointerOptions::default()).expect("device");
    let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    // the page, on its own thread: a sample a millisecond of page time, as fast as it can
    let page = {
        let done = done.clone();
        std::thread::spawn(move || {
            let mut k = 0u64;
            while !done.load(std::sync::atomic::Ordering::Relaxed) {
                let x = (k % 100) as f64 * 1e-4;
                if feed
                    .push(PointerSample::new(k as f64, [x, 0.0, 0.0], 0.001, true))
                    .is_ok()
                {
                    k += 1;
                }
                let _ = feed.latest_force_newtons();
                let _ = feed.echo_ms(k);
                std::thread::yield_now();
            }
            k
        })
    };
    // the page has begun (its thread started), and the device has taken samples
    let started = std::time::Instant::now();
    let mut tick = 0;
    while pointer
        .counters()
        .accepted
        .load(std::sync::atomic::Ordering::Relaxed)
        < 10
        && started.elapsed().as_secs() < 10
    {
        let _ = pointer.read(tick, tick as f64 * 1e-6);
        tick = (tick + 1).min(9);
        std::thread::yield_now();
    }
    reset_violation_count();
    let mut poses = 0u64;
    // session time runs at a microsecond a tick here, so however the page thread is
    // scheduled the device does not time out: every tick takes the sample path
    assert_no_alloc(|| {
        for tick in 10..15_000u64 {
            if pointer.read(tick, tick as f64 * 1e-6).is_ok() {
                poses += 1;
            }
            let _ = pointer.write_force(Vector3::new(0.0, 0.0, tick as f64 * 1e-4));
        }
    });
    done.store(true, std::sync::atomic::Ordering::Relaxed);
    let pushed = page.join().expect("page");
    assert_eq!(violation_count(), 0, "allocations during pointer ticks");
    assert!(pushed > 0, "the page pushed nothing");
    assert_eq!((pointer.fault(), poses), (None, 14_990));
}
