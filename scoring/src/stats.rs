//! Statistics of the validity evidence and the metrics: Mann-Whitney U, the AUC with its
//! bootstrap interval, ICC(2,1), the contrasting-groups cut score, a learning curve's plateau,
//! Spearman's rho, Pearson's r, the mean and standard deviation.
//! Pure functions on plain slices; a sample too small for a statistic gives `None`.

use cutlab_sim::rng::Rng;

/// The standard normal distribution function, `Φ(x) = erfc(-x / √2) / 2`.
pub fn normal_cdf(x: f64) -> f64 {
    0.5 * libm::erfc(-x / std::f64::consts::SQRT_2)
}

/// Mean and sample standard deviation (`n - 1`); `None` below two values.
pub fn mean_sd(v: &[f64]) -> Option<(f64, f64)> {
    if v.len() < 2 {
        return None;
    }
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    Some((mean, var.sqrt()))
}

/// The median (the mean of the middle two for an even count); `None` when empty.
pub fn median(v: &[f64]) -> Option<f64> {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    match n {
        0 => None,
        _ if n % 2 == 1 => Some(s[n / 2]),
        _ => Some(0.5 * (s[n / 2 - 1] + s[n / 2])),
    }
}

/// A Mann-Whitney U test of `a` against `b`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct MannWhitney {
    /// `U_a = Σ_ij [a_i > b_j] + ½ [a_i = b_j]`: the pairs `a` wins, ties halved.
    pub u_a: f64,
    /// `U_a / (n_a n_b)`: the probability that a value of `a` exceeds one of `b` (ties
    /// counted half), the area under the ROC curve of `a` against `b`.
    pub auc: f64,
    /// The two-sided p value.
    pub p: f64,
    /// Whether `p` is exact (no ties, small samples) or from the normal approximation with
    /// the tie correction and the continuity correction.
    pub exact: bool,
}

/// Largest `n_a + n_b` for the exact distribution of U (its counts stay exact in `f64`).
const EXACT_MAX_N: usize = 40;

/// `U_a` of `a` against `b`: the pairs `a` wins, ties halved, from the ranks of the pooled
/// sample (`U_a = R_a - n_a (n_a + 1) / 2`, ties at their mean rank): `O(n log n)`, so the
/// bootstrap stays fast on a hub's thousands of attempts.
pub fn u_statistic(a: &[f64], b: &[f64]) -> f64 {
    let pooled: Vec<f64> = a.iter().chain(b).copied().collect();
    let r = ranks(&pooled);
    let na = a.len() as f64;
    r[..a.len()].iter().sum::<f64>() - na * (na + 1.0) / 2.0
}

/// The Mann-Whitney U test; `None` when either sample is empty or holds a non-finite value.
///
/// Exact p (the null distribution of U counted) when there are no ties and `n_a + n_b <=
/// 40`; otherwise `z = (|U_a - n_a n_b / 2| - ½) / σ` with `σ² = n_a n_b / 12 ((n + 1) -
/// Σ (t³ - t) / (n (n - 1)))` over the tie groups `t`, and `p = 2 (1 - Φ(z))`.
pub fn mann_whitney(a: &[f64], b: &[f64]) -> Option<MannWhitney> {
    if a.is_empty() || b.is_empty() || a.iter().chain(b).any(|x| !x.is_finite()) {
        return None;
    }
    let (na, nb) = (a.len(), b.len());
    let u_a = u_statistic(a, b);
    let auc = u_a / (na * nb) as f64;
    let mut all: Vec<f64> = a.iter().chain(b).copied().collect();
    all.sort_by(f64::total_cmp);
    let ties: Vec<f64> = all
        .chunk_by(|x, y| x == y)
        .map(|g| g.len() as f64)
        .filter(|t| *t > 1.0)
        .collect();
    let (p, exact) = if ties.is_empty() && na + nb <= EXACT_MAX_N {
        (exact_p(na, nb, u_a.round() as usize), true)
    } else {
        let n = (na + nb) as f64;
        let tie_term = ties.iter().map(|t| t * t * t - t).sum::<f64>() / (n * (n - 1.0));
        let var = (na * nb) as f64 / 12.0 * ((n + 1.0) - tie_term);
        let dev = (u_a - (na * nb) as f64 / 2.0).abs();
        let p = if var > 0.0 {
            let z = (dev - 0.5).max(0.0) / var.sqrt();
            (2.0 * (1.0 - normal_cdf(z))).min(1.0)
        } else {
            1.0
        };
        (p, false)
    };
    Some(MannWhitney { u_a, auc, p, exact })
}

