//! The preconditioned conjugate-gradient solves of `A x = b`: SSOR in Eisenstat's form, or
//! block-Jacobi where SSOR does not apply, from the `x` given or from the projection of a start
//! onto a span of vectors (see [`super::super::span`]).

use crate::Vector3;

use super::super::span::SPAN;
use super::blocks::OffBlock;
use super::lanes::{Lanes, SpanEntries};
use super::layout::split3;
use super::preconditioner::Sweeps;
use super::{BlockSystem, PARALLEL_MIN_PARTICLES, solver_threads};
use crate::parallel::join;

/// Settings of the conjugate-gradient solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CgSettings {
    /// Stop when `|r| <= max(relative_tolerance |b|, absolute_tolerance)`.
    pub relative_tolerance: f64,
    /// In the units of `b`; zero for a purely relative tolerance.
    pub absolute_tolerance: f64,
    /// The most iterations the solve may take.
    pub max_iterations: usize,
}

/// Outcome of a conjugate-gradient solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CgReport {
    /// Iterations taken.
    pub iterations: usize,
    /// `|b - A x| / |b|` at the end (over the free particles).
    pub relative_residual: f64,
    /// Whether the residual reached the tolerance.
    pub converged: bool,
}

/// Scratch vectors of the solver (kept between calls so steps do not allocate). All by rank.
#[derive(Debug, Clone, Default)]
pub struct CgScratch {
    r: Vec<Vector3>,
    z: Vec<Vector3>,
    p: Vec<Vector3>,
    q: Vec<Vector3>,
    t: Vec<Vector3>,
    /// The right-hand side and the iterate, gathered into the sweep order.
    b: Vec<Vector3>,
    x: Vec<Vector3>,
    /// The second half's products with the separator in a forward sweep (the first half adds
    /// its own to the separator's entries directly).
    spill: Vec<Vector3>,
    /// The vectors a start is projected onto, by rank, and their products with the matrix.
    span: Vec<SpanEntries>,
    span_products: SpanScratch,
    /// Last seen `(|r| / |r_0|) / (|r^| / |r^_0|)` of the SSOR solve (carried to the next
    /// solve's stopping test, so part of a [`super::resume::WarmStart`]).
    pub(crate) residual_ratio: f64,
}

/// Buffers of [`SpringSystem::project_start`].
#[derive(Debug, Clone, Default)]
struct SpanScratch {
    y: Vec<SpanEntries>,
    spill: Vec<SpanEntries>,
}

fn dot(a: &[Vector3], b: &[Vector3]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a.dot(b)).sum()
}

/// Solves `A x = b` by preconditioned conjugate gradients (SSOR, or block-Jacobi when SSOR does
/// not apply; see the module documentation), starting from the `x` given (warm start). Held
/// entries of `b` and `x` are treated as zero. Stops when
/// `|b - A x| <= max(relative_tolerance |b|, absolute_tolerance)`.
pub fn solve<B: OffBlock>(
    sys: &BlockSystem<B>,
    held: &[bool],
    b: &[Vector3],
    x: &mut [Vector3],
    settings: CgSettings,
    scratch: &mut CgScratch,
) -> CgReport {
    let parallel = b.len() >= PARALLEL_MIN_PARTICLES && solver_threads() > 1;
    solve_on(sys, held, b, x, None, settings, scratch, parallel)
}

/// [`solve`], starting from the projection onto the span of `x` (as given) and `more` (see
/// [`super::span`]): the start closest to the solution in the `A`-norm among their
/// combinations. Its residual comes with the products, so the projection costs one pass over
/// the springs that multiplies by all four vectors, in place of the first residual's. Vectors
/// of `more` that do not have one entry per particle are left out of the span.
pub fn solve_from_span<B: OffBlock>(
    sys: &BlockSystem<B>,
    held: &[bool],
    b: &[Vector3],
    x: &mut [Vector3],
    more: [&[Vector3]; SPAN - 1],
    settings: CgSettings,
    scratch: &mut CgScratch,
) -> CgReport {
    let parallel = b.len() >= PARALLEL_MIN_PARTICLES && solver_threads() > 1;
    let n = b.len();
    let more = more.map(|v| if v.len() == n { v } else { &[] as &[Vector3] });
    solve_on(sys, held, b, x, Some(more), settings, scratch, parallel)
}

