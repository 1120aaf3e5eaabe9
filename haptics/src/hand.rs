//! A person's hand on a pointer: what the station's end-to-end tests and the `pointer:steady`
//! device ([`crate::device::PointerHand`]) feed the
//! page instead of a robot's perfect line.
//!
//! The model, in the page's pixels (any 2D frame works):
//!
//! - **Submovements** follow the minimum-jerk profile (Flash and Hogan 1985): a movement of
//!   duration `T` covers the fraction `s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5` of its way at
//!   `tau = t / T`. A reach to a target is a primary submovement that stops short (it covers
//!   [`Hand::reach_cover`] of the way, as aimed movements do) and a corrective one after a
//!   pause; the stroke along a line is one submovement over its arc length.
//! - **Signal-dependent noise** (Harris and Wolpert 1998): the hand drifts off the intended
//!   path by a smooth random deviation (an Ornstein-Uhlenbeck process with time constant
//!   [`Hand::drift_tau_s`]) whose size grows with speed: SD `drift_px + drift_per_px_s * v`.
//! - **Tremor**: physiological tremor, 8-12 Hz, a fraction of a millimetre: a sinusoid of
//!   [`Hand::tremor_px`] at a frequency drawn in that band, on both axes with random phases.
//! - **Reaction times**: a pause before pressing and after releasing the button
//!   ([`Hand::settle_ms`]).
//! - **Sampling**: the pointer reports at [`Hand::rate_hz`] (60 Hz, a display's frame rate).
//!
//! The gestures are deterministic given the seed.

use cutlab_sim::rng::Rng;

/// One step of what the hand does, in order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Gesture {
    /// The pointer moves to `(x, y)` over `ms` milliseconds (one sample).
    Move {
        /// Where to, px.
        x: f64,
        /// See `x`.
        y: f64,
        /// How long the move takes, ms.
        ms: u64,
    },
    /// The button goes down (the blade engages).
    Press,
    /// The button comes up.
    Release,
    /// The hand holds still for `ms` milliseconds.
    Wait {
        /// How long, ms.
        ms: u64,
    },
}

/// A hand: its noise, its tremor and how often its pointer is sampled.
#[derive(Debug, Clone)]
pub struct Hand {
    /// How often the pointer reports, Hz.
    pub rate_hz: f64,
    /// The tremor's amplitude, px.
    pub tremor_px: f64,
    /// The drift's SD when still, px, and its growth with speed, px per px/s.
    pub drift_px: f64,
    /// See `drift_px`.
    pub drift_per_px_s: f64,
    /// The drift's time constant, s.
    pub drift_tau_s: f64,
    /// The share of the way a reach's primary submovement covers.
    pub reach_cover: f64,
    /// A pause before a press and after a release (reaction and settling), ms.
    pub settle_ms: u64,
    rng: Rng,
    tremor_hz: f64,
    tremor_phase: [f64; 2],
    drift: f64,
    t_s: f64,
}

/// The minimum-jerk share of the way at `tau` in `[0, 1]`.
pub fn minimum_jerk(tau: f64) -> f64 {
    let t = tau.clamp(0.0, 1.0);
    t * t * t * (10.0 - 15.0 * t + 6.0 * t * t)
}

impl Hand {
    /// A steady hand: tremor and drift of a skilled person at a mouse, with `px_per_mm`
    /// pixels to a millimetre of tissue (tremor 0.1 mm, drift 0.15 mm still).
    pub fn steady(px_per_mm: f64, seed: u64) -> Self {
        let mut rng = Rng::new(seed);
        let tremor_hz = 8.0 + 4.0 * rng.uniform();
        let tau = std::f64::consts::TAU;
        let tremor_phase = [tau * rng.uniform(), tau * rng.uniform()];
        Self {
            rate_hz: 60.0,
            tremor_px: 0.1 * px_per_mm,
            drift_px: 0.15 * px_per_mm,
            drift_per_px_s: 0.004,
            drift_tau_s: 0.3,
            reach_cover: 0.94,
            settle_ms: 350,
            rng,
            tremor_hz,
            tremor_phase,
            drift: 0.0,
            t_s: 0.0,
        }
    }

