use super::cg::solve_on;
use super::*;
use crate::Vector3;
use crate::model::Particles;
use crate::scene::{BuildOptions, Scene};
use crate::solver::span::SPAN;

/// An implicit-Euler-like system on the chest wall (1 ms step, current positions).
fn system(model: &Particles<'_>, x: &[crate::Point3]) -> (SpringSystem, Vec<Vector3>) {
    let s = &model.springs;
    let h = 1e-3;
    let mut sys = SpringSystem {
        mass_weight: 1.0,
        ..Default::default()
    };
    sys.begin(model);
    for (e, &[a, b]) in s.ends.iter().enumerate() {
        let (ka, kn, n) = stiffness_block(
            s.stiffness[e],
            s.rest_length[e],
            &(x[b as usize] - x[a as usize]),
        );
        sys.set_block(e, h * h * ka, h * s.damping[e] + h * h * kn, &n);
    }
    sys.update_preconditioner(model);
    let rhs = (0..model.vertex_count())
        .map(|i| Vector3::new((i as f64).sin(), (0.7 * i as f64).cos(), 0.3) * 1e-6)
        .collect();
    (sys, rhs)
}

fn true_residual(sys: &SpringSystem, model: &Particles<'_>, b: &[Vector3], x: &[Vector3]) -> f64 {
    let n = b.len();
    let mut ax = vec![Vector3::zeros(); n];
    sys.apply(x, &mut ax);
    let r_norm = (0..n)
        .filter(|&i| !model.held[i])
        .map(|i| (b[i] - ax[i]).norm_squared())
        .sum::<f64>()
        .sqrt();
    let b_norm = b
        .iter()
        .zip(model.held)
        .filter(|(_, h)| !**h)
        .map(|(b, _)| b.norm_squared())
        .sum::<f64>()
        .sqrt();
    r_norm / b_norm
}

#[test]
fn ssor_and_jacobi_solve_the_same_system() {
    let scene = Scene::load(
        "chest-wall",
        BuildOptions {
            min_tets: Some(1_000),
        },
    )
    .expect("built-in scene");
    let positions = scene.model.mesh.positions();
    let model = &scene.model.particles();
    let (mut sys, b) = system(model, positions);
    assert!(sys.ssor);
    let settings = CgSettings {
        relative_tolerance: 1e-10,
        absolute_tolerance: 0.0,
        max_iterations: 1000,
    };
    let n = b.len();
    let mut x_ssor = vec![Vector3::zeros(); n];
    let ssor = solve(
        &sys,
        model.held,
        &b,
        &mut x_ssor,
        settings,
        &mut CgScratch::default(),
    );
    assert!(ssor.converged, "{ssor:?}");
    assert!(true_residual(&sys, model, &b, &x_ssor) <= 1e-10);
    sys.ssor = false;
    let mut x_jacobi = vec![Vector3::zeros(); n];
    let jacobi = solve(
        &sys,
        model.held,
        &b,
        &mut x_jacobi,
        settings,
        &mut CgScratch::default(),
    );
    assert!(jacobi.converged, "{jacobi:?}");
    assert!(
        ssor.iterations * 2 < jacobi.iterations,
        "{ssor:?} vs {jacobi:?}"
    );
    let scale = x_jacobi.iter().map(|v| v.norm()).fold(0.0, f64::max);
    let diff = x_ssor
        .iter()
        .zip(&x_jacobi)
        .map(|(a, b)| (a - b).norm())
        .fold(0.0, f64::max);
    assert!(diff < 1e-8 * scale, "{diff} vs {scale}");
    for (x, &h) in x_ssor.iter().zip(model.held.iter()) {
        assert!(!h || *x == Vector3::zeros());
    }
}

#[test]
fn one_thread_or_two_give_the_same_bits() {
    let scene = Scene::load(
        "chest-wall",
        BuildOptions {
            min_tets: Some(1_000),
        },
    )
    .expect("built-in scene");
    let positions = scene.model.mesh.positions();
    let model = &scene.model.particles();
    let (sys, b) = system(model, positions);
    assert!(sys.ssor);
    let settings = CgSettings {
        relative_tolerance: 1e-8,
        absolute_tolerance: 0.0,
        max_iterations: 1000,
    };
    // the solve from `start` (and the span of `more`) on one thread and on two: the same
    // report and the same bits; returns them
    let same_bits = |start: Vec<Vector3>, more: Option<[&[Vector3]; SPAN - 1]>| {
        let (mut one, mut two) = (start.clone(), start);
        let a = solve_on(
            &sys,
            model.held,
            &b,
            &mut one,
            more,
            settings,
            &mut CgScratch::default(),
            false,
        );
        let c = solve_on(
            &sys,
            model.held,
            &b,
            &mut two,
            more,
            settings,
            &mut CgScratch::default(),
            true,
        );
        assert_eq!(a, c);
        assert!(
            one.iter()
                .zip(&two)
                .all(|(u, v)| u.map(f64::to_bits) == v.map(f64::to_bits))
        );
        (a, one)
    };
    let (a, one) = same_bits(vec![Vector3::zeros(); b.len()], None);
    assert!(a.converged && a.iterations > 5, "{a:?}");
    assert!(true_residual(&sys, model, &b, &one) <= 1e-8);
    // started from a span
    let more: Vec<Vec<Vector3>> = (1..SPAN)
        .map(|j| {
            one.iter()
                .enumerate()
                .map(|(i, v)| v * (1.0 + 0.1 * ((i * j) as f64).sin()))
                .collect()
        })
        .collect();
    let (a, _) = same_bits(b.clone(), Some([&more[0][..], &more[1][..], &more[2][..]]));
    assert!(a.converged, "{a:?}");
}