/// [`solve`] or [`solve_from_span`] (with `more`), with the halves' sweeps on two threads or
/// not (the same bits either way).
#[allow(clippy::too_many_arguments)]
pub(super) fn solve_on<B: OffBlock>(
    sys: &BlockSystem<B>,
    held: &[bool],
    b: &[Vector3],
    x: &mut [Vector3],
    more: Option<[&[Vector3]; SPAN - 1]>,
    settings: CgSettings,
    scratch: &mut CgScratch,
    parallel: bool,
) -> CgReport {
    let n = b.len();
    for (xi, &h) in x.iter_mut().zip(held) {
        if h {
            *xi = Vector3::zeros();
        }
    }
    let b_norm = b
        .iter()
        .zip(held)
        .filter(|(_, h)| !**h)
        .map(|(b, _)| b.norm_squared())
        .sum::<f64>()
        .sqrt();
    if b_norm == 0.0 {
        x.iter_mut().for_each(|xi| *xi = Vector3::zeros());
        return CgReport {
            iterations: 0,
            relative_residual: 0.0,
            converged: true,
        };
    }
    // (every entry is written before it is read: no need to clear)
    for buf in [
        &mut scratch.r,
        &mut scratch.z,
        &mut scratch.p,
        &mut scratch.q,
        &mut scratch.t,
    ] {
        buf.resize(n, Vector3::zeros());
    }
    let order = &sys.layout.order[..n];
    let (mut b_ranked, mut x_ranked) = (
        std::mem::take(&mut scratch.b),
        std::mem::take(&mut scratch.x),
    );
    b_ranked.clear();
    b_ranked.extend(order.iter().map(|&i| b[i as usize]));
    x_ranked.clear();
    let ssor = sys.ssor && sys.chol.len() == n && sys.layout.start.len() == n + 1;
    // with a span: its projection, and the residual in `z` (where the SSOR solve wants it)
    let known = match more {
        Some(more) => {
            let span = &mut scratch.span;
            span.clear();
            span.extend(order.iter().map(|&i| {
                let i = i as usize;
                let at = |v: &[Vector3]| v.get(i).copied().unwrap_or_else(Vector3::zeros);
                if held[i] {
                    SpanEntries::ZERO
                } else {
                    SpanEntries::of([x[i], at(more[0]), at(more[1]), at(more[2])])
                }
            }));
            x_ranked.resize(n, Vector3::zeros());
            let run = |scratch: &mut CgScratch, x: &mut [Vector3]| {
                let CgScratch {
                    span,
                    span_products,
                    z,
                    ..
                } = scratch;
                sys.project_start(span, &b_ranked, x, z, span_products, parallel)
            };
            Some(if parallel {
                rayon::scope(|_| run(scratch, &mut x_ranked))
            } else {
                run(scratch, &mut x_ranked)
            })
        }
        None => {
            x_ranked.extend(order.iter().map(|&i| x[i as usize]));
            None
        }
    };
    let report = if ssor {
        if parallel {
            // on one of rayon's threads, so that handing the other half of a sweep over is cheap
            rayon::scope(|_| {
                solve_ssor(
                    sys,
                    &b_ranked,
                    &mut x_ranked,
                    b_norm,
                    known,
                    settings,
                    scratch,
                    true,
                )
            })
        } else {
            solve_ssor(
                sys,
                &b_ranked,
                &mut x_ranked,
                b_norm,
                known,
                settings,
                scratch,
                false,
            )
        }
    } else {
        if known.is_some() {
            let CgScratch { r, z, .. } = &mut *scratch;
            r.copy_from_slice(z);
        }
        solve_jacobi(
            sys,
            &b_ranked,
            &mut x_ranked,
            b_norm,
            known,
            settings,
            scratch,
        )
    };
    for (&i, x_k) in order.iter().zip(&x_ranked) {
        x[i as usize] = *x_k;
    }
    (scratch.b, scratch.x) = (b_ranked, x_ranked);
    report
}