/// The exact two-sided p of `U = u` for samples of `m` and `n` without ties: twice the
/// smaller tail, counted by `f(m, n, u) = f(m - 1, n, u - n) + f(m, n - 1, u)` (the largest
/// value is from the first sample, or from the second).
fn exact_p(m: usize, n: usize, u: usize) -> f64 {
    let max_u = m * n;
    // table[i][j] = counts of U for samples of i and j
    let mut table: Vec<Vec<Vec<f64>>> = vec![vec![Vec::new(); n + 1]; m + 1];
    for i in 0..=m {
        for j in 0..=n {
            let mut f = vec![0.0; i * j + 1];
            if i == 0 || j == 0 {
                f[0] = 1.0;
            } else {
                for (k, c) in table[i - 1][j].iter().enumerate() {
                    f[k + j] += c;
                }
                for (k, c) in table[i][j - 1].iter().enumerate() {
                    f[k] += c;
                }
            }
            table[i][j] = f;
        }
    }
    let f = &table[m][n];
    let total: f64 = f.iter().sum();
    let low: f64 = f[..=u.min(max_u)].iter().sum();
    let high: f64 = f[u.min(max_u)..].iter().sum();
    (2.0 * low.min(high) / total).min(1.0)
}

/// A percentile bootstrap 95 % interval of the AUC of `a` against `b`: both samples
/// resampled with replacement `resamples` times from the seeded generator.
pub fn auc_interval(a: &[f64], b: &[f64], resamples: usize, seed: u64) -> Option<(f64, f64)> {
    if a.is_empty() || b.is_empty() || resamples == 0 {
        return None;
    }
    let mut rng = Rng::new(seed);
    let mut draw = |v: &[f64]| -> Vec<f64> {
        (0..v.len())
            .map(|_| v[((rng.uniform() * v.len() as f64) as usize).min(v.len() - 1)])
            .collect()
    };
    let mut aucs: Vec<f64> = (0..resamples)
        .map(|_| {
            let (ra, rb) = (draw(a), draw(b));
            u_statistic(&ra, &rb) / (ra.len() * rb.len()) as f64
        })
        .collect();
    aucs.sort_by(f64::total_cmp);
    let at = |q: f64| aucs[((q * resamples as f64) as usize).min(resamples - 1)];
    Some((at(0.025), at(0.975)))
}

/// ICC(2,1) of Shrout and Fleiss (1979): two-way random effects, absolute agreement, a
/// single measurement, of `rows` (one per subject, `k >= 2` measurements each):
///
/// `ICC = (MS_R - MS_E) / (MS_R + (k - 1) MS_E + k (MS_C - MS_E) / n)`
///
/// with the mean squares of rows (subjects), columns (occasions) and the residual. `None`
/// below two subjects, for rows of unequal or too short length, or no variance at all.
pub fn icc_2_1(rows: &[Vec<f64>]) -> Option<f64> {
    let n = rows.len();
    let k = rows.first()?.len();
    if n < 2
        || k < 2
        || rows
            .iter()
            .any(|r| r.len() != k || r.iter().any(|x| !x.is_finite()))
    {
        return None;
    }
    let (nf, kf) = (n as f64, k as f64);
    let grand = rows.iter().flatten().sum::<f64>() / (nf * kf);
    let row_means: Vec<f64> = rows.iter().map(|r| r.iter().sum::<f64>() / kf).collect();
    let col_means: Vec<f64> = (0..k)
        .map(|j| rows.iter().map(|r| r[j]).sum::<f64>() / nf)
        .collect();
    let ss_rows = kf * row_means.iter().map(|m| (m - grand).powi(2)).sum::<f64>();
    let ss_cols = nf * col_means.iter().map(|m| (m - grand).powi(2)).sum::<f64>();
    let ss_total = rows
        .iter()
        .flatten()
        .map(|x| (x - grand).powi(2))
        .sum::<f64>();
    let ss_err = ss_total - ss_rows - ss_cols;
    let ms_r = ss_rows / (nf - 1.0);
    let ms_c = ss_cols / (kf - 1.0);
    let ms_e = ss_err / ((nf - 1.0) * (kf - 1.0));
    let den = ms_r + (kf - 1.0) * ms_e + kf * (ms_c - ms_e) / nf;
    (den > 0.0).then(|| (ms_r - ms_e) / den)
}

