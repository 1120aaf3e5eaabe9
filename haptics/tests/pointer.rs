//! The station's pointer device: page samples in, servo poses out.

use cutlab_haptics::device::pointer::{
    PointerCounters, PointerFault, PointerOrientation, PushError, scalpel_down,
};
use cutlab_haptics::device::{
    DeviceFault, HapticDevice, PointerDevice, PointerFeed, PointerOptions, PointerSample,
};
use cutlab_haptics::plan::Plan;
use cutlab_haptics::{Point3, Rotation, ToolPose, Vector3};
use proptest::prelude::*;
use std::sync::atomic::Ordering;

fn device(options: PointerOptions) -> (PointerDevice, PointerFeed) {
    PointerDevice::new(options).expect("valid options")
}

/// The servo's time of tick `tick` at 1 kHz.
fn time_s(tick: u64) -> f64 {
    tick as f64 * 1e-3
}

fn read(d: &mut PointerDevice, tick: u64) -> Result<ToolPose, DeviceFault> {
    d.read(tick, time_s(tick))
}

fn x_at(d: &mut PointerDevice, tick: u64) -> f64 {
    read(d, tick).expect("a pose").tip_in_world.x
}

/// A sample on the line `x = x_m` of the surface `z = 0`, at the surface (depth 0).
fn on_line(t_ms: f64, x_m: f64) -> PointerSample {
    PointerSample::new(t_ms, [x_m, 0.0, 0.0], 0.0, true)
}

fn count(c: &std::sync::atomic::AtomicU64) -> u64 {
    c.load(Ordering::Relaxed)
}

#[test]
fn the_feed_can_go_to_any_thread_and_the_device_to_the_servo() {
    fn page_side<T: Clone + Send + Sync + 'static>() {}
    fn servo_side<T: HapticDevice + 'static>() {}
    page_side::<PointerFeed>();
    servo_side::<PointerDevice>();
    servo_side::<Box<dyn HapticDevice>>();
    let (d, _feed) = device(PointerOptions::default());
    let boxed: Box<dyn HapticDevice> = Box::new(d);
    assert_eq!(boxed.name(), "pointer");
}

#[test]
fn before_any_sample_the_rest_pose_is_held_above_the_tissue() {
    let plan = Plan {
        line_m: vec![Point3::new(-0.03, 0.0, 0.0), Point3::new(0.03, 0.0, 0.0)],
        normals: vec![Vector3::z(); 2],
        depth_m: 0.005,
        approach_height_m: 0.015,
        viewpoint_m: None,
    };
    let options = PointerOptions::above_entry(&plan).expect("plan");
    let (mut d, _feed) = device(options);
    for tick in [0, 1, 1000] {
        let pose = read(&mut d, tick).expect("rest pose");
        assert_eq!(pose.tip_in_world, Point3::new(-0.03, 0.0, 0.015));
        assert!(!pose.blade_engaged());
        // the blade points down (its edge runs up from the tip), cutting along the line
        assert!((pose.edge_direction() - Vector3::z()).norm() < 1e-12);
        assert!((pose.world_from_tool * Vector3::x() - Vector3::x()).norm() < 1e-12);
    }
    // no timeout before the first sample (the page may take a while to load)
    assert_eq!(d.fault(), None);
}

#[test]
fn interpolation_is_exact_at_sample_times_and_linear_between() {
    let (mut d, feed) = device(PointerOptions::default());
    // three samples arrive at once at tick 0; the newest (1020 ms) plays 30 ms later
    for (t, x) in [(1000.0, 0.0), (1010.0, 0.001), (1020.0, 0.003)] {
        feed.push(on_line(t, x)).expect("queued");
    }
    let expected = [
        (0, 0.0),     // before the first sample's time: the first sample
        (10, 0.0),    // 1000 ms
        (15, 0.0005), // halfway to 1010 ms
        (20, 0.001),  // 1010 ms
        (25, 0.002),  // halfway to 1020 ms
        (30, 0.003),  // 1020 ms
        (40, 0.003),  // after the newest: held
    ];
    for (tick, x) in expected {
        let got = x_at(&mut d, tick);
        assert!((got - x).abs() < 1e-15, "tick {tick}: {got} instead of {x}");
    }
    let pose = read(&mut d, 41).expect("pose");
    assert!(pose.blade_engaged());
    assert_eq!(pose.tip_in_world.z, 0.0);
    assert_eq!(count(&feed.counters().accepted), 3);
}