/// `r = b - A x` (held entries zero), by rank; returns `|r|`.
fn residual<B: OffBlock>(
    sys: &BlockSystem<B>,
    b: &[Vector3],
    x: &[Vector3],
    r: &mut [Vector3],
    ax: &mut [Vector3],
    spill: &mut Vec<Vector3>,
    parallel: bool,
) -> f64 {
    sys.apply_ranked(x, ax, spill, parallel);
    let mut rr = 0.0;
    for k in 0..b.len() {
        r[k] = if sys.held[k] {
            Vector3::zeros()
        } else {
            b[k] - ax[k]
        };
        rr += r[k].norm_squared();
    }
    rr.sqrt()
}

/// Block-Jacobi preconditioned CG, by rank.
/// `known`: the norm of the residual of `x`, already in `r`.
fn solve_jacobi<B: OffBlock>(
    sys: &BlockSystem<B>,
    b: &[Vector3],
    x: &mut [Vector3],
    b_norm: f64,
    known: Option<f64>,
    settings: CgSettings,
    scratch: &mut CgScratch,
) -> CgReport {
    let n = b.len();
    let CgScratch {
        r, z, p, q, spill, ..
    } = scratch;
    let mut r_norm = match known {
        Some(r_norm) => r_norm,
        None => residual(sys, b, x, r, q, spill, false),
    };
    for k in 0..n {
        z[k] = sys.inv_diag[k].mul(&r[k]);
        p[k] = z[k];
    }
    let mut rz = dot(r, z);
    let target = (settings.relative_tolerance * b_norm).max(settings.absolute_tolerance);
    let mut iterations = 0;
    while r_norm > target && iterations < settings.max_iterations {
        sys.apply_ranked(p, q, spill, false);
        let pq = dot(p, q);
        if !(pq > 0.0) {
            break; // breakdown: the matrix is singular along p, or the numbers are bad
        }
        let alpha = rz / pq;
        // One pass: x and r updated, z = P r, and the dot products r.z and r.r.
        let (mut rz_next, mut rr) = (0.0, 0.0);
        for k in 0..n {
            x[k] += p[k] * alpha;
            r[k] -= q[k] * alpha;
            z[k] = sys.inv_diag[k].mul(&r[k]);
            rz_next += r[k].dot(&z[k]);
            rr += r[k].norm_squared();
        }
        let beta = rz_next / rz;
        rz = rz_next;
        for k in 0..n {
            p[k] = z[k] + p[k] * beta;
        }
        r_norm = rr.sqrt();
        iterations += 1;
    }
    CgReport {
        iterations,
        relative_residual: r_norm / b_norm,
        converged: r_norm <= target,
    }
}