    /// A shaky, hurried hand: tremor and drift four times the steady hand's.
    pub fn sloppy(px_per_mm: f64, seed: u64) -> Self {
        let mut h = Self::steady(px_per_mm, seed);
        h.tremor_px *= 4.0;
        h.drift_px *= 4.0;
        h.drift_per_px_s *= 4.0;
        h.settle_ms = 150;
        h
    }

    /// This hand made one person's among many, drawn from its seed: tremor and drift scaled
    /// by factors in [0.6, 1.5], the reaction pause 250-450 ms. Returns the person's pace as a
    /// factor in [0.75, 1.25] of the population's (people cut at their own speed).
    pub fn one_of_many(&mut self) -> f64 {
        let mut factor = |lo: f64, hi: f64| lo + (hi - lo) * self.rng.uniform();
        let (tremor, drift, settle, pace) = (
            factor(0.6, 1.5),
            factor(0.6, 1.5),
            factor(250.0, 450.0),
            factor(0.75, 1.25),
        );
        self.tremor_px *= tremor;
        self.drift_px *= drift;
        self.drift_per_px_s *= drift;
        self.settle_ms = settle.round() as u64;
        pace
    }

    fn sample_ms(&self) -> u64 {
        (1000.0 / self.rate_hz).round() as u64
    }

    /// The noise of one sample at speed `v` px/s along unit direction `dir`: the drift across
    /// the path (grown by speed) and the tremor on both axes.
    fn noise(&mut self, v: f64, dir: [f64; 2]) -> [f64; 2] {
        let dt = 1.0 / self.rate_hz;
        self.t_s += dt;
        let sd = self.drift_px + self.drift_per_px_s * v;
        let a = (-dt / self.drift_tau_s).exp();
        self.drift = a * self.drift + sd * (1.0 - a * a).sqrt() * self.rng.normal();
        let w = std::f64::consts::TAU * self.tremor_hz * self.t_s;
        let across = [-dir[1], dir[0]];
        [
            across[0] * self.drift + self.tremor_px * (w + self.tremor_phase[0]).sin(),
            across[1] * self.drift + self.tremor_px * (w + self.tremor_phase[1]).sin(),
        ]
    }

    /// One minimum-jerk submovement from `from` along `path` (its points, from `from` on)
    /// to the share `stop_at` of its arc length, over `duration_s`, sampled.
    fn submovement(&mut self, path: &[[f64; 2]], duration_s: f64, stop_at: f64) -> Vec<Gesture> {
        let along = Along::new(path);
        let n = (duration_s * self.rate_hz).ceil().max(1.0) as usize;
        let ms = self.sample_ms();
        let mut out = Vec::with_capacity(n);
        let mut last = 0.0;
        for k in 1..=n {
            let s = stop_at * along.length * minimum_jerk(k as f64 / n as f64);
            let v = (s - last) * self.rate_hz;
            last = s;
            let (p, dir) = along.at(s);
            let e = self.noise(v, dir);
            out.push(Gesture::Move {
                x: p[0] + e[0],
                y: p[1] + e[1],
                ms,
            });
        }
        out
    }

    /// The hand put down at `rest`, a pause of 400 ms, then a reach of 0.8 s onto `to`: how
    /// an attempt begins.
    pub fn approach(&mut self, rest: [f64; 2], to: [f64; 2]) -> Vec<Gesture> {
        let mut out = vec![
            Gesture::Move {
                x: rest[0],
                y: rest[1],
                ms: 16,
            },
            Gesture::Wait { ms: 400 },
        ];
        out.extend(self.reach(rest, to, 0.8));
        out
    }

    /// A reach from `from` to `to` over `duration_s`: a primary submovement that stops short,
    /// a pause, and a correction onto the target.
    pub fn reach(&mut self, from: [f64; 2], to: [f64; 2], duration_s: f64) -> Vec<Gesture> {
        let mut out = self.submovement(&[from, to], 0.75 * duration_s, self.reach_cover);
        let short = lerp(from, to, self.reach_cover);
        out.push(Gesture::Wait { ms: 120 });
        out.extend(self.submovement(&[short, to], 0.25 * duration_s, 1.0));
        out
    }

