//! The start of a solve projected onto the span of a few vectors (Galerkin): of all
//! `x_0 = sum_j c_j u_j`, the one closest to the solution of `A x = b` in the `A`-norm, from
//! the Gram matrix `G_ij = u_i^T A u_j` and `f_i = u_i^T b` by `G c = f`. The implicit step
//! projects onto its last velocity changes and their extrapolation (see
//! [`super::implicit`]): a start at least as good, in that norm, as the extrapolation alone.

/// How many vectors a start may be projected onto.
pub const SPAN: usize = 4;

/// A vector whose `A`-norm, once its part along the vectors before it is removed, is below the
/// square root of this times its own `A`-norm counts as dependent on them and gets no
/// coefficient.
const DEPENDENT: f64 = 1e-10;

/// `c` with `G c = f` on the vectors independent of those before them (the others get 0):
/// `G` scaled to a unit diagonal, factored as `L D L^T` in the vectors' order, a pivot below
/// [`DEPENDENT`] (or a vector with no positive, finite `G_jj`) dropping its vector.
pub fn coefficients(g: &[[f64; SPAN]; SPAN], f: &[f64; SPAN]) -> [f64; SPAN] {
    let scale: [f64; SPAN] = std::array::from_fn(|j| {
        let d = g[j][j];
        if d > 0.0 && d.is_finite() {
            1.0 / d.sqrt()
        } else {
            0.0
        }
    });
    let a = |i: usize, j: usize| g[i][j] * scale[i] * scale[j];
    let mut l = [[0.0; SPAN]; SPAN];
    let mut d = [0.0; SPAN];
    let mut kept = [false; SPAN];
    for k in 0..SPAN {
        if scale[k] == 0.0 {
            continue;
        }
        let dk = a(k, k)
            - (0..k)
                .filter(|&j| kept[j])
                .map(|j| l[k][j] * l[k][j] * d[j])
                .sum::<f64>();
        if !(dk > DEPENDENT) {
            continue;
        }
        (kept[k], d[k]) = (true, dk);
        for i in k + 1..SPAN {
            if scale[i] != 0.0 {
                let sum: f64 = (0..k)
                    .filter(|&j| kept[j])
                    .map(|j| l[i][j] * l[k][j] * d[j])
                    .sum();
                l[i][k] = (a(i, k) - sum) / dk;
            }
        }
    }
    // L y = S f, then L^T c' = D^-1 y, c = S c'
    let mut y = [0.0; SPAN];
    for i in (0..SPAN).filter(|&i| kept[i]) {
        y[i] = f[i] * scale[i]
            - (0..i)
                .filter(|&j| kept[j])
                .map(|j| l[i][j] * y[j])
                .sum::<f64>();
    }
    let mut c = [0.0; SPAN];
    for i in (0..SPAN).rev().filter(|&i| kept[i]) {
        c[i] = y[i] / d[i]
            - (i + 1..SPAN)
                .filter(|&j| kept[j])
                .map(|j| l[j][i] * c[j])
                .sum::<f64>();
    }
    for (c, s) in c.iter_mut().zip(scale) {
        *c *= s;
    }
    if c.iter().all(|c| c.is_finite()) {
        c
    } else {
        [0.0; SPAN]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gram(u: &[[f64; 3]; SPAN], a: &[[f64; 3]; 3]) -> [[f64; SPAN]; SPAN] {
        let au = |v: &[f64; 3]| -> [f64; 3] {
            std::array::from_fn(|r| (0..3).map(|k| a[r][k] * v[k]).sum())
        };
        std::array::from_fn(|i| {
            std::array::from_fn(|j| au(&u[j]).iter().zip(&u[i]).map(|(x, y)| x * y).sum())
        })
    }

    #[test]
    fn independent_vectors_give_the_galerkin_solution() {
        // in 4 dimensions with 4 independent vectors the projection is the exact solution
        let a = [
            [4.0, 1.0, 0.0, 0.5],
            [1.0, 3.0, 0.2, 0.0],
            [0.0, 0.2, 2.0, 0.1],
            [0.5, 0.0, 0.1, 1.5],
        ];
        let u = [
            [1.0, 0.0, 0.5, 0.0],
            [0.0, 2.0, 0.0, 0.1],
            [0.3, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 3.0],
        ];
        let x_true = [0.7, -1.2, 0.4, 2.0];
        let b: [f64; 4] = std::array::from_fn(|r| (0..4).map(|k| a[r][k] * x_true[k]).sum());
        let au = |v: &[f64; 4]| -> [f64; 4] {
            std::array::from_fn(|r| (0..4).map(|k| a[r][k] * v[k]).sum())
        };
        let dot = |p: &[f64; 4], q: &[f64; 4]| p.iter().zip(q).map(|(x, y)| x * y).sum::<f64>();
        let g = std::array::from_fn(|i| std::array::from_fn(|j| dot(&u[i], &au(&u[j]))));
        let f = std::array::from_fn(|i| dot(&u[i], &b));
        let c = coefficients(&g, &f);
        let x: [f64; 4] = std::array::from_fn(|r| (0..SPAN).map(|j| c[j] * u[j][r]).sum());
        for (x, t) in x.iter().zip(&x_true) {
            assert!((x - t).abs() < 1e-12, "{x:?} vs {x_true:?}");
        }
    }

    #[test]
    fn dependent_and_zero_vectors_are_dropped_and_the_rest_is_optimal() {
        // in 3 dimensions: u1 = 2 u0, u2 zero, u3 independent: the optimum over span{u0, u3}
        let a = [[3.0, 0.5, 0.0], [0.5, 2.0, 0.3], [0.0, 0.3, 1.0]];
        let u = [[1.0, 1.0, 0.0], [2.0, 2.0, 0.0], [0.0; 3], [0.0, 1.0, 1.0]];
        let b = [1.0, -2.0, 0.5];
        let g = gram(&u, &a);
        let f: [f64; SPAN] = std::array::from_fn(|i| u[i].iter().zip(&b).map(|(x, y)| x * y).sum());
        let c = coefficients(&g, &f);
        assert_eq!((c[1], c[2]), (0.0, 0.0), "{c:?}");
        // optimal over the two kept: the 2x2 Galerkin system
        let (g00, g03, g33) = (g[0][0], g[0][3], g[3][3]);
        let det = g00 * g33 - g03 * g03;
        let (c0, c3) = (
            (g33 * f[0] - g03 * f[3]) / det,
            (g00 * f[3] - g03 * f[0]) / det,
        );
        assert!(
            (c[0] - c0).abs() < 1e-12 && (c[3] - c3).abs() < 1e-12,
            "{c:?} vs {c0} {c3}"
        );
    }

    #[test]
    fn bad_numbers_give_no_start() {
        let mut g = [[0.0; SPAN]; SPAN];
        assert_eq!(coefficients(&g, &[1.0; SPAN]), [0.0; SPAN]);
        g[0][0] = f64::NAN;
        g[1][1] = 1.0;
        assert_eq!(coefficients(&g, &[1.0, f64::NAN, 0.0, 0.0]), [0.0; SPAN]);
        assert_eq!(
            coefficients(&g, &[1.0, 2.0, 0.0, 0.0]),
            [0.0, 2.0, 0.0, 0.0]
        );
    }
}