/// SSOR preconditioned CG in Eisenstat's form (see the module documentation), by rank; the
/// halves' parts of each sweep side by side when `parallel`. The recursive residual is the
/// transformed `r^ = C^-1 (b - A x)`; iterations stop once `|r^|` has fallen by the factor the
/// tolerance asks of `|b - A x|`, corrected by the ratio of the two reductions seen at the last
/// check (`|r|` falls about half as fast as `|r^|` on the chest wall). The true residual is then
/// checked, and the iteration continued with a tighter target if it is not yet small enough.
/// `known`: the norm of the residual of `x`, already in the scratch's `z`.
#[allow(clippy::too_many_arguments)]
fn solve_ssor<B: OffBlock>(
    sys: &BlockSystem<B>,
    b: &[Vector3],
    x: &mut [Vector3],
    b_norm: f64,
    known: Option<f64>,
    settings: CgSettings,
    scratch: &mut CgScratch,
    parallel: bool,
) -> CgReport {
    let n = b.len();
    let CgScratch {
        r,
        z: acc,
        p,
        q,
        t,
        spill,
        residual_ratio,
        ..
    } = scratch;
    let (r, acc, p, q, t) = (
        &mut r[..n],
        &mut acc[..n],
        &mut p[..n],
        &mut q[..n],
        &mut t[..n],
    );
    let [h, s] = sys.layout.halves;
    let sweeps = Sweeps {
        start: &sys.layout.start[..=n],
        other: &sys.layout.other,
        coef: &sys.coef,
        inv_diag: &sys.inv_diag[..n],
        chol: &sys.chol[..n],
        s,
    };
    spill.resize(n - s, Vector3::zeros());
    let target = (settings.relative_tolerance * b_norm).max(settings.absolute_tolerance);

    let mut r_norm = match known {
        Some(r_norm) => r_norm,
        None => residual(sys, b, x, acc, q, spill, parallel),
    };
    if r_norm <= target {
        return CgReport {
            iterations: 0,
            relative_residual: r_norm / b_norm,
            converged: true,
        };
    }
    // r^ = G^T P^-1 r: forward sweep on acc = r.
    let transform =
        |acc: &mut [Vector3], r: &mut [Vector3], p: &mut [Vector3], spill: &mut [Vector3]| {
            let (acc1, acc2, acc_s) = split3(acc, h, s);
            let (r1, r2, r_s) = split3(r, h, s);
            let (p1, p2, p_s) = split3(p, h, s);
            spill.iter_mut().for_each(|v| *v = Vector3::zeros());
            join(
                parallel,
                || sweeps.forward_first(0, acc1, acc_s, r1, p1),
                || sweeps.forward_first(h, acc2, spill, r2, p2),
            );
            acc_s
                .iter_mut()
                .zip(spill.iter())
                .for_each(|(a, v)| *a += v);
            sweeps.forward_first(s, acc_s, &mut [], r_s, p_s);
        };
    transform(acc, r, p, spill);
    let mut rr = dot(r, r);
    let (r_norm0, rr0) = (r_norm, rr);
    let ratio = if *residual_ratio > 0.0 {
        residual_ratio.clamp(0.1, 10.0)
    } else {
        1.0
    };
    let mut target_hat = rr.sqrt() * (target / r_norm) / ratio;
    let mut beta = 0.0;
    let (mut iterations, mut checks) = (0, 0);
    while iterations < settings.max_iterations {
        let (r1, r2, r_s) = split3(r, h, s);
        let (p1, p2, p_s) = split3(p, h, s);
        let (t1, t2, t_s) = split3(t, h, s);
        let (acc1, acc2, acc_s) = split3(acc, h, s);
        let (q1, q2, q_s) = split3(q, h, s);
        // Backward sweep: the separator, then the halves.
        sweeps.backward(s, beta, r_s, p_s, t_s, &[], acc_s);
        let t_s: &[Vector3] = t_s;
        join(
            parallel,
            || sweeps.backward(0, beta, r1, p1, t1, t_s, acc1),
            || sweeps.backward(h, beta, r2, p2, t2, t_s, acc2),
        );
        // Forward sweep: the halves, then the separator with what both added to it.
        spill.iter_mut().for_each(|v| *v = Vector3::zeros());
        let (pq1, pq2) = join(
            parallel,
            || sweeps.forward(0, acc1, acc_s, t1, p1, q1),
            || sweeps.forward(h, acc2, spill, t2, p2, q2),
        );
        acc_s
            .iter_mut()
            .zip(spill.iter())
            .for_each(|(a, v)| *a += v);
        let pq = pq1 + pq2 + sweeps.forward(s, acc_s, &mut [], t_s, p_s, q_s);
        if !(pq > 0.0) {
            break; // breakdown: the matrix is singular along p, or the numbers are bad
        }
        let alpha = rr / pq;
        let update = |x: &mut [Vector3], r: &mut [Vector3], t: &[Vector3], q: &[Vector3]| {
            let mut rr_part = 0.0;
            for k in 0..x.len() {
                x[k] += t[k] * alpha;
                r[k] -= q[k] * alpha;
                rr_part += r[k].norm_squared();
            }
            rr_part
        };
        let m = n / 2;
        let (x1, x2) = x.split_at_mut(m);
        let (r1, r2) = r.split_at_mut(m);
        let (t1, t2) = t.split_at(m);
        let (q1, q2) = q.split_at(m);
        let (rr1, rr2) = join(
            parallel,
            || update(x1, r1, t1, q1),
            || update(x2, r2, t2, q2),
        );
        let rr_next = rr1 + rr2;
        beta = rr_next / rr;
        rr = rr_next;
        iterations += 1;
        if rr.sqrt() <= target_hat {
            r_norm = residual(sys, b, x, acc, q, spill, parallel);
            // an exact solve (rr = 0, as a few particles can reach) has no ratio: stored as 0,
            // which the next solve reads as none (as it read the NaN this once stored, which a
            // keyframe cannot carry); above 10 it is read as 10
            let ratio = (r_norm / r_norm0) / (rr.sqrt() / rr0.sqrt());
            *residual_ratio = if ratio.is_nan() { 0.0 } else { ratio.min(10.0) };
            if r_norm <= target {
                break;
            }
            checks += 1;
            if checks == 1 {
                // not there yet in the true norm: tighten the transformed target accordingly
                target_hat *= 0.5 * target / r_norm;
            } else {
                // again: the recursive residual has drifted from the true one (long solves of
                // stiff systems, such as the quadratic elements' slender bars); restart from
                // the true residual, now in `acc`
                transform(acc, r, p, spill);
                rr = dot(r, r);
                target_hat = 0.5 * rr.sqrt() * (target / r_norm);
                beta = 0.0;
            }
        }
    }
    if iterations == settings.max_iterations || !(r_norm <= target) {
        r_norm = residual(sys, b, x, acc, q, spill, parallel);
    }
    CgReport {
        iterations,
        relative_residual: r_norm / b_norm,
        converged: r_norm <= target,
    }
}