/// `|x - y|_A`.
fn a_norm_of_difference(
    sys: &SpringSystem,
    model: &Particles<'_>,
    x: &[Vector3],
    y: &[Vector3],
) -> f64 {
    let d: Vec<Vector3> = x.iter().zip(y).map(|(x, y)| x - y).collect();
    let mut ad = vec![Vector3::zeros(); d.len()];
    sys.apply(&d, &mut ad);
    d.iter()
        .zip(&ad)
        .zip(model.held)
        .filter(|(_, h)| !**h)
        .map(|((d, ad), _)| d.dot(ad))
        .sum::<f64>()
        .sqrt()
}

#[test]
fn a_start_from_a_span_is_the_best_of_its_combinations() {
    let scene = Scene::load(
        "chest-wall",
        BuildOptions {
            min_tets: Some(1_000),
        },
    )
    .expect("built-in scene");
    let positions = scene.model.mesh.positions();
    let model = &scene.model.particles();
    let (sys, b) = system(model, positions);
    let n = b.len();
    let tight = CgSettings {
        relative_tolerance: 1e-12,
        absolute_tolerance: 0.0,
        max_iterations: 1000,
    };
    let mut exact = vec![Vector3::zeros(); n];
    assert!(
        solve(
            &sys,
            model.held,
            &b,
            &mut exact,
            tight,
            &mut CgScratch::default()
        )
        .converged
    );
    // the solution disturbed in two ways, a vector with no part along it, and a repeat
    let wave = |k: f64| -> Vec<Vector3> {
        exact
            .iter()
            .enumerate()
            .map(|(i, v)| v * (1.0 + 0.3 * (k * i as f64).sin()))
            .collect()
    };
    let (u0, u1) = (wave(0.37), wave(1.9));
    let u2: Vec<Vector3> = (0..n)
        .map(|i| Vector3::new((0.5 * i as f64).cos(), 0.0, 1.0) * 1e-7)
        .collect();
    let no_iterations = CgSettings {
        max_iterations: 0,
        ..tight
    };
    let mut start = u0.clone();
    solve_from_span(
        &sys,
        model.held,
        &b,
        &mut start,
        [&u1, &u2, &u1],
        no_iterations,
        &mut CgScratch::default(),
    );
    let error = a_norm_of_difference(&sys, model, &start, &exact);
    let zero = vec![Vector3::zeros(); n];
    for (name, other) in [
        ("u0", &u0),
        ("u1", &u1),
        (
            "the mean",
            &u0.iter().zip(&u1).map(|(a, b)| (a + b) / 2.0).collect(),
        ),
        ("zero", &zero),
    ] {
        let e = a_norm_of_difference(&sys, model, other, &exact);
        assert!(error <= e, "{error} from the span, {e} from {name}");
    }
    // with the solution in the span, the start is the solution: no iteration needed
    let mut start = u0.clone();
    let report = solve_from_span(
        &sys,
        model.held,
        &b,
        &mut start,
        [&u1, &exact, &u2],
        CgSettings {
            relative_tolerance: 1e-8,
            ..tight
        },
        &mut CgScratch::default(),
    );
    assert_eq!(report.iterations, 0, "{report:?}");
    assert!(true_residual(&sys, model, &b, &start) <= 1e-8);
}