/// Feeds a page whose clock reads 5000 ms at the session's start, one sample every `every`
/// ticks arriving on time, on the line x = (t - 5000 ms) mm; returns x at each tick.
fn steady_stream(delay_s: f64, ticks: u64, every: u64) -> Vec<f64> {
    let (mut d, feed) = device(PointerOptions {
        delay_s,
        ..PointerOptions::default()
    });
    (0..ticks)
        .map(|tick| {
            if tick % every == 0 {
                feed.push(on_line(5000.0 + tick as f64, tick as f64 * 1e-3))
                    .expect("queued");
            }
            x_at(&mut d, tick)
        })
        .collect()
}

#[test]
fn the_fixed_delay_shifts_the_pose_in_time() {
    let x30 = steady_stream(0.03, 400, 10);
    let x60 = steady_stream(0.06, 400, 10);
    for tick in 100..400 {
        // the pose trails the page by the delay, exactly on the line the samples lie on
        let want = (tick as f64 - 30.0) * 1e-3;
        assert!(
            (x30[tick] - want).abs() < 1e-12,
            "tick {tick}: {}",
            x30[tick]
        );
        assert!((x60[tick] - x30[tick - 30]).abs() < 1e-12, "tick {tick}");
    }
    // and before the delay has passed, the first sample is held
    assert!(x30[..30].iter().all(|&x| x == 0.0));
}

#[test]
fn out_of_order_samples_are_dropped_and_counted() {
    let (mut d, feed) = device(PointerOptions::default());
    feed.push(on_line(100.0, 0.0)).expect("queued");
    feed.push(on_line(120.0, 0.002)).expect("queued");
    feed.push(on_line(110.0, 0.5)).expect("queued"); // older than the last
    feed.push(on_line(120.0, 0.5)).expect("queued"); // same time as the last
    for tick in 0..60 {
        let x = x_at(&mut d, tick);
        assert!((0.0..=0.002).contains(&x), "tick {tick}: {x}");
    }
    let c = d.counters();
    assert_eq!((count(&c.accepted), count(&c.dropped_out_of_order)), (2, 2));
    assert_eq!(d.fault(), None);
}

#[test]
fn absurd_samples_are_dropped_and_counted_without_a_fault() {
    let (mut d, feed) = device(PointerOptions::default());
    feed.push(on_line(100.0, 0.0)).expect("queued");
    let far = PointerSample::new(110.0, [11.0, 0.0, 0.0], 0.0, true);
    let deep = PointerSample::new(111.0, [0.0, 0.0, 0.0], 0.2, true);
    let jump = on_line(100.0 + 10_001.0, 0.0);
    let unnormalised = PointerSample {
        world_from_tool_xyzw: Some([0.0, 0.0, 0.0, 2.0]),
        ..on_line(112.0, 0.0)
    };
    for s in [far, deep, jump, unnormalised] {
        feed.push(s).expect("queued");
    }
    assert!(read(&mut d, 0).is_ok());
    assert_eq!(count(&d.counters().dropped_invalid), 4);
    assert_eq!(count(&d.counters().accepted), 1);
    assert_eq!(d.fault(), None);
}