/// A cut score between a group that should pass and one that should not.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct CutScore {
    /// Where the two groups' fitted normal densities cross, between their means.
    pub cut: f64,
    /// Of the group that should not pass, the share at or above the cut (observed).
    pub false_pass: f64,
    /// Of the group that should pass, the share below the cut (observed).
    pub false_fail: f64,
    /// The same shares from the fitted normal distributions.
    pub false_pass_normal: f64,
    pub false_fail_normal: f64,
}

/// The contrasting-groups cut score (Livingston and Zieky): each group's scores fitted by a
/// normal distribution (mean, sample SD), the cut where the two densities cross between
/// the means, i.e. the root there of
///
/// `(x - μ_l)² / σ_l² - (x - μ_h)² / σ_h² = 2 ln(σ_h / σ_l)`
///
/// (the midpoint for equal SDs). `None` when a group has fewer than two scores, no spread,
/// or the passing group's mean is not above the other's.
pub fn contrasting_groups(pass: &[f64], fail: &[f64]) -> Option<CutScore> {
    let (mh, sh) = mean_sd(pass)?;
    let (ml, sl) = mean_sd(fail)?;
    if !(sh > 0.0 && sl > 0.0 && mh > ml) {
        return None;
    }
    // a x² + b x + c = 0 from the equation above, times σ_l² σ_h²
    let (vh, vl) = (sh * sh, sl * sl);
    let a = vh - vl;
    let b = -2.0 * (ml * vh - mh * vl);
    let c = ml * ml * vh - mh * mh * vl - 2.0 * vh * vl * (sh / sl).ln();
    let cut = if a.abs() < 1e-12 * vh.max(vl) {
        0.5 * (mh + ml)
    } else {
        let disc = (b * b - 4.0 * a * c).max(0.0).sqrt();
        let roots = [(-b + disc) / (2.0 * a), (-b - disc) / (2.0 * a)];
        *roots
            .iter()
            .find(|r| (ml..=mh).contains(*r))
            .unwrap_or(&(0.5 * (mh + ml)))
    };
    let share = |v: &[f64], f: &dyn Fn(f64) -> bool| {
        v.iter().filter(|x| f(**x)).count() as f64 / v.len() as f64
    };
    Some(CutScore {
        cut,
        false_pass: share(fail, &|x| x >= cut),
        false_fail: share(pass, &|x| x < cut),
        false_pass_normal: 1.0 - normal_cdf((cut - ml) / sl),
        false_fail_normal: normal_cdf((cut - mh) / sh),
    })
}

/// Where a learning curve levels off.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Plateau {
    /// The median of the last three scores: the level the trainee is at now.
    pub plateau: f64,
    /// The attempt (from 1) from which every later score lies within the band of the
    /// plateau.
    pub reached_at: usize,
    /// Whether that run holds at least [`PLATEAU_RUN`] attempts: the curve has levelled off.
    pub levelled: bool,
}

