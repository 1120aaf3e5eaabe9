//! A plan-following synthetic trainee: performs an incision from an expert plan with the
//! imperfections of a human hand, seeded so an attempt is reproducible.
//!
//! The hand hovers above the entry point, descends along the (mis-)approach direction until
//! the blade is `depth_m` below the surface, strokes along the planned line (with tremor, slow
//! lateral drift, speed variability and hesitations), overshoots the exit, lifts out and
//! holds still. The blade button is held from the descent to the end of the stroke.
//!
//! The hand feels the force: when the tissue yields under the blade instead of letting it in
//! (the push-back has not yet reached the force a blade needs, the renderer's default
//! threshold, and then dropped from that peak by [`GIVE_FRACTION`], as it does once the blade
//! enters; nor has the hand pressed the depth a blade needs since it first felt the tissue),
//! it presses on, slowly and at most [`MAX_PRESS_M`] deeper, until the blade gives; over the
//! first part of the stroke it comes back up to the planned depth.

use super::{DeviceFault, HapticDevice, Planning, Traction};
use crate::plan::Plan;
use cutlab_sim::rng::Rng;

use crate::pose::BUTTON_BLADE;
use crate::{HapticsError, Point3, Rotation, ToolPose, Vector3};

/// Skill parameters of a synthetic trainee.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Skill {
    /// Physiological tremor: amplitude (m) and frequency (Hz).
    pub tremor_amplitude_m: f64,
    /// The tremor's frequency, Hz.
    pub tremor_frequency_hz: f64,
    /// Slow lateral drift off the line: standard deviation (m) and time constant (s).
    pub drift_m: f64,
    /// The drift's time constant, s.
    pub drift_time_constant_s: f64,
    /// Mean cutting speed along the line, m/s.
    pub cut_speed_m_per_s: f64,
    /// Relative standard deviation of the speed (slowly varying).
    pub speed_variability: f64,
    /// Number of pauses along the stroke and their mean length, s.
    pub hesitations: usize,
    /// The mean length of a pause, s.
    pub hesitation_s: f64,
    /// How far the stroke runs past the exit point, m.
    pub overshoot_m: f64,
    /// Tilt of the blade away from the planned approach direction, rad (sign drawn per attempt).
    pub approach_angle_error_rad: f64,
    /// How it chooses an incision where the exercise leaves the choice to the trainee.
    pub planning: Planning,
    /// How its other hand gives countertraction, when it uses both.
    pub traction: Traction,
}

