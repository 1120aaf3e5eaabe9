//! Signal processing for the path metrics: uniform resampling, the zero-phase low-pass
//! filter applied before differentiating, and the two smoothness measures of
//! Balasubramanian, Melendez-Calderon, Roby-Brami and Burdet, *On the analysis of movement
//! smoothness*, J NeuroEng Rehabil 12:112 (2015): log dimensionless jerk and SPARC.

use std::f64::consts::{PI, SQRT_2};

use rustfft::FftPlanner;
use rustfft::num_complex::Complex;

/// Linear interpolation of the samples `(t[i], x[i])` (strictly increasing `t`) onto the
/// uniform grid `t[0] + k / fs`, `k = 0 ..= floor((t_last - t[0]) fs)`.
pub fn resample(t: &[f64], x: &[f64], fs: f64) -> Vec<f64> {
    if t.is_empty() {
        return Vec::new();
    }
    let n = ((t[t.len() - 1] - t[0]) * fs + 1e-9).floor() as usize + 1;
    let mut out = Vec::with_capacity(n);
    let mut j = 0;
    for k in 0..n {
        let tk = t[0] + k as f64 / fs;
        while j + 2 < t.len() && t[j + 1] < tk {
            j += 1;
        }
        if t.len() == 1 {
            out.push(x[0]);
            continue;
        }
        let (t0, t1) = (t[j], t[j + 1]);
        let a = ((tk - t0) / (t1 - t0)).clamp(0.0, 1.0);
        out.push(x[j] + a * (x[j + 1] - x[j]));
    }
    out
}

/// Zero-phase low-pass filter: a 2nd-order Butterworth section (bilinear transform with
/// pre-warping, `K = tan(pi fc / fs)`,
/// `b = [K^2, 2K^2, K^2] / (1 + sqrt2 K + K^2)`,
/// `a = [1, 2(K^2 - 1), 1 - sqrt2 K + K^2] / (1 + sqrt2 K + K^2)`) run forwards and then
/// backwards (`filtfilt`: no phase lag, magnitude response squared, so effectively 4th order
/// with -6 dB at `fc`). The ends are padded by odd reflection (`2 x0 - x[k]`, up to 50
/// samples) and the filter starts in its steady state, which keeps ramps free of edge
/// transients. `fc >= fs / 2` or fewer than 3 samples: returned unfiltered.
pub fn lowpass_zero_phase(x: &[f64], fs: f64, fc: f64) -> Vec<f64> {
    if x.len() < 3 || !(fc > 0.0) || fc >= 0.5 * fs {
        return x.to_vec();
    }
    let k = (PI * fc / fs).tan();
    let norm = 1.0 / (1.0 + SQRT_2 * k + k * k);
    let b0 = k * k * norm;
    let (b1, b2) = (2.0 * b0, b0);
    let a1 = 2.0 * (k * k - 1.0) * norm;
    let a2 = (1.0 - SQRT_2 * k + k * k) * norm;
    let run = |x: &mut Vec<f64>| {
        // transposed direct form II, steady state for the first value
        let c = x[0];
        let mut z2 = (b2 - a2) * c;
        let mut z1 = (b1 - a1) * c + z2;
        for v in x.iter_mut() {
            let inp = *v;
            let y = b0 * inp + z1;
            z1 = b1 * inp - a1 * y + z2;
            z2 = b2 * inp - a2 * y;
            *v = y;
        }
    };
    let n = x.len();
    let pad = 50.min(n - 1);
    let mut padded = Vec::with_capacity(n + 2 * pad);
    padded.extend((1..=pad).rev().map(|i| 2.0 * x[0] - x[i]));
    padded.extend_from_slice(x);
    padded.extend((1..=pad).map(|i| 2.0 * x[n - 1] - x[n - 1 - i]));
    run(&mut padded);
    padded.reverse();
    run(&mut padded);
    padded.reverse();
    padded[pad..pad + n].to_vec()
}

/// Derivative by central differences (one-sided at the ends), sample spacing `dt`.
pub fn derivative(x: &[f64], dt: f64) -> Vec<f64> {
    let n = x.len();
    if n < 2 {
        return vec![0.0; n];
    }
    (0..n)
        .map(|i| match i {
            0 => (x[1] - x[0]) / dt,
            i if i == n - 1 => (x[n - 1] - x[n - 2]) / dt,
            i => (x[i + 1] - x[i - 1]) / (2.0 * dt),
        })
        .collect()
}

/// Dimensionless jerk of a speed profile `v` sampled at `fs`:
/// `DJ = -(T^3 / v_peak^2) sum_i (d^2v/dt^2)_i^2 dt`, with `T = n dt` and the second
/// derivative by second differences `(v[i+2] - 2 v[i+1] + v[i]) / dt^2` (as in the paper's
/// reference code). `None` for fewer than 3 samples or a zero peak.
pub fn dimensionless_jerk(v: &[f64], fs: f64) -> Option<f64> {
    let peak = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if v.len() < 3 || !(peak > 0.0) {
        return None;
    }
    let dt = 1.0 / fs;
    let duration = v.len() as f64 * dt;
    let sum: f64 = v
        .windows(3)
        .map(|w| ((w[2] - 2.0 * w[1] + w[0]) / (dt * dt)).powi(2))
        .sum();
    Some(-duration.powi(3) / (peak * peak) * sum * dt)
}

/// Log dimensionless jerk: `LDLJ = -ln |DJ|` (higher, i.e. closer to zero, is smoother).
pub fn ldlj(v: &[f64], fs: f64) -> Option<f64> {
    dimensionless_jerk(v, fs)
        .filter(|dj| *dj != 0.0)
        .map(|dj| -dj.abs().ln())
}