/// Attempts in a row within the band that make a plateau.
pub const PLATEAU_RUN: usize = 3;

/// The plateau of `scores` (in attempt order, at least four): the median of the last
/// [`PLATEAU_RUN`]; reached at the first attempt from which every score lies within `band`
/// of it; levelled when that run is at least [`PLATEAU_RUN`] attempts long. An empirical
/// rule (no curve is fitted), after the moving-window plateaus of surgical learning-curve
/// studies.
pub fn plateau(scores: &[f64], band: f64) -> Option<Plateau> {
    if scores.len() < 4 || scores.iter().any(|x| !x.is_finite()) {
        return None;
    }
    let level = median(&scores[scores.len() - PLATEAU_RUN..])?;
    let run = scores
        .iter()
        .rev()
        .take_while(|s| (*s - level).abs() <= band)
        .count();
    Some(Plateau {
        plateau: level,
        reached_at: scores.len() - run + 1,
        levelled: run >= PLATEAU_RUN,
    })
}

/// Ranks from 1, ties given their mean rank.
pub fn ranks(v: &[f64]) -> Vec<f64> {
    let mut order: Vec<usize> = (0..v.len()).collect();
    order.sort_by(|&i, &j| v[i].total_cmp(&v[j]));
    let mut r = vec![0.0; v.len()];
    let mut i = 0;
    while i < order.len() {
        let mut j = i;
        while j + 1 < order.len() && v[order[j + 1]] == v[order[i]] {
            j += 1;
        }
        let mean_rank = 0.5 * (i + j) as f64 + 1.0;
        for &k in &order[i..=j] {
            r[k] = mean_rank;
        }
        i = j + 1;
    }
    r
}

/// Pearson's correlation; `None` below three pairs, for unequal lengths, a non-finite value
/// or no spread.
pub fn pearson(x: &[f64], y: &[f64]) -> Option<f64> {
    if x.len() != y.len() || x.len() < 3 || x.iter().chain(y).any(|v| !v.is_finite()) {
        return None;
    }
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = x.iter().map(|a| (a - mx).powi(2)).sum();
    let syy: f64 = y.iter().map(|b| (b - my).powi(2)).sum();
    (sxx > 0.0 && syy > 0.0).then(|| sxy / (sxx * syy).sqrt())
}