#[test]
fn a_non_finite_sample_is_dropped_and_counted_and_the_device_goes_on() {
    let (mut d, feed) = device(PointerOptions::default());
    feed.push(on_line(100.0, 0.001)).expect("queued");
    assert!(read(&mut d, 0).is_ok());
    let mut nan = on_line(110.0, 0.0);
    nan.surface_in_world_m[2] = f64::NAN;
    let mut inf = on_line(115.0, 0.0);
    inf.depth_m = f64::INFINITY;
    for s in [nan, inf, on_line(120.0, 0.002)] {
        feed.push(s).expect("queued");
    }
    assert!(read(&mut d, 1).is_ok());
    assert_eq!(d.fault(), None);
    assert_eq!(feed.fault(), None);
    assert_eq!(count(&d.counters().non_finite), 2);
    assert_eq!(count(&d.counters().accepted), 2);
    assert!(!d.finished(0.002) && !d.ends_session());
    // the poses stay finite and the next samples are taken
    feed.push(on_line(130.0, 0.003)).expect("queued");
    for tick in 2..200 {
        let pose = read(&mut d, tick).expect("a pose");
        assert!(pose.tip_in_world.iter().all(|c| c.is_finite()));
    }
    assert_eq!(count(&d.counters().accepted), 3);
    assert!(d.write_force(Vector3::zeros()).is_ok());
}

#[test]
fn a_stalled_page_pauses_the_blade_then_ends_after_the_absence() {
    let (mut d, feed) = device(PointerOptions {
        timeout_s: 0.2,
        absence_s: 1.0,
        ..PointerOptions::default()
    });
    feed.push(on_line(0.0, 0.0)).expect("queued");
    feed.push(on_line(10.0, 0.004)).expect("queued");
    // samples stop after tick 0: the pose moves to the newest, then holds there
    for tick in 0..=200 {
        let x = x_at(&mut d, tick);
        if tick >= 30 {
            assert_eq!(x, 0.004, "tick {tick}");
        }
    }
    assert!(count(&d.counters().held_ticks) > 150);
    // past the timeout: paused (stale, the servo holds the pose and fades the force), not
    // ended
    for tick in 201..1000 {
        match read(&mut d, tick) {
            Err(DeviceFault::Stale { age_nanos }) => assert!(age_nanos > 200_000_000),
            other => panic!("tick {tick}: expected a pause, got {other:?}"),
        }
    }
    assert_eq!(d.fault(), None);
    assert!(!d.ends_session(), "a pause does not end the session");
    assert!(count(&d.counters().paused_ticks) >= 799);
    // past the absence: the page is gone, the session ends
    assert!(matches!(read(&mut d, 1001), Err(DeviceFault::Stale { .. })));
    assert_eq!(d.fault(), Some(PointerFault::TimedOut));
    assert_eq!(feed.fault(), Some(PointerFault::TimedOut));
    assert!(d.ends_session(), "a lost page ends the session");
    // a sample after the absence does not bring it back: the session's input was lost
    assert_eq!(
        feed.push(on_line(5000.0, 0.0)),
        Err(PushError::Faulted(PointerFault::TimedOut))
    );
}

#[test]
fn a_page_back_after_a_pause_plays_on_even_with_its_clock_started_again() {
    let (mut d, feed) = device(PointerOptions::default());
    // the page samples every 10 ms for 300 ms, goes away for 2 s (a hidden tab), then comes
    // back reloaded: its clock starts again near zero, a long way from where it was
    for tick in 0..300u64 {
        if tick % 10 == 0 {
            feed.push(on_line(1000.0 + tick as f64, tick as f64 * 1e-4))
                .expect("queued");
        }
        assert!(read(&mut d, tick).is_ok(), "tick {tick}");
    }
    for tick in 300..2300u64 {
        let r = read(&mut d, tick);
        assert!(
            tick < 900 || matches!(r, Err(DeviceFault::Stale { .. })),
            "tick {tick}: {r:?}"
        );
    }
    assert!(count(&d.counters().paused_ticks) > 1000);
    for tick in 2300..2600u64 {
        if tick % 10 == 0 {
            let page_ms = (tick - 2300) as f64 + 5.0;
            feed.push(on_line(page_ms, 0.05 + page_ms * 1e-5))
                .expect("queued");
        }
        let r = read(&mut d, tick);
        assert!(r.is_ok(), "tick {tick}: {r:?}");
    }
    assert_eq!(d.fault(), None);
    assert_eq!(count(&d.counters().resumes), 1);
    assert_eq!(count(&d.counters().dropped_out_of_order), 0);
    // it plays the new samples: near the last one, the delay behind
    assert!((x_at(&mut d, 2600) - (0.05 + 265.0 * 1e-5)).abs() < 1e-3);
}