    /// Presses, strokes along `line` to the share `stop_at` of its length over `duration_s`
    /// (one minimum-jerk submovement), and releases, pausing before and after.
    pub fn stroke(&mut self, line: &[[f64; 2]], duration_s: f64, stop_at: f64) -> Vec<Gesture> {
        let mut out = vec![
            Gesture::Wait { ms: self.settle_ms },
            Gesture::Press,
            Gesture::Wait { ms: self.settle_ms },
        ];
        out.extend(self.submovement(line, duration_s, stop_at));
        out.push(Gesture::Wait { ms: self.settle_ms });
        out.push(Gesture::Release);
        out
    }

    /// A sloppy zig-zag along `line`: `amplitude_px` from side to side, `waves` times.
    pub fn zigzag(
        &mut self,
        line: &[[f64; 2]],
        duration_s: f64,
        amplitude_px: f64,
        waves: f64,
    ) -> Vec<Gesture> {
        let along = Along::new(line);
        let n = (duration_s * self.rate_hz).ceil().max(1.0) as usize;
        let ms = self.sample_ms();
        let mut out = vec![Gesture::Press];
        for k in 1..=n {
            let tau = k as f64 / n as f64;
            let (p, dir) = along.at(along.length * tau);
            let side = amplitude_px * (std::f64::consts::TAU * waves * tau).sin();
            let e = self.noise(along.length / duration_s, dir);
            out.push(Gesture::Move {
                x: p[0] - dir[1] * side + e[0],
                y: p[1] + dir[0] * side + e[1],
                ms,
            });
        }
        out.push(Gesture::Release);
        out
    }

    /// Moves away from `from` by `offset` (the lift and the hand going back to rest).
    pub fn withdraw(&mut self, from: [f64; 2], offset: [f64; 2], duration_s: f64) -> Vec<Gesture> {
        let to = [from[0] + offset[0], from[1] + offset[1]];
        self.submovement(&[from, to], duration_s, 1.0)
    }
}

fn lerp(a: [f64; 2], b: [f64; 2], t: f64) -> [f64; 2] {
    [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t]
}

/// A polyline by arc length.
struct Along<'a> {
    points: &'a [[f64; 2]],
    /// The arc length at each point.
    at_point: Vec<f64>,
    length: f64,
}

