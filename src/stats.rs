//! Summary statistics of timing samples.

use serde::Serialize;

/// Median, 99th percentile, mean and maximum of a sample, in the sample's unit.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct Summary {
    pub count: usize,
    pub median: f64,
    pub p99: f64,
    pub mean: f64,
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
        let q = |p: f64| s[((p * (s.len() - 1) as f64).round() as usize).min(s.len() - 1)];
        Self {
            count: s.len(),
            median: q(0.5),
            p99: q(0.99),
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
}