impl<B: OffBlock> BlockSystem<B> {
    /// The start of a solve projected onto the span of `span` (by rank, held entries zero;
    /// see [`super::span`]): `x = U c` and its residual `r = b - A x = b - (A U) c` (held
    /// entries zero), whose norm this returns. The Gram matrix and `U^T b` are summed over the
    /// two halves of the ranks, side by side when `parallel` (the same bits either way).
    fn project_start(
        &self,
        span: &[SpanEntries],
        b: &[Vector3],
        x: &mut [Vector3],
        r: &mut [Vector3],
        scratch: &mut SpanScratch,
        parallel: bool,
    ) -> f64 {
        let n = b.len();
        let SpanScratch { y, spill } = scratch;
        y.resize(n, SpanEntries::ZERO);
        self.apply_ranked(span, y, spill, parallel);
        let sums = |k0: usize, k1: usize| {
            let (mut g, mut f) = ([[0.0; SPAN]; SPAN], [0.0; SPAN]);
            for k in k0..k1 {
                let (u, y) = (&span[k], &y[k]);
                for i in 0..SPAN {
                    f[i] += u.get(i).dot(&b[k]);
                    for j in i..SPAN {
                        g[i][j] += u.get(i).dot(&y.get(j));
                    }
                }
            }
            (g, f)
        };
        let m = n / 2;
        let ((g1, f1), (g2, f2)) = join(parallel, || sums(0, m), || sums(m, n));
        let g = std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                let (i, j) = (i.min(j), i.max(j));
                g1[i][j] + g2[i][j]
            })
        });
        let f = std::array::from_fn(|i| f1[i] + f2[i]);
        let c = super::super::span::coefficients(&g, &f);
        let mut rr = 0.0;
        for k in 0..n {
            x[k] = span[k].combine(&c);
            r[k] = if self.held[k] {
                Vector3::zeros()
            } else {
                b[k] - y[k].combine(&c)
            };
            rr += r[k].norm_squared();
        }
        rr.sqrt()
    }
}