impl<'a> Along<'a> {
    fn new(points: &'a [[f64; 2]]) -> Self {
        let mut at_point = vec![0.0];
        for w in points.windows(2) {
            let d = (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]);
            at_point.push(at_point.last().copied().unwrap_or(0.0) + d);
        }
        let length = at_point.last().copied().unwrap_or(0.0);
        Self {
            points,
            at_point,
            length,
        }
    }

    /// The point at arc length `s` and the unit direction there.
    fn at(&self, s: f64) -> ([f64; 2], [f64; 2]) {
        let n = self.points.len();
        if n < 2 || self.length <= 0.0 {
            return (
                self.points.first().copied().unwrap_or([0.0, 0.0]),
                [1.0, 0.0],
            );
        }
        let i = self.at_point[1..n - 1].partition_point(|&a| a < s);
        let (a, b) = (self.points[i], self.points[i + 1]);
        let span = (self.at_point[i + 1] - self.at_point[i]).max(1e-12);
        let t = ((s - self.at_point[i]) / span).clamp(0.0, 1.0);
        let d = [(b[0] - a[0]) / span, (b[1] - a[1]) / span];
        (lerp(a, b, t), d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn moves(g: &[Gesture]) -> Vec<[f64; 2]> {
        g.iter()
            .filter_map(|g| match *g {
                Gesture::Move { x, y, .. } => Some([x, y]),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn minimum_jerk_starts_and_ends_at_rest() {
        assert_eq!(minimum_jerk(0.0), 0.0);
        assert_eq!(minimum_jerk(1.0), 1.0);
        assert!((minimum_jerk(0.5) - 0.5).abs() < 1e-12);
        // zero velocity at both ends: a small step moves far less than linearly
        assert!(minimum_jerk(0.01) < 1e-4);
        assert!(1.0 - minimum_jerk(0.99) < 1e-4);
    }

    #[test]
    fn a_steady_stroke_follows_the_line_within_a_millimetre_at_60_hz() {
        let px_per_mm = 8.0;
        let line = [[100.0, 300.0], [580.0, 300.0]];
        let mut hand = Hand::steady(px_per_mm, 7);
        let g = hand.stroke(&line, 4.0, 1.0);
        let m = moves(&g);
        assert_eq!(m.len(), 240, "60 samples a second for 4 s");
        let worst = m.iter().map(|p| (p[1] - 300.0).abs()).fold(0.0, f64::max);
        assert!(worst < 1.0 * px_per_mm, "worst lateral {worst} px");
        assert!(
            worst > 0.02 * px_per_mm,
            "the hand is not a robot: {worst} px"
        );
        let end = m.last().expect("moves");
        assert!((end[0] - 580.0).abs() < 0.5 * px_per_mm, "{end:?}");
        assert_eq!(g.iter().filter(|g| **g == Gesture::Press).count(), 1);
    }

    #[test]
    fn a_sloppy_hand_strays_further_and_a_half_stroke_stops_half_way() {
        let line = [[0.0, 0.0], [400.0, 0.0]];
        let spread = |h: &mut Hand| {
            let m = moves(&h.stroke(&line, 3.0, 1.0));
            (m.iter().map(|p| p[1] * p[1]).sum::<f64>() / m.len() as f64).sqrt()
        };
        let (steady, sloppy) = (
            spread(&mut Hand::steady(8.0, 3)),
            spread(&mut Hand::sloppy(8.0, 3)),
        );
        assert!(sloppy > 2.0 * steady, "{sloppy} against {steady}");
        let half = moves(&Hand::steady(8.0, 3).stroke(&line, 2.0, 0.5));
        let end = half.last().expect("moves")[0];
        assert!((end - 200.0).abs() < 4.0, "{end}");
    }

    #[test]
    fn a_reach_stops_short_then_corrects_onto_the_target() {
        let mut hand = Hand::steady(8.0, 1);
        let g = hand.reach([0.0, 0.0], [300.0, 100.0], 0.8);
        let m = moves(&g);
        let end = m.last().expect("moves");
        assert!(
            (end[0] - 300.0).abs() < 3.0 && (end[1] - 100.0).abs() < 3.0,
            "{end:?}"
        );
        assert!(
            g.iter().any(|g| matches!(g, Gesture::Wait { .. })),
            "a pause between"
        );
    }

    #[test]
    fn people_differ_from_one_another_within_bounds() {
        let people: Vec<(Hand, f64)> = (0..20)
            .map(|seed| {
                let mut h = Hand::steady(8.0, seed);
                let pace = h.one_of_many();
                (h, pace)
            })
            .collect();
        let base = Hand::steady(8.0, 0);
        for (h, pace) in &people {
            assert!((0.75..=1.25).contains(pace));
            assert!(h.tremor_px >= 0.6 * base.tremor_px && h.tremor_px <= 1.5 * base.tremor_px);
            assert!((250..=450).contains(&h.settle_ms));
        }
        let paces: Vec<f64> = people.iter().map(|p| p.1).collect();
        let spread = paces.iter().cloned().fold(f64::MIN, f64::max)
            - paces.iter().cloned().fold(f64::MAX, f64::min);
        assert!(spread > 0.25, "twenty people, one pace: {paces:?}");
    }

    #[test]
    fn the_same_seed_gives_the_same_hand() {
        let line = [[0.0, 0.0], [100.0, 50.0], [200.0, 60.0]];
        let a = Hand::steady(8.0, 11).stroke(&line, 2.0, 1.0);
        let b = Hand::steady(8.0, 11).stroke(&line, 2.0, 1.0);
        assert_eq!(a, b);
    }
}