#[test]
fn a_page_that_comes_back_before_the_timeout_plays_on_without_going_back() {
    let (mut d, feed) = device(PointerOptions::default());
    let mut last = f64::NEG_INFINITY;
    for tick in 0..800u64 {
        // a page that stalls from 200 ms to 500 ms (its clock goes on: the next sample is
        // 300 ms later), moving along x at 1 mm per 10 ms
        if tick % 10 == 0 && !(200..500).contains(&tick) {
            feed.push(on_line(tick as f64, tick as f64 * 1e-4))
                .expect("queued");
        }
        let x = x_at(&mut d, tick);
        assert!(x >= last, "tick {tick}: moved back from {last} to {x}");
        last = x;
    }
    assert_eq!(d.fault(), None);
    assert!(!d.ends_session() && !d.finished(0.8));
    assert!(count(&d.counters().reanchors) >= 1);
    // after the stall the pose trails the page by the delay again
    assert!((x_at(&mut d, 800) - 0.077).abs() < 1e-12);
}

#[test]
fn closing_the_feed_faults_the_device() {
    let (mut d, feed) = device(PointerOptions::default());
    let page = feed.clone();
    page.push(on_line(0.0, 0.0)).expect("queued");
    assert!(read(&mut d, 0).is_ok());
    page.close();
    assert_eq!(feed.push(on_line(5.0, 0.0)), Err(PushError::Closed));
    assert_eq!(read(&mut d, 1), Err(DeviceFault::Disconnected));
    assert_eq!(d.fault(), Some(PointerFault::Closed));
    assert!(d.finished(0.001) && d.ends_session());

    // dropping every clone of the feed closes it too (a tab closed without a word)
    let (mut d, feed) = device(PointerOptions::default());
    let other = feed.clone();
    drop(feed);
    assert!(
        read(&mut d, 0).is_ok(),
        "one clone still open: the rest pose"
    );
    assert!(!d.ends_session());
    drop(other);
    assert_eq!(read(&mut d, 1), Err(DeviceFault::Disconnected));
    assert_eq!(d.fault(), Some(PointerFault::Closed));

    // and a feed whose device is gone says so
    let (d, feed) = device(PointerOptions::default());
    drop(d);
    assert_eq!(feed.push(on_line(0.0, 0.0)), Err(PushError::DeviceGone));
}

#[test]
fn a_full_queue_refuses_samples_and_the_servo_side_never_waits() {
    let (mut d, feed) = device(PointerOptions {
        queue_capacity: 4,
        ..PointerOptions::default()
    });
    let results: Vec<_> = (0..6).map(|k| feed.push(on_line(k as f64, 0.0))).collect();
    assert_eq!(results[..4], [Ok(()); 4]);
    assert_eq!(results[4..], [Err(PushError::Full); 2]);
    assert_eq!(count(&feed.counters().dropped_full), 2);
    assert!(read(&mut d, 0).is_ok());
    assert_eq!(count(&d.counters().accepted), 4);
    assert_eq!(feed.push(on_line(10.0, 0.0)), Ok(()), "room again");

    // pages on two threads push as fast as they can while the servo reads 20k ticks: every
    // sample is either queued or refused, every queued one is taken (used or dropped as out
    // of order, since the two pages' clocks interleave), and the servo never sees a fault
    let (mut d, feed) = device(PointerOptions {
        queue_capacity: 16,
        ..PointerOptions::default()
    });
    let pages: Vec<_> = (0..2)
        .map(|p| {
            let feed = feed.clone();
            std::thread::spawn(move || {
                let mut attempts = 0u64;
                for k in 0..20_000 {
                    let _ = feed.push(on_line(k as f64 + 0.5 * p as f64, 0.0));
                    attempts += 1;
                }
                attempts
            })
        })
        .collect();
    for tick in 0..20_000 {
        // the page clock runs as fast as the pages push: whatever it reads, it is a pose
        let r = d.read(tick, tick as f64 * 1e-6);
        assert!(r.is_ok(), "tick {tick}: {r:?}");
    }
    let attempts: u64 = pages.into_iter().map(|p| p.join().expect("page")).sum();
    let _ = d.read(20_000, 0.02);
    let c: &PointerCounters = feed.counters();
    assert_eq!(count(&c.pushed) + count(&c.dropped_full), attempts);
    assert_eq!(
        count(&c.accepted) + count(&c.dropped_out_of_order) + count(&c.dropped_invalid),
        count(&c.pushed)
    );
    assert!(count(&c.accepted) > 0);
}