#[test]
fn springs_in_any_order_and_orientation_give_the_same_solution() {
    let scene = Scene::load(
        "chest-wall",
        BuildOptions {
            min_tets: Some(1_000),
        },
    )
    .expect("built-in scene");
    let positions = scene.model.mesh.positions();
    let model = &scene.model.particles();
    let (sys, b) = system(model, positions);
    let settings = CgSettings {
        relative_tolerance: 1e-10,
        absolute_tolerance: 0.0,
        max_iterations: 1000,
    };
    let n = b.len();
    let mut x = vec![Vector3::zeros(); n];
    assert!(
        solve(
            &sys,
            model.held,
            &b,
            &mut x,
            settings,
            &mut CgScratch::default()
        )
        .converged
    );

    // the springs reversed in order, every other one with its ends swapped
    let mut shuffled = model.springs.clone();
    let m = shuffled.len();
    let order: Vec<usize> = (0..m).rev().collect();
    let s = &model.springs;
    shuffled.ends = order
        .iter()
        .map(|&e| {
            if e % 2 == 0 {
                s.ends[e]
            } else {
                [s.ends[e][1], s.ends[e][0]]
            }
        })
        .collect();
    shuffled.rest_length = order.iter().map(|&e| s.rest_length[e]).collect();
    shuffled.stiffness = order.iter().map(|&e| s.stiffness[e]).collect();
    shuffled.damping = order.iter().map(|&e| s.damping[e]).collect();
    let shuffled = Particles {
        springs: &shuffled,
        ..*model
    };
    let (sys2, _) = system(&shuffled, positions);
    assert!(sys2.ssor);
    let (mut y, mut y2) = (vec![Vector3::zeros(); n], vec![Vector3::zeros(); n]);
    sys.apply(&b, &mut y);
    sys2.apply(&b, &mut y2);
    let scale = y.iter().map(|v| v.norm()).fold(0.0, f64::max);
    assert!(
        y.iter()
            .zip(&y2)
            .all(|(a, b)| (a - b).norm() <= 1e-12 * scale)
    );
    let mut x2 = vec![Vector3::zeros(); n];
    assert!(
        solve(
            &sys2,
            shuffled.held,
            &b,
            &mut x2,
            settings,
            &mut CgScratch::default()
        )
        .converged
    );
    let scale = x.iter().map(|v| v.norm()).fold(0.0, f64::max);
    assert!(
        x.iter()
            .zip(&x2)
            .all(|(a, b)| (a - b).norm() <= 1e-8 * scale)
    );
}

/// General (non-symmetric) off-diagonal blocks, the finite elements' kind: SSOR in Eisenstat's
/// form and block-Jacobi both solve the system, on one thread and on two with the same bits.
#[test]
fn general_blocks_are_solved_with_either_preconditioner() {
    use nalgebra::Matrix3;

    use super::ElementSystem;
    use super::blocks::Sym3;

    let n = 13_000; // past PARALLEL_MIN_PARTICLES: the halves side by side
    let edges: Vec<[u32; 2]> = (0..n as u32 - 1)
        .map(|i| [i, i + 1])
        .chain((0..n as u32 - 7).map(|i| [i, i + 7]))
        .collect();
    let mut sorted = edges.clone();
    sorted.sort_unstable();
    let mut sys = ElementSystem::default();
    sys.begin_sums(n, &sorted);
    for (e, &[a, b]) in sorted.iter().enumerate() {
        let s = 1.0 + 0.1 * (e % 5) as f64;
        let k = Matrix3::new(-1.0, 0.3, 0.0, 0.1, -0.5, 0.2, 0.0, -0.1, -0.7) * s;
        sys.add_off(e, a, b, &k);
        // diagonally dominant: each end gets more than the block's absolute row sums
        for v in [a, b] {
            sys.diag[v as usize] += Sym3::scalar(2.5 * s);
        }
    }
    let mut held = vec![false; n];
    held[0] = true;
    sys.prepare_held(&held, &[]);
    let b: Vec<Vector3> = (0..n)
        .map(|i| Vector3::new(1.0, -((i % 13) as f64), 0.5))
        .collect();
    let settings = CgSettings {
        relative_tolerance: 1e-12,
        absolute_tolerance: 0.0,
        max_iterations: 1_000,
    };
    let mut solutions = Vec::new();
    for (ssor, parallel) in [(true, true), (true, false), (false, false)] {
        sys.ssor = ssor;
        let mut x = vec![Vector3::zeros(); n];
        let report = solve_on(
            &sys,
            &held,
            &b,
            &mut x,
            None,
            settings,
            &mut CgScratch::default(),
            parallel,
        );
        assert!(report.converged, "{ssor}: {report:?}");
        let mut y = vec![Vector3::zeros(); n];
        sys.apply(&x, &mut y);
        for i in 1..n {
            assert!(
                (y[i] - b[i]).norm() < 1e-10,
                "{ssor}, {i}: {} vs {}",
                y[i],
                b[i]
            );
        }
        assert_eq!(x[0], Vector3::zeros());
        solutions.push(x);
    }
    assert_eq!(
        solutions[0], solutions[1],
        "the same bits on one thread or two"
    );
}