impl Skill {
    /// The names of the presets.
    pub const PRESETS: [&'static str; 3] = ["expert", "intermediate", "novice"];

    /// The presets `expert`, `intermediate` and `novice`.
    pub fn preset(name: &str) -> Option<Self> {
        let deg = std::f64::consts::PI / 180.0;
        Some(match name {
            "expert" => Self {
                tremor_amplitude_m: 0.05e-3,
                tremor_frequency_hz: 10.0,
                drift_m: 0.2e-3,
                drift_time_constant_s: 1.0,
                cut_speed_m_per_s: 0.02,
                speed_variability: 0.05,
                hesitations: 0,
                hesitation_s: 0.0,
                overshoot_m: 0.5e-3,
                approach_angle_error_rad: 2.0 * deg,
                planning: Planning::EXPERT,
                traction: Traction {
                    beside_m: 10e-3,
                    away_m: 4e-3,
                    lift_m: 2e-3,
                    hold_share: 2.0,
                },
            },
            "intermediate" => Self {
                tremor_amplitude_m: 0.15e-3,
                tremor_frequency_hz: 9.0,
                drift_m: 1.0e-3,
                drift_time_constant_s: 0.8,
                cut_speed_m_per_s: 0.015,
                speed_variability: 0.15,
                hesitations: 2,
                hesitation_s: 0.3,
                overshoot_m: 2.0e-3,
                approach_angle_error_rad: 6.0 * deg,
                planning: Planning::INTERMEDIATE,
                traction: Traction {
                    beside_m: 14e-3,
                    away_m: 1.5e-3,
                    lift_m: 1e-3,
                    hold_share: 0.8,
                },
            },
            "novice" => Self {
                tremor_amplitude_m: 0.4e-3,
                tremor_frequency_hz: 8.0,
                drift_m: 2.5e-3,
                drift_time_constant_s: 0.6,
                cut_speed_m_per_s: 0.01,
                speed_variability: 0.35,
                hesitations: 5,
                hesitation_s: 0.6,
                overshoot_m: 5.0e-3,
                approach_angle_error_rad: 12.0 * deg,
                planning: Planning::NOVICE,
                traction: Traction {
                    beside_m: 20e-3,
                    away_m: -1.5e-3,
                    lift_m: 0.5e-3,
                    hold_share: 0.45,
                },
            },
            _ => return None,
        })
    }

    /// A hand between the presets: `level` 0 is the novice, 0.5 the intermediate and 1 the
    /// expert, each parameter interpolated linearly between the two nearest (the number of
    /// hesitations rounded); what the demo's trainees improve along. `None` outside [0, 1].
    pub fn at_level(level: f64) -> Option<Self> {
        if !(0.0..=1.0).contains(&level) {
            return None;
        }
        let (a, b, t) = if level <= 0.5 {
            ("novice", "intermediate", 2.0 * level)
        } else {
            ("intermediate", "expert", 2.0 * level - 1.0)
        };
        let (a, b) = (Self::preset(a)?, Self::preset(b)?);
        let mix = |x: f64, y: f64| x * (1.0 - t) + y * t;
        Some(Self {
            tremor_amplitude_m: mix(a.tremor_amplitude_m, b.tremor_amplitude_m),
            tremor_frequency_hz: mix(a.tremor_frequency_hz, b.tremor_frequency_hz),
            drift_m: mix(a.drift_m, b.drift_m),
            drift_time_constant_s: mix(a.drift_time_constant_s, b.drift_time_constant_s),
            cut_speed_m_per_s: mix(a.cut_speed_m_per_s, b.cut_speed_m_per_s),
            speed_variability: mix(a.speed_variability, b.speed_variability),
            hesitations: mix(a.hesitations as f64, b.hesitations as f64).round() as usize,
            hesitation_s: mix(a.hesitation_s, b.hesitation_s),
            overshoot_m: mix(a.overshoot_m, b.overshoot_m),
            approach_angle_error_rad: mix(a.approach_angle_error_rad, b.approach_angle_error_rad),
            planning: Planning::mix(&a.planning, &b.planning, t),
            traction: Traction {
                beside_m: mix(a.traction.beside_m, b.traction.beside_m),
                away_m: mix(a.traction.away_m, b.traction.away_m),
                lift_m: mix(a.traction.lift_m, b.traction.lift_m),
                hold_share: mix(a.traction.hold_share, b.traction.hold_share),
            },
        })
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Hover,
    Descend,
    Stroke,
    Retract,
    Idle,
}

const HOVER_S: f64 = 0.3;
/// The blade has gone in when the push-back along the surface normal fell below this share
/// of its peak during the descent.
pub const GIVE_FRACTION: f64 = 0.7;
/// How much deeper than planned the hand presses at most, m.
pub const MAX_PRESS_M: f64 = 0.005;
/// How much further than the depth at which it expects the blade to go in the hand presses
/// before it takes the blade to be in (it feels the tissue a little after the renderer
/// does, and along its own approach rather than the surface's normal), m.
pub const DEPTH_MARGIN_M: f64 = 0.001;
/// How fast it presses on, m/s.
const PRESS_M_PER_S: f64 = 0.005;
/// Time constant of the return to the planned depth during the stroke, s.
const PRESS_RETURN_S: f64 = 0.2;
const DESCEND_M_PER_S: f64 = 0.02;
const RETRACT_M_PER_S: f64 = 0.03;

/// The synthetic trainee device.
#[derive(Debug, Clone)]
pub struct SyntheticTrainee {
    name: String,
    plan: Plan,
    skill: Skill,
    /// Cumulative arc length at each line point.
    arc_m: Vec<f64>,
    /// Arc positions and lengths of the pauses.
    pauses: Vec<(f64, f64)>,
    tilt_rad: f64,
    phases: [f64; 3],
    rng: Rng,
    phase: Phase,
    /// Progress within the phase: seconds (hover), metres (descend, stroke, retract).
    progress: f64,
    pause_index: usize,
    pause_left_s: f64,
    drift_m: f64,
    speed_noise: f64,
    time_s: f64,
    last: ToolPose,
    /// The latest rendered force's push-back along the surface normal, and its peak in the
    /// descent, N.
    push_n: f64,
    peak_push_n: f64,
    /// How much deeper than planned the hand pressed for the blade to go in, m.
    press_m: f64,
    /// The force the hand expects a blade to need (the renderer's default threshold), N.
    cutting_force_n: f64,
    /// How far the hand expects to press the tissue in before the blade goes in (the
    /// renderer's default cut depth), m, and how far down it was when it first felt the
    /// tissue push back (descent progress).
    cutting_depth_m: f64,
    touched_at_m: Option<f64>,
}

impl SyntheticTrainee {
    /// A trainee following `plan` with `skill`; `seed` fixes every random choice.
    pub fn new(name: &str, plan: Plan, skill: Skill, seed: u64) -> Result<Self, HapticsError> {
        plan.check()?;
        let mut arc_m = vec![0.0];
        for w in plan.line_m.windows(2) {
            let last = arc_m[arc_m.len() - 1];
            arc_m.push(last + (w[1] - w[0]).norm());
        }
        let length = arc_m[arc_m.len() - 1];
        let mut rng = Rng::new(seed);
        let mut pauses: Vec<(f64, f64)> = (0..skill.hesitations)
            .map(|_| {
                (
                    length * (0.1 + 0.8 * rng.uniform()),
                    skill.hesitation_s * (0.5 + rng.uniform()),
                )
            })
            .collect();
        pauses.sort_by(|a, b| a.0.total_cmp(&b.0));
        let sign = if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
        let tilt_rad = sign * skill.approach_angle_error_rad * (0.5 + rng.uniform());
        let phases = [
            rng.uniform() * std::f64::consts::TAU,
            rng.uniform() * std::f64::consts::TAU,
            rng.uniform() * std::f64::consts::TAU,
        ];
        let mut me = Self {
            name: name.to_owned(),
            plan,
            skill,
            arc_m,
            pauses,
            tilt_rad,
            phases,
            rng,
            phase: Phase::Hover,
            progress: 0.0,
            pause_index: 0,
            pause_left_s: 0.0,
            drift_m: 0.0,
            speed_noise: 0.0,
            time_s: 0.0,
            last: ToolPose::default(),
            push_n: 0.0,
            peak_push_n: 0.0,
            press_m: 0.0,
            cutting_force_n: crate::render::RenderSettings::default().cut_threshold_newtons,
            cutting_depth_m: crate::render::RenderSettings::default().cut_depth_m,
            touched_at_m: None,
        };
        me.last = me.pose();
        Ok(me)
    }

    /// The same trainee expecting the blade to enter the tissue at a push of `newtons` or
    /// once pressed `depth_m` in (the renderer's cut threshold and cut depth; default 1 N and
    /// 4 mm): at its planned depth it presses on until the push has reached that force and
    /// given way, or it has pressed that deep (and [`DEPTH_MARGIN_M`] more) since it first
    /// felt the tissue, or it is
    /// [`MAX_PRESS_M`] deeper than planned.
    pub fn expecting_cut(mut self, newtons: f64, depth_m: f64) -> Self {
        self.cutting_force_n = newtons;
        self.cutting_depth_m = depth_m;
        self
    }

    /// [`Self::expecting_cut`] with the cut threshold and depth the session renders with.
    pub fn expecting_cut_of(self, render: &crate::render::RenderSettings) -> Self {
        self.expecting_cut(render.cut_threshold_newtons, render.cut_depth_m)
    }

    /// Point, outward normal and unit tangent of the line at arc length `s` (extrapolated
    /// along the last segment past the exit).
    fn along(&self, s: f64) -> (Point3, Vector3, Vector3) {
        let line = &self.plan.line_m;
        let n = line.len();
        let mut i = match self.arc_m.binary_search_by(|a| a.total_cmp(&s)) {
            Ok(i) => i,
            Err(i) => i.saturating_sub(1),
        };
        i = i.min(n - 2);
        let seg = self.arc_m[i + 1] - self.arc_m[i];
        let u = if seg > 0.0 {
            (s - self.arc_m[i]) / seg
        } else {
            0.0
        };
        let tangent = (line[i + 1] - line[i])
            .try_normalize(1e-15)
            .unwrap_or_else(Vector3::x);
        let uc = u.clamp(0.0, 1.0);
        let normal = (self.plan.normals[i] * (1.0 - uc) + self.plan.normals[i + 1] * uc)
            .try_normalize(1e-15)
            .unwrap_or_else(Vector3::z);
        (line[i] + (line[i + 1] - line[i]) * u, normal, tangent)
    }

    fn stroke_end_m(&self) -> f64 {
        self.arc_m[self.arc_m.len() - 1] + self.skill.overshoot_m
    }

    /// The blade's orientation for the surface normal and cutting direction: +z along the
    /// normal tilted by the approach error about the cutting direction, +x along the cut.
    fn orientation(&self, normal: Vector3, tangent: Vector3) -> Rotation {
        let tilt =
            Rotation::from_axis_angle(&nalgebra::Unit::new_normalize(tangent), self.tilt_rad);
        blade_frame(tilt * normal, tangent)
    }

    /// The pose for the current state.
    fn pose(&self) -> ToolPose {
        let h = self.plan.approach_height_m;
        let d = self.plan.depth_m;
        let (s, offset, buttons) = match self.phase {
            Phase::Hover => (0.0, h, 0),
            Phase::Descend => (0.0, h - self.progress, BUTTON_BLADE),
            Phase::Stroke => (self.progress, -d - self.press_m, BUTTON_BLADE),
            Phase::Retract => (self.stroke_end_m(), -d - self.press_m + self.progress, 0),
            Phase::Idle => (self.stroke_end_m(), h, 0),
        };
        let (p, normal, tangent) = self.along(s);
        let rotation = self.orientation(normal, tangent);
        let axis = rotation * Vector3::z();
        let lateral = normal
            .cross(&tangent)
            .try_normalize(1e-12)
            .unwrap_or_else(Vector3::y);
        let w = std::f64::consts::TAU * self.skill.tremor_frequency_hz * self.time_s;
        let a = self.skill.tremor_amplitude_m;
        let tremor = lateral * (a * (w + self.phases[0]).sin())
            + tangent * (0.7 * a * (1.13 * w + self.phases[1]).sin())
            + normal * (0.5 * a * (0.87 * w + self.phases[2]).sin());
        let tip = p + axis * offset + lateral * self.drift_m + tremor;
        ToolPose {
            tip_in_world: tip,
            world_from_tool: rotation,
            buttons,
        }
    }

    /// Advances the hand by `dt` seconds.
    fn advance(&mut self, dt: f64) {
        // Ornstein-Uhlenbeck processes: stationary standard deviation `sigma`.
        let ou = |x: f64, tau: f64, sigma: f64, n: f64| {
            x - x / tau * dt + sigma * (2.0 * dt / tau).sqrt() * n
        };
        let n1 = self.rng.normal();
        let n2 = self.rng.normal();
        self.drift_m = ou(
            self.drift_m,
            self.skill.drift_time_constant_s.max(1e-3),
            self.skill.drift_m,
            n1,
        );
        self.speed_noise = ou(self.speed_noise, 0.3, 1.0, n2);
        let speed_factor = (1.0 + self.skill.speed_variability * self.speed_noise).clamp(0.2, 3.0);
        let h = self.plan.approach_height_m;
        let d = self.plan.depth_m;
        match self.phase {
            Phase::Hover => {
                self.progress += dt;
                if self.progress >= HOVER_S {
                    (self.phase, self.progress) = (Phase::Descend, 0.0);
                }
            }
            Phase::Descend => {
                self.peak_push_n = self.peak_push_n.max(self.push_n);
                if self.push_n > 0.0 && self.touched_at_m.is_none() {
                    self.touched_at_m = Some(self.progress);
                }
                if self.progress < h + d {
                    self.progress += DESCEND_M_PER_S * speed_factor * dt;
                } else {
                    // at the planned depth: on once the blade has given way, else press on
                    let given = (self.peak_push_n >= self.cutting_force_n
                        && self.push_n < GIVE_FRACTION * self.peak_push_n)
                        || self.touched_at_m.is_some_and(|at| {
                            self.progress - at >= self.cutting_depth_m + DEPTH_MARGIN_M
                        });
                    if given || self.progress >= h + d + MAX_PRESS_M {
                        self.press_m = self.progress - (h + d);
                        (self.phase, self.progress) = (Phase::Stroke, 0.0);
                    } else {
                        self.progress += PRESS_M_PER_S * dt;
                    }
                }
            }
            Phase::Stroke => {
                self.press_m -= self.press_m * (dt / PRESS_RETURN_S).min(1.0);
                if self.pause_left_s > 0.0 {
                    self.pause_left_s -= dt;
                    return;
                }
                self.progress += self.skill.cut_speed_m_per_s * speed_factor * dt;
                if let Some(&(at, length)) = self.pauses.get(self.pause_index)
                    && self.progress >= at
                {
                    self.pause_index += 1;
                    self.pause_left_s = length;
                }
                if self.progress >= self.stroke_end_m() {
                    (self.phase, self.progress) = (Phase::Retract, 0.0);
                }
            }
            Phase::Retract => {
                self.progress += RETRACT_M_PER_S * dt;
                if self.progress >= h + d + self.press_m {
                    (self.phase, self.progress) = (Phase::Idle, 0.0);
                }
            }
            Phase::Idle => {}
        }
    }

    /// The plan being followed.
    pub fn plan(&self) -> &Plan {
        &self.plan
    }
}

impl HapticDevice for SyntheticTrainee {
    fn name(&self) -> &str {
        &self.name
    }

    fn read(&mut self, _tick: u64, time_s: f64) -> Result<ToolPose, DeviceFault> {
        let dt = time_s - self.time_s;
        if dt > 0.0 && dt.is_finite() {
            self.advance(dt);
            self.time_s = time_s;
            self.last = self.pose();
        }
        Ok(self.last)
    }

    fn write_force(&mut self, force_newtons: Vector3) -> Result<(), DeviceFault> {
        // A scripted hand does not yield to the force (an ideal position source), but it feels
        // whether the blade has gone in.
        let (_, normal, _) = self.along(0.0);
        let push = force_newtons.dot(&normal);
        self.push_n = if push.is_finite() { push } else { 0.0 };
        Ok(())
    }

    fn finished(&self, _time_s: f64) -> bool {
        self.phase == Phase::Idle
    }
}

/// The tool frame with +z along `axis` (unit) and +x along `tangent` made perpendicular to it:
/// a blade held along the surface normal, cutting along the line.
pub(crate) fn blade_frame(axis: Vector3, tangent: Vector3) -> Rotation {
    let z = axis;
    let x = (tangent - z * tangent.dot(&z))
        .try_normalize(1e-12)
        .unwrap_or_else(|| z.cross(&Vector3::y()).normalize());
    let y = z.cross(&x);
    let m = nalgebra::Matrix3::from_columns(&[x, y, z]);
    Rotation::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(m))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat_plan() -> Plan {
        Plan::flat_across_x(0.005)
    }

    #[test]
    fn skill_levels_run_through_the_presets() {
        for (level, name) in [(0.0, "novice"), (0.5, "intermediate"), (1.0, "expert")] {
            assert_eq!(Skill::at_level(level), Skill::preset(name), "level {level}");
        }
        let (n, e, q) = (
            Skill::at_level(0.0).unwrap(),
            Skill::at_level(1.0).unwrap(),
            Skill::at_level(0.75).unwrap(),
        );
        assert!(
            q.tremor_amplitude_m < Skill::preset("intermediate").unwrap().tremor_amplitude_m
                && q.tremor_amplitude_m > e.tremor_amplitude_m
        );
        assert!(q.cut_speed_m_per_s > n.cut_speed_m_per_s && q.hesitations == 1);
        assert!(Skill::at_level(1.5).is_none() && Skill::at_level(f64::NAN).is_none());
    }

    fn run(skill: &str, seed: u64, seconds: f64) -> Vec<ToolPose> {
        let mut t = SyntheticTrainee::new(
            skill,
            flat_plan(),
            Skill::preset(skill).expect("preset"),
            seed,
        )
        .expect("plan");
        (0..(seconds * 1000.0) as u64)
            .map(|k| t.read(k, k as f64 * 1e-3).expect("pose"))
            .collect()
    }

    #[test]
    fn same_seed_same_hand_other_seed_other_hand() {
        let a = run("novice", 3, 2.0);
        assert_eq!(a, run("novice", 3, 2.0));
        assert_ne!(a, run("novice", 4, 2.0));
    }

    #[test]
    fn an_expert_cuts_along_the_line_and_a_novice_wanders() {
        let lateral = |skill: &str| {
            let poses = run(skill, 11, 16.0);
            let cutting: Vec<&ToolPose> = poses
                .iter()
                .filter(|p| p.blade_engaged() && p.tip_in_world.z < -0.004)
                .collect();
            assert!(
                cutting.len() > 1000,
                "{skill}: {} cutting ticks",
                cutting.len()
            );
            let xmax = cutting
                .iter()
                .map(|p| p.tip_in_world.x)
                .fold(f64::MIN, f64::max);
            let ymax = cutting
                .iter()
                .map(|p| p.tip_in_world.y.abs())
                .fold(0.0, f64::max);
            (xmax, ymax)
        };
        let (x_expert, y_expert) = lateral("expert");
        let (x_novice, y_novice) = lateral("novice");
        assert!(
            x_expert > 0.03 && x_expert < 0.0312,
            "expert overshoot: {x_expert}"
        );
        assert!(x_novice > 0.033, "novice overshoot: {x_novice}");
        assert!(
            y_expert < 1e-3 && y_novice > y_expert,
            "{y_expert} {y_novice}"
        );
    }

    #[test]
    fn the_blade_points_out_of_the_surface_within_the_angle_error() {
        let poses = run("intermediate", 5, 3.0);
        for p in &poses {
            let angle = p
                .edge_direction()
                .dot(&Vector3::z())
                .clamp(-1.0, 1.0)
                .acos();
            assert!(angle <= 1.5 * 6.0f64.to_radians() + 1e-9, "{angle}");
            assert!(p.is_finite());
        }
    }

    #[test]
    fn bad_plans_are_errors() {
        let mut p = flat_plan();
        p.line_m.pop();
        assert!(
            SyntheticTrainee::new("x", p, Skill::preset("expert").expect("preset"), 0).is_err()
        );
        let mut p = flat_plan();
        p.depth_m = f64::NAN;
        assert!(
            SyntheticTrainee::new("x", p, Skill::preset("expert").expect("preset"), 0).is_err()
        );
        assert!(Skill::preset("surgeon").is_none());
    }
}