#[test]
fn the_force_and_the_echo_reach_the_page() {
    let (mut d, feed) = device(PointerOptions::default());
    assert_eq!(feed.latest_force_newtons(), Vector3::zeros());
    assert_eq!(feed.echo_ms(10), None);
    feed.push(on_line(250.0, 0.0)).expect("queued");
    read(&mut d, 3).expect("pose");
    d.write_force(Vector3::new(0.0, 0.25, -1.5))
        .expect("written");
    assert_eq!(feed.latest_force_newtons(), Vector3::new(0.0, 0.25, -1.5));
    assert_eq!(d.latest_force_newtons(), Vector3::new(0.0, 0.25, -1.5));
    feed.push(on_line(260.0, 0.0)).expect("queued");
    read(&mut d, 9).expect("pose");
    assert_eq!(feed.echo_ms(2), None);
    assert_eq!(feed.echo_ms(3), Some(250.0));
    assert_eq!(feed.echo_ms(8), Some(250.0));
    assert_eq!(feed.echo_ms(9), Some(260.0));
}

#[test]
fn orientation_per_sample_is_slerped_and_the_tip_goes_in_along_the_blade() {
    let fallback = scalpel_down(&Vector3::y(), &Vector3::x()).expect("rotation");
    let (mut d, feed) = device(PointerOptions {
        orientation: PointerOrientation::PerSample { fallback },
        ..PointerOptions::default()
    });
    // the blade pointing down -z, then turned 90 degrees about x: its edge runs up +y from the
    // tip, so the tip goes into the tissue along -y
    let tilted = Rotation::from_axis_angle(&Vector3::x_axis(), -std::f64::consts::FRAC_PI_2);
    let q = |r: &Rotation| Some([r.i, r.j, r.k, r.w]);
    let mut a = PointerSample::new(0.0, [0.0, 0.0, 0.0], 0.01, true);
    a.world_from_tool_xyzw = q(&Rotation::identity());
    let mut b = PointerSample::new(10.0, [0.0, 0.0, 0.0], 0.01, true);
    b.world_from_tool_xyzw = q(&tilted);
    let c = PointerSample::new(20.0, [0.0, 0.0, 0.0], 0.01, true); // no quaternion
    for s in [a, b, c] {
        feed.push(s).expect("queued");
    }
    // anchored at tick 0: the newest (20 ms) plays at tick 30, 0 ms at tick 10
    read(&mut d, 0).expect("pose");
    let start = read(&mut d, 10).expect("pose"); // 0 ms
    assert!((start.tip_in_world - Point3::new(0.0, 0.0, -0.01)).norm() < 1e-12);
    let mid = read(&mut d, 15).expect("pose"); // 5 ms: 45 degrees
    assert!((mid.world_from_tool.angle() - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
    // the tip is linear between the samples' tips (not swung round with the orientation)
    assert!(
        (mid.tip_in_world - Point3::new(0.0, -0.005, -0.005)).norm() < 1e-12,
        "{mid:?}"
    );
    let end = read(&mut d, 20).expect("pose"); // 10 ms
    assert!((end.tip_in_world - Point3::new(0.0, -0.01, 0.0)).norm() < 1e-12);
    let last = read(&mut d, 30).expect("pose"); // 20 ms: the fallback, edge along +y
    assert!((last.edge_direction() - Vector3::y()).norm() < 1e-12);
    assert!((last.tip_in_world - Point3::new(0.0, -0.01, 0.0)).norm() < 1e-12);
}

#[test]
fn options_are_checked() {
    let bad = [
        PointerOptions {
            delay_s: -0.01,
            ..PointerOptions::default()
        },
        PointerOptions {
            delay_s: f64::NAN,
            ..PointerOptions::default()
        },
        PointerOptions {
            timeout_s: 0.02,
            ..PointerOptions::default()
        },
        PointerOptions {
            max_lag_s: 0.01,
            ..PointerOptions::default()
        },
        PointerOptions {
            absence_s: 0.1,
            ..PointerOptions::default()
        },
        PointerOptions {
            queue_capacity: 1,
            ..PointerOptions::default()
        },
        PointerOptions {
            rest_pose: ToolPose {
                tip_in_world: Point3::new(f64::INFINITY, 0.0, 0.0),
                ..ToolPose::default()
            },
            ..PointerOptions::default()
        },
    ];
    for o in bad {
        assert!(PointerDevice::new(o).is_err(), "{o:?} accepted");
    }
    assert!(scalpel_down(&Vector3::z(), &Vector3::z()).is_none());
    assert!(scalpel_down(&Vector3::zeros(), &Vector3::x()).is_none());
}

/// One generated sample: the page-time step from the last, ms; the surface point, m; the
/// depth, m; the button; the quaternion (or none); the ticks it arrives after the last.
type Step = (f64, [f64; 3], f64, bool, Option<[f64; 4]>, u64);

/// A stream of finite, in-range samples.
fn stream() -> impl Strategy<Value = Vec<Step>> {
    let quaternion = prop::option::of(prop::array::uniform4(-1.0f64..1.0).prop_filter_map(
        "not zero",
        |q| {
            let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
            (n > 1e-3).then(|| q.map(|c| c / n))
        },
    ));
    prop::collection::vec(
        (
            1e-3f64..80.0,
            prop::array::uniform3(-5.0f64..5.0),
            -0.05f64..=0.1,
            any::<bool>(),
            quaternion,
            0u64..60,
        ),
        1..120,
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    #[test]
    fn finite_in_range_samples_give_finite_poses_the_same_every_time(
        samples in stream(),
        delay_ms in 0u32..120,
        per_sample in any::<bool>(),
    ) {
        let run = || {
            let options = PointerOptions {
                delay_s: f64::from(delay_ms) * 1e-3,
                max_lag_s: f64::from(delay_ms) * 1e-3 + 0.05,
                orientation: if per_sample {
                    PointerOrientation::PerSample { fallback: Rotation::identity() }
                } else {
                    PointerOrientation::default()
                },
                ..PointerOptions::default()
            };
            let (mut d, feed) = device(options);
            let mut poses = Vec::new();
            let (mut tick, mut t_ms) = (0u64, 1.0e6);
            for &(dt_ms, surface, depth_m, engaged, q, gap) in &samples {
                for _ in 0..gap {
                    poses.push(d.read(tick, time_s(tick)));
                    tick += 1;
                }
                t_ms += dt_ms;
                let mut s = PointerSample::new(t_ms, surface, depth_m, engaged);
                s.world_from_tool_xyzw = q;
                feed.push(s).expect("queued");
            }
            for _ in 0..200 {
                poses.push(d.read(tick, time_s(tick)));
                tick += 1;
            }
            poses
        };
        let first = run();
        for (tick, r) in first.iter().enumerate() {
            let pose = r.as_ref().map_err(|e| TestCaseError::fail(format!("tick {tick}: {e}")))?;
            prop_assert!(pose.is_finite(), "tick {}: {:?}", tick, pose);
            prop_assert!(pose.tip_in_world.coords.norm() < 5.0 * 3f64.sqrt() + 0.11);
        }
        prop_assert_eq!(first, run(), "the same samples at the same ticks: the same poses");
    }
}