/// Spearman's rho: Pearson's correlation of the ranks (ties at their mean rank); `None`
/// below three pairs, for unequal lengths or no spread.
pub fn spearman(x: &[f64], y: &[f64]) -> Option<f64> {
    if x.len() != y.len() || x.iter().chain(y).any(|v| !v.is_finite()) {
        return None;
    }
    pearson(&ranks(x), &ranks(y))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn the_normal_distribution_function_at_known_points() {
        // tables: Φ(0) = 0.5, Φ(1) = 0.841345, Φ(1.96) = 0.975002, Φ(-2) = 0.022750
        assert!(close(normal_cdf(0.0), 0.5, 1e-15));
        assert!(close(normal_cdf(1.0), 0.841_344_746, 1e-9));
        assert!(close(normal_cdf(1.96), 0.975_002_105, 1e-9));
        assert!(close(normal_cdf(-2.0), 0.022_750_132, 1e-9));
    }

    #[test]
    fn mann_whitney_on_separated_samples_by_hand() {
        // every b above every a: U_a = 0; of the C(6, 3) = 20 orders one gives U = 0 and one
        // U = 9, so p = 2 / 20
        let m = mann_whitney(&[1.0, 2.0, 3.0], &[4.0, 5.0, 6.0]).unwrap();
        assert_eq!(m.u_a, 0.0);
        assert_eq!(m.auc, 0.0);
        assert!(m.exact && close(m.p, 0.1, 1e-12), "{m:?}");
        let m = mann_whitney(&[4.0, 5.0, 6.0], &[1.0, 2.0, 3.0]).unwrap();
        assert_eq!((m.u_a, m.auc), (9.0, 1.0));
        assert!(close(m.p, 0.1, 1e-12));
        // one a above one b: a = {1, 3}, b = {2, 4}: U_a = 1 of 4; U <= 1 in 2 of the 6
        // orders (U = 0: 1 2 | 3 4; U = 1: 1 3 | 2 4), so p = 2 * 2 / 6
        let m = mann_whitney(&[1.0, 3.0], &[2.0, 4.0]).unwrap();
        assert_eq!(m.u_a, 1.0);
        assert!(close(m.p, 2.0 / 3.0, 1e-12), "{m:?}");
    }

    #[test]
    fn mann_whitney_with_ties_uses_the_corrected_normal_approximation() {
        // a = 1 2 2 3, b = 2 3 4 5: U_a = 0 + 0.5 + 0.5 + (1 + 0.5) = 2.5 (by hand); ties
        // {2, 2, 2} and {3, 3}: σ² = 16 / 12 (9 - (24 + 6) / 56) = 11.2857, z = (8 - 2.5 -
        // 0.5) / 3.3594 = 1.4883, p = 0.1367 (scipy.stats.mannwhitneyu, asymptotic, with
        // the continuity correction: 0.136658)
        let m = mann_whitney(&[1.0, 2.0, 2.0, 3.0], &[2.0, 3.0, 4.0, 5.0]).unwrap();
        assert_eq!(m.u_a, 2.5);
        assert!(!m.exact);
        assert!(close(m.p, 0.136_658, 1e-5), "{m:?}");
        assert!(mann_whitney(&[], &[1.0]).is_none());
        assert!(mann_whitney(&[f64::NAN], &[1.0]).is_none());
    }

    #[test]
    fn auc_interval_brackets_the_auc_and_is_reproducible() {
        let a: Vec<f64> = (0..12).map(|i| 1.0 + 0.3 * i as f64).collect();
        let b: Vec<f64> = (0..12).map(|i| 0.5 * i as f64).collect();
        let auc = mann_whitney(&a, &b).unwrap().auc;
        let (lo, hi) = auc_interval(&a, &b, 2000, 45).unwrap();
        assert!(
            0.0 <= lo && lo < auc && auc < hi && hi <= 1.0 && hi - lo > 0.2,
            "{lo} {auc} {hi}"
        );
        assert_eq!(auc_interval(&a, &b, 2000, 45), Some((lo, hi)));
        // separated samples: every resample is separated too
        assert_eq!(
            auc_interval(&[5.0, 6.0], &[1.0, 2.0], 500, 1),
            Some((1.0, 1.0))
        );
    }

    #[test]
    fn icc_of_shrout_and_fleiss_table_2() {
        // Shrout & Fleiss (1979), Table 2: 6 targets by 4 judges; ICC(2,1) = .29
        let rows = [
            [9.0, 2.0, 5.0, 8.0],
            [6.0, 1.0, 3.0, 2.0],
            [8.0, 4.0, 6.0, 8.0],
            [7.0, 1.0, 2.0, 6.0],
            [10.0, 5.0, 6.0, 9.0],
            [6.0, 2.0, 4.0, 7.0],
        ]
        .map(|r| r.to_vec());
        let icc = icc_2_1(&rows).unwrap();
        assert!(close(icc, 0.2898, 1e-4), "{icc}");
        // perfect agreement: 1
        let same: Vec<Vec<f64>> = (0..5).map(|i| vec![i as f64, i as f64]).collect();
        assert!(close(icc_2_1(&same).unwrap(), 1.0, 1e-12));
        assert!(icc_2_1(&rows[..1]).is_none());
        assert!(icc_2_1(&[vec![1.0, 2.0], vec![1.0]]).is_none());
    }

    #[test]
    fn contrasting_groups_cut_by_hand() {
        // equal SDs (1): the midpoint of the means 2 and 6; each tail beyond 2 SD: 0.02275
        let c = contrasting_groups(&[5.0, 6.0, 7.0], &[1.0, 2.0, 3.0]).unwrap();
        assert!(close(c.cut, 4.0, 1e-12), "{c:?}");
        assert_eq!((c.false_pass, c.false_fail), (0.0, 0.0));
        assert!(close(c.false_pass_normal, 0.022_750, 1e-6));
        assert!(close(c.false_fail_normal, 0.022_750, 1e-6));
        // N(0, 1) against N(3, 2): -x²/2 = -(x - 3)²/8 - ln 2, i.e. 3x² + 6x - 9 - 8 ln 2 =
        // 0, x = (-6 + sqrt(36 + 12 (9 + 8 ln 2))) / 6 = 1.41838
        let c = contrasting_groups(&[1.0, 3.0, 5.0], &[-1.0, 0.0, 1.0]).unwrap();
        let x = (-6.0 + (36.0 + 12.0 * (9.0 + 8.0 * 2f64.ln())).sqrt()) / 6.0;
        assert!(close(c.cut, x, 1e-9) && close(x, 1.418_345, 1e-6), "{c:?}");
        // observed: of 1 3 5 below 1.4183: one; of -1 0 1 at or above: none
        assert!(close(c.false_fail, 1.0 / 3.0, 1e-12) && c.false_pass == 0.0);
        assert!(close(c.false_pass_normal, 1.0 - normal_cdf(x), 1e-12));
        // the passing group not better, or no spread: no cut
        assert!(contrasting_groups(&[1.0, 2.0], &[3.0, 4.0]).is_none());
        assert!(contrasting_groups(&[3.0, 3.0], &[1.0, 2.0]).is_none());
        assert!(contrasting_groups(&[3.0], &[1.0, 2.0]).is_none());
    }

    #[test]
    fn plateaus_by_hand() {
        // the last three 0.97 0.97 1.00: median 0.97; within 0.1 of it from attempt 5 on
        let p = plateau(&[0.04, -0.28, 0.60, 0.73, 0.97, 0.97, 1.0], 0.1).unwrap();
        assert_eq!((p.plateau, p.reached_at, p.levelled), (0.97, 5, true));
        // still climbing: the median of -0.57 0.15 0.03 is 0.03; only the last is within 0.1
        let p = plateau(&[-0.39, -0.57, 0.15, 0.03], 0.1).unwrap();
        assert_eq!((p.plateau, p.reached_at, p.levelled), (0.03, 4, false));
        // level from the first attempt
        let p = plateau(&[1.0, 1.0, 0.99, 0.99], 0.1).unwrap();
        assert_eq!((p.reached_at, p.levelled), (1, true));
        assert!(plateau(&[0.1, 0.2, 0.3], 0.1).is_none());
        assert!(plateau(&[0.1, 0.2, 0.3, f64::NAN], 0.1).is_none());
    }

    #[test]
    fn spearman_by_hand() {
        // ranks x 1 2 3 4 5, y 2 1 4 3 5: d² = 1+1+1+1+0 = 4, rho = 1 - 6*4/(5*24) = 0.8
        let rho = spearman(&[1.0, 2.0, 3.0, 4.0, 5.0], &[20.0, 10.0, 40.0, 30.0, 50.0]).unwrap();
        assert!(close(rho, 0.8, 1e-12), "{rho}");
        assert!(close(
            spearman(&[1.0, 2.0, 3.0], &[3.0, 2.0, 1.0]).unwrap(),
            -1.0,
            1e-12
        ));
        assert_eq!(ranks(&[3.0, 1.0, 3.0, 2.0]), vec![3.5, 1.0, 3.5, 2.0]);
        // U from the ranks is the pair count: a = 1 2 2 3 against b = 2 3 4 5 wins 0, ½,
        // ½ and 1 + ½ of its pairs
        assert_eq!(
            u_statistic(&[1.0, 2.0, 2.0, 3.0], &[2.0, 3.0, 4.0, 5.0]),
            2.5
        );
        assert!(spearman(&[1.0, 1.0, 1.0], &[1.0, 2.0, 3.0]).is_none());
    }
}
