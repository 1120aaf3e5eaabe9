//! Do the motion metrics predict raters' ratings of people they have not seen? Leave one
//! subject out: for each subject, a composite of the metrics is fitted on the other
//! subjects' trials and predicts this subject's; Spearman's rho of all the out-of-fold
//! predictions with the ratings says how well the composite generalises across people.
//!
//! The composites' form is fixed here, before any data: each metric oriented by its
//! direction (larger is better), standardised by the training trials' mean and SD, then
//!
//! - [`Composite::MeanZ`]: the mean of the standardised metrics, mapped to the rating by a
//!   straight line fitted on the training trials (nothing else is fitted);
//! - [`Composite::Ridge`]: ridge regression of the rating on the standardised metrics, with
//!   the penalty `λ = n_train` (one unit per training trial on the standardised scale).
//!
//! Metrics missing in a trial take the training mean (zero once standardised).

use nalgebra::{DMatrix, DVector};
use serde::Serialize;

use super::report::{EvidenceAttempt, definition};
use crate::metrics::Better;
use crate::stats;

/// How the metrics are combined.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Composite {
    MeanZ,
    Ridge,
}

/// The out-of-fold agreement of one composite of a set of metrics.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Prediction {
    pub family: String,
    pub composite: Composite,
    pub metrics: usize,
    /// Trials predicted (of subjects with a rating, each once).
    pub n: usize,
    pub subjects: usize,
    /// Spearman's rho of the out-of-fold predictions with the ratings.
    pub rho: Option<f64>,
}

/// The oriented value of `key` in `a` (larger is better), `None` when absent.
fn oriented(a: &EvidenceAttempt, key: &str) -> Option<f64> {
    let v = a.metrics.iter().find(|(k, _)| k == key)?.1;
    v.is_finite().then(|| match definition(key).2 {
        Better::LowerIsBetter => -v,
        _ => v,
    })
}

/// The training trials' standardised features and the test trials', by the training
/// mean and SD (a metric without spread in training is dropped).
fn standardise(
    train: &[&EvidenceAttempt],
    test: &[&EvidenceAttempt],
    keys: &[String],
) -> (DMatrix<f64>, DMatrix<f64>) {
    let mut cols_train = Vec::new();
    let mut cols_test = Vec::new();
    for key in keys {
        let v: Vec<f64> = train.iter().filter_map(|a| oriented(a, key)).collect();
        let Some((mean, sd)) = stats::mean_sd(&v) else {
            continue;
        };
        if !(sd > 0.0) {
            continue;
        }
        let z = |a: &&EvidenceAttempt| oriented(a, key).map_or(0.0, |x| (x - mean) / sd);
        cols_train.push(train.iter().map(z).collect::<Vec<f64>>());
        cols_test.push(test.iter().map(z).collect::<Vec<f64>>());
    }
    let m = |cols: &[Vec<f64>], rows: usize| DMatrix::from_fn(rows, cols.len(), |i, j| cols[j][i]);
    (m(&cols_train, train.len()), m(&cols_test, test.len()))
}

/// The straight line `y = a + b x` by least squares; `(mean y, 0)` without spread in `x`.
fn line(x: &[f64], y: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxx: f64 = x.iter().map(|v| (v - mx).powi(2)).sum();
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let b = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    (my - b * mx, b)
}

/// One fold: the composite fitted on `train`, predicting `test`.
fn fold(
    train: &[&EvidenceAttempt],
    test: &[&EvidenceAttempt],
    keys: &[String],
    composite: Composite,
) -> Vec<f64> {
    let y: Vec<f64> = train.iter().filter_map(|a| a.rating).collect();
    let (xt, xs) = standardise(train, test, keys);
    let my = y.iter().sum::<f64>() / y.len() as f64;
    if xt.ncols() == 0 {
        return vec![my; test.len()];
    }
    match composite {
        Composite::MeanZ => {
            let c = |x: &DMatrix<f64>| -> Vec<f64> { x.row_iter().map(|r| r.mean()).collect() };
            let (a, b) = line(&c(&xt), &y);
            c(&xs).iter().map(|v| a + b * v).collect()
        }
        Composite::Ridge => {
            let yc = DVector::from_iterator(y.len(), y.iter().map(|v| v - my));
            let lambda = train.len() as f64;
            let gram = xt.transpose() * &xt + DMatrix::identity(xt.ncols(), xt.ncols()) * lambda;
            let w = gram
                .cholesky()
                .map(|c| c.solve(&(xt.transpose() * yc)))
                .unwrap_or_else(|| DVector::zeros(xt.ncols()));
            (xs * w).iter().map(|v| my + v).collect()
        }
    }
}

