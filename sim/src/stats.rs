//! Summary statistics of samples (timings, mostly): one definition of a percentile for the
//! whole workspace (benchmarks, the servo's period statistics, the demo, the session summary).

use serde::Serialize;

/// The `p`-quantile (`p` in [0, 1]) of `sorted` (ascending): the sample nearest to rank
/// `p (n - 1)` (ties rounded away from zero; no interpolation), so the median of an even
/// sample is its upper middle. NaN for an empty sample.
pub fn percentile(sorted: &[f64], p: f64) -> f64 {
    match sorted.len() {
        0 => f64::NAN,
        n => sorted[((p * (n - 1) as f64).round() as usize).min(n - 1)],
    }
}

/// Median, 99th percentile, mean and maximum of a sample, in the sample's unit.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct Summary {
    /// The number of samples.
    pub count: usize,
    /// The 50th percentile (nearest rank).
    pub median: f64,
    /// The 99th percentile (nearest rank).
    pub p99: f64,
    /// The arithmetic mean.
    pub mean: f64,
    /// The largest sample.
    pub max: f64,
}

impl Summary {
    /// Summarises `samples` (order irrelevant); an empty sample gives zeros.
    pub fn of(samples: &[f64]) -> Self {
        if samples.is_empty() {
            return Self {
                count: 0,
                median: 0.0,
                p99: 0.0,
                mean: 0.0,
                max: 0.0,
            };
        }
        let mut s = samples.to_vec();
        s.sort_by(f64::total_cmp);
        Self {
            count: s.len(),
            median: percentile(&s, 0.5),
            p99: percentile(&s, 0.99),
            mean: s.iter().sum::<f64>() / s.len() as f64,
            max: s[s.len() - 1],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_of_one_to_hundred_and_one() {
        let v: Vec<f64> = (1..=101).rev().map(f64::from).collect();
        let s = Summary::of(&v);
        assert_eq!((s.median, s.p99, s.max, s.count), (51.0, 100.0, 101.0, 101));
        assert!((s.mean - 51.0).abs() < 1e-12);
    }

    #[test]
    fn percentile_picks_the_nearest_rank() {
        let v = [1.0, 2.0, 3.0, 4.0];
        // ranks 0, 1.5 -> 2, 2.97 -> 3
        assert_eq!(
            (
                percentile(&v, 0.0),
                percentile(&v, 0.5),
                percentile(&v, 0.99)
            ),
            (1.0, 3.0, 4.0)
        );
        // the median of an even sample is the upper middle: index n / 2
        for n in 1..40 {
            let v: Vec<f64> = (0..n).map(f64::from).collect();
            assert_eq!(percentile(&v, 0.5), v[v.len() / 2]);
        }
        assert!(percentile(&[], 0.5).is_nan());
    }
}