/// Spectral arc length (SPARC) of a speed profile `v` sampled at `fs`:
/// zero-pad to `nfft = 2^(ceil(log2 n) + padlevel)`, take the FFT magnitude normalised by its
/// maximum, `M(f)`; keep the frequencies `f <= fc`, then from the first to the last whose
/// `M >= amp_th` (the adaptive cut-off); return
/// `-sum sqrt((df / (f_last - f_first))^2 + dM^2)` over that band. Closer to zero is
/// smoother. `None` for fewer than 2 samples or a flat spectrum band.
pub fn sparc(v: &[f64], fs: f64, padlevel: u32, fc: f64, amp_th: f64) -> Option<f64> {
    if v.len() < 2 || !geomfinite(v) {
        return None;
    }
    let nfft = 1usize << ((v.len() as f64).log2().ceil() as u32 + padlevel);
    let mut buf: Vec<Complex<f64>> = v.iter().map(|&x| Complex::new(x, 0.0)).collect();
    buf.resize(nfft, Complex::new(0.0, 0.0));
    FftPlanner::new().plan_fft_forward(nfft).process(&mut buf);
    let mag: Vec<f64> = buf.iter().map(|c| c.norm()).collect();
    let max = mag.iter().copied().fold(0.0, f64::max);
    if !(max > 0.0) {
        return None;
    }
    let df = fs / nfft as f64;
    let band: Vec<(f64, f64)> = (0..nfft)
        .map(|k| (k as f64 * df, mag[k] / max))
        .take_while(|(f, _)| *f <= fc)
        .collect();
    let first = band.iter().position(|(_, m)| *m >= amp_th)?;
    let last = band.iter().rposition(|(_, m)| *m >= amp_th)?;
    let band = &band[first..=last];
    if band.len() < 2 {
        return None;
    }
    let span = band[band.len() - 1].0 - band[0].0;
    Some(
        -band
            .windows(2)
            .map(|w| (((w[1].0 - w[0].0) / span).powi(2) + (w[1].1 - w[0].1).powi(2)).sqrt())
            .sum::<f64>(),
    )
}

fn geomfinite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The paper's example: v(t) = exp(-5 t^2), t = -1 .. 0.99 s at 100 Hz.
    fn gaussian() -> Vec<f64> {
        (0..200)
            .map(|i| -1.0 + i as f64 * 0.01)
            .map(|t: f64| (-5.0 * t * t).exp())
            .collect()
    }

    fn rel(a: f64, b: f64) -> f64 {
        ((a - b) / b).abs()
    }

    #[test]
    fn known_values_of_the_gaussian_speed_profile() {
        let v = gaussian();
        let dj = dimensionless_jerk(&v, 100.0).unwrap();
        assert!(rel(dj, -335.74684) < 1e-6, "DJ {dj}");
        let l = ldlj(&v, 100.0).unwrap();
        assert!(rel(l, -5.81636) < 1e-5, "LDLJ {l}");
        let s = sparc(&v, 100.0, 4, 10.0, 0.05).unwrap();
        assert!(rel(s, -1.41403) < 1e-4, "SPARC {s}");
    }

    #[test]
    fn a_two_peaked_profile_is_less_smooth() {
        let one = gaussian();
        let two: Vec<f64> = (0..200)
            .map(|i| -1.0 + i as f64 * 0.01)
            .map(|t: f64| (-40.0 * (t + 0.4).powi(2)).exp() + (-40.0 * (t - 0.4).powi(2)).exp())
            .collect();
        assert!(ldlj(&two, 100.0).unwrap() < ldlj(&one, 100.0).unwrap());
        assert!(
            sparc(&two, 100.0, 4, 10.0, 0.05).unwrap() < sparc(&one, 100.0, 4, 10.0, 0.05).unwrap()
        );
        assert!(ldlj(&[0.0; 10], 100.0).is_none());
    }

    #[test]
    fn resampling_is_linear_interpolation_on_a_uniform_grid() {
        let t = [0.0, 0.1, 0.3];
        let x = [0.0, 1.0, 3.0];
        let r = resample(&t, &x, 20.0);
        assert_eq!(r.len(), 7);
        for (k, v) in r.iter().enumerate() {
            assert!((v - k as f64 * 0.5).abs() < 1e-12, "{r:?}");
        }
    }

    #[test]
    fn the_filter_keeps_ramps_and_removes_fast_oscillation() {
        let fs = 100.0;
        let ramp: Vec<f64> = (0..300).map(|i| 0.01 * i as f64).collect();
        let f = lowpass_zero_phase(&ramp, fs, 6.0);
        assert!(
            ramp.iter().zip(&f).all(|(a, b)| (a - b).abs() < 1e-6),
            "a ramp passes unchanged"
        );
        let noisy: Vec<f64> = (0..300)
            .map(|i| (2.0 * PI * 30.0 * i as f64 / fs).sin())
            .collect();
        let g = lowpass_zero_phase(&noisy, fs, 6.0);
        let amp = g[100..200].iter().fold(0.0f64, |m, x| m.max(x.abs()));
        // |H(30 Hz)|^2 of the 6 Hz 2nd-order Butterworth is about 0.0015
        assert!(amp < 0.01, "30 Hz attenuated: {amp}");
        let d = derivative(&ramp, 1.0 / fs);
        assert!(d.iter().all(|v| (v - 1.0).abs() < 1e-9));
    }
}