/// Leave one subject out over the rated attempts with the metrics `keys`.
pub fn leave_one_subject_out(
    attempts: &[EvidenceAttempt],
    family: &str,
    keys: &[String],
    composite: Composite,
) -> Prediction {
    let rated: Vec<&EvidenceAttempt> = attempts
        .iter()
        .filter(|a| a.rating.is_some_and(f64::is_finite))
        .collect();
    let mut subjects: Vec<i64> = rated.iter().map(|a| a.trainee_id).collect();
    subjects.sort_unstable();
    subjects.dedup();
    let (mut predicted, mut actual) = (Vec::new(), Vec::new());
    if subjects.len() >= 3 {
        for s in &subjects {
            let (test, train): (Vec<&EvidenceAttempt>, Vec<&EvidenceAttempt>) =
                rated.iter().partition(|a| a.trainee_id == *s);
            predicted.extend(fold(&train, &test, keys, composite));
            actual.extend(test.iter().filter_map(|a| a.rating));
        }
    }
    Prediction {
        family: family.to_owned(),
        composite,
        metrics: keys.len(),
        n: predicted.len(),
        subjects: subjects.len(),
        rho: stats::spearman(&predicted, &actual),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trial(id: i64, subject: i64, rating: f64, metrics: Vec<(&str, f64)>) -> EvidenceAttempt {
        EvidenceAttempt {
            attempt_id: id,
            trainee_id: subject,
            trainee: format!("s{subject}"),
            experience: None,
            started_ns: id,
            reference: false,
            score: Some(rating),
            metrics: metrics
                .into_iter()
                .map(|(k, v)| (k.to_owned(), v))
                .collect(),
            rating: Some(rating),
        }
    }

    /// Six subjects, three trials each; the time falls as the rating rises for everyone,
    /// and a noise metric follows the subject, not the rating.
    fn trials() -> Vec<EvidenceAttempt> {
        let mut v = Vec::new();
        for s in 0..6 {
            for k in 0..3 {
                let rating = 10.0 + 3.0 * s as f64 + k as f64;
                let id = (3 * s + k) as i64;
                v.push(trial(
                    id,
                    s as i64,
                    rating,
                    vec![
                        ("time_s", 100.0 - 2.0 * rating),
                        ("peak_force_n", ((s * 37) % 7) as f64),
                    ],
                ));
            }
        }
        v
    }

    #[test]
    fn a_metric_that_follows_the_rating_predicts_unseen_subjects() {
        let v = trials();
        for composite in [Composite::MeanZ, Composite::Ridge] {
            let p = leave_one_subject_out(&v, "time", &["time_s".into()], composite);
            assert_eq!((p.n, p.subjects), (18, 6));
            assert!(p.rho.unwrap() > 0.99, "{p:?}");
            // a metric that follows the person does not
            let p = leave_one_subject_out(&v, "noise", &["peak_force_n".into()], composite);
            assert!(p.rho.is_none_or(|r| r.abs() < 0.7), "{p:?}");
        }
    }

    #[test]
    fn too_few_subjects_predict_nothing() {
        let v: Vec<EvidenceAttempt> = trials().into_iter().filter(|a| a.trainee_id < 2).collect();
        let p = leave_one_subject_out(&v, "time", &["time_s".into()], Composite::Ridge);
        assert_eq!((p.n, p.rho), (0, None));
    }
}
