//! Force rendering at the servo rate: a god-object proxy held on the tissue surface by the
//! local contact model the simulation refreshes, coupled to the tool by a spring-damper;
//! cutting resistance once the blade is in the tissue; and the safety layer.
//!
//! Between simulation updates the servo loop uses the latest [`ContactModel`] (a plane and a
//! stiffness), so the force is smooth at 1 kHz even when the simulation runs slower.
//!
//! - Touching: the tool touches with its tip or, when the simulation found the surface under
//!   the heel of the blade nearer than under the tip ([`ContactModel::at_heel`]; the blade is
//!   a segment from the tip along the cutting edge, and the deepest point of a segment is one
//!   of its ends), with its heel; the proxy is that point `p` projected onto the contact plane;
//!   the force is `k (proxy - p) - b v_n` (never pulling into the surface). Only a contact at
//!   the tip can start a cut: a blade laid on the tissue heel first presses, it does not cut.
//! - A light touch does not cut: only when the blade is engaged and the contact force
//!   exceeds `cut_threshold_newtons`, or the tip has pressed `cut_depth_m` into the tissue
//!   from where it first touched it (a soft or loosely held tissue yields rather than
//!   pushing back), does the blade enter the tissue (mode `Cutting`); the
//!   proxy then follows the tip and the force is a cutting resistance opposing the blade's
//!   motion, `-R tanh(|v| / v0) v/|v|`. Lifting the tip above the surface where the cut
//!   began (as the simulation tracks it, [`ContactModel::cut_entry`]), or releasing the blade,
//!   ends the cut.
//! - Safety: the force is clamped to the device's limit and rate-limited; a non-finite pose or
//!   model, a stalled simulation (no refresh for `stale_after_ticks`) or a lost device fades
//!   the force to zero within `fade_ticks`; when the fault clears the force ramps back in.
//!   The output is always finite.

use crate::device::{DeviceFault, DeviceLimits};
use crate::{Point3, ToolPose, Vector3};

/// The local linear contact model the simulation publishes for the servo loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactModel {
    /// False until the simulation published its first model.
    pub published: bool,
    /// The servo tick whose sample the simulation step consumed to make this model.
    pub source_tick: u64,
    /// The plane is under the blade's heel, not under the proxy: the tool touches with its heel.
    pub at_heel: bool,
    /// A surface is near the proxy.
    pub valid: bool,
    /// Closest surface point to the proxy.
    pub plane_point: Point3,
    /// The outward unit normal of the surface at `plane_point`.
    pub plane_normal: Vector3,
    /// Local stiffness of the tissue along the normal, N/m.
    pub stiffness_newtons_per_m: f64,
    /// While the blade cuts: the surface point where it went in and the outward normal
    /// there, as they are now (they move with the tissue, which springs back from the press
    /// once the blade is in). Lifting the tip above this plane ends the cut.
    pub cut_entry: Option<(Point3, Vector3)>,
    /// The wound of the last cut that ended: where its blade's tip last cut, and its entry
    /// (point and outward normal, as [`Self::cut_entry`]). A blade engaged again within
    /// [`WOUND_REACH_M`] of that tip and below the entry's plane is put back into its wound:
    /// it cuts on at once (after a reload, a release and a press again, or a lift that did not
    /// leave the wound), rather than having to enter the tissue anew (inside a wound the
    /// nearest surface is its wall, which takes millimetres of travel to cut into).
    pub wound: Option<Wound>,
    /// While the blade cuts and its edge meets tissue a scalpel does not cut (a rib): where
    /// its tip stopped and the edge's unit direction from the tip towards the heel
    /// (`cutlab_sim::cut::Cutter::stop`). The tip is pushed back to it as from a hard
    /// surface, at the renderer's largest stiffness.
    pub blade_stop: Option<(Point3, Vector3)>,
    /// While the grasper's jaws hold tissue: its pull on them, N
    /// (`cutlab_sim::grasp::Grasp::pull_newtons`); zero otherwise.
    pub grasp_pull_newtons: Vector3,
}

/// See [`ContactModel::wound`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wound {
    /// Where the blade's tip last cut, m.
    pub end_m: Point3,
    /// The cut's entry point and its outward normal, as they are now.
    pub entry: (Point3, Vector3),
}

/// How near the end of its wound an engaged blade must be to cut on in it, m.
pub const WOUND_REACH_M: f64 = 0.003;

impl Default for ContactModel {
    fn default() -> Self {
        Self {
            published: false,
            source_tick: 0,
            at_heel: false,
            valid: false,
            plane_point: Point3::origin(),
            plane_normal: Vector3::z(),
            stiffness_newtons_per_m: 0.0,
            cut_entry: None,
            wound: None,
            blade_stop: None,
            grasp_pull_newtons: Vector3::zeros(),
        }
    }
}

impl ContactModel {
    /// The tip is near the end of the last cut's wound and below its entry's plane.
    fn back_in_wound(&self, tip: &Point3) -> bool {
        self.wound.is_some_and(|w| {
            let (p0, n0) = w.entry;
            (tip - w.end_m).norm() <= WOUND_REACH_M && (tip - p0).dot(&n0) < 0.0
        })
    }

    fn is_finite(&self) -> bool {
        self.plane_point
            .iter()
            .chain(self.plane_normal.iter())
            .all(|c| c.is_finite())
            && self.stiffness_newtons_per_m.is_finite()
            && self
                .cut_entry
                .into_iter()
                .chain(self.blade_stop)
                .all(|(p, n)| p.iter().chain(n.iter()).all(|c| c.is_finite()))
            && self.wound.is_none_or(|w| {
                let (p, n) = w.entry;
                w.end_m
                    .iter()
                    .chain(p.iter())
                    .chain(n.iter())
                    .all(|c| c.is_finite())
            })
    }
}

/// Settings of the force renderer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderSettings {
    /// The device's force and force-rate limits.
    pub limits: DeviceLimits,
    /// Servo period, s.
    pub period_s: f64,
    /// Damping of the proxy coupling along the normal, N s/m.
    pub damping_newton_seconds_per_m: f64,
    /// Upper bound on the model's stiffness (stability of the 1 kHz loop), N/m.
    pub max_stiffness_newtons_per_m: f64,
    /// Contact force above which an engaged blade enters the tissue, N.
    pub cut_threshold_newtons: f64,
    /// Depth below the surface where the tip first touched it (along the normal there) at
    /// which an engaged blade enters the tissue whatever the force, m.
    pub cut_depth_m: f64,
    /// Cutting resistance at speed, N.
    pub cut_resistance_newtons: f64,
    /// The speed scale of the cutting resistance's onset, m/s.
    pub cut_resistance_speed_m_per_s: f64,
    /// A model older than this many ticks means the simulation stalled.
    pub stale_after_ticks: u64,
    /// Ticks to fade the force out on a fault.
    pub fade_ticks: u32,
    /// Ticks to ramp the force back in after a fault cleared.
    pub recover_ticks: u32,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            limits: DeviceLimits::default(),
            period_s: 1e-3,
            damping_newton_seconds_per_m: 0.3,
            max_stiffness_newtons_per_m: 2000.0,
            cut_threshold_newtons: 1.0,
            cut_depth_m: 0.004,
            cut_resistance_newtons: 0.8,
            cut_resistance_speed_m_per_s: 0.005,
            stale_after_ticks: 50,
            fade_ticks: 5,
            recover_ticks: 100,
        }
    }
}

impl RenderSettings {
    /// These settings with `scene`'s cut threshold and depth (`cut_threshold_newtons`,
    /// `cut_depth_mm`): what a session on that scene renders with.
    pub fn with_scene_cut(mut self, scene: &cutlab_sim::scene::SceneSpec) -> Self {
        self.cut_threshold_newtons = scene.cut_threshold_newtons;
        self.cut_depth_m = scene.cut_depth_mm * 1e-3;
        self
    }
}

/// A [`RenderSettings`] value out of range.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum RenderSettingsError {
    /// A value that must be positive and finite is not.
    #[error("{name} must be positive and finite, got {value}")]
    NotPositive {
        /// The setting's name.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// The damping or the cutting resistance is negative (or not a number).
    #[error("damping and cut resistance must not be negative")]
    Negative,
    /// A tick count is zero.
    #[error("fade, recover and stale tick counts must be at least 1")]
    ZeroTicks,
}

impl RenderSettings {
    /// Checks every value's range (see [`RenderSettingsError`]).
    pub fn check(&self) -> Result<(), RenderSettingsError> {
        let l = &self.limits;
        let positive = [
            ("max force", l.max_force_newtons),
            ("max force rate", l.max_force_rate_newtons_per_s),
            ("period", self.period_s),
            ("max stiffness", self.max_stiffness_newtons_per_m),
            ("cut threshold", self.cut_threshold_newtons),
            ("cut depth", self.cut_depth_m),
            ("cut resistance speed", self.cut_resistance_speed_m_per_s),
        ];
        for (name, value) in positive {
            if !(value > 0.0 && value.is_finite()) {
                return Err(RenderSettingsError::NotPositive { name, value });
            }
        }
        if !(self.damping_newton_seconds_per_m >= 0.0 && self.cut_resistance_newtons >= 0.0) {
            return Err(RenderSettingsError::Negative);
        }
        if self.fade_ticks == 0 || self.recover_ticks == 0 || self.stale_after_ticks == 0 {
            return Err(RenderSettingsError::ZeroTicks);
        }
        Ok(())
    }
}

/// What the tool is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Mode {
    /// Not touching the tissue.
    #[default]
    Free,
    /// Pressing on the surface (the proxy on the contact plane).
    Touching,
    /// The blade is in the tissue.
    Cutting,
}

/// Fault bits of a tick.
pub mod fault {
    /// The device is disconnected.
    pub const DEVICE_LOST: u8 = 1;
    /// The device's last pose is too old.
    pub const DEVICE_STALE: u8 = 2;
    /// A pose, contact model or force had a non-finite value.
    pub const NON_FINITE: u8 = 4;
    /// The simulation's contact model is too old.
    pub const SIM_STALLED: u8 = 8;

    /// Names of the set bits, for logs.
    pub fn describe(bits: u8) -> &'static str {
        match bits {
            0 => "none",
            DEVICE_LOST => "device lost",
            DEVICE_STALE => "device data stale",
            NON_FINITE => "non-finite value",
            SIM_STALLED => "simulation stalled",
            _ => "several faults",
        }
    }
}

/// What the renderer produced this tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RenderOutput {
    /// The force sent to the device (clamped, rate-limited, faded), N.
    pub force_newtons: Vector3,
    /// The proxy's position, m.
    pub proxy: Point3,
    /// What the tool is doing.
    pub mode: Mode,
    /// The tick's fault bits (see [`fault`]).
    pub faults: u8,
    /// Fade gain applied, 0..1.
    pub gain: f64,
}

/// The time constant of the velocity the cutting resistance follows, s: a hand's stroke
/// (tens of ms and longer), not the steps its input arrives in. A pointer moves in whole
/// pixels (0.2 mm on the tissue, every 50 ms at 4 mm/s) and a page's samples come in
/// bursts; a resistance that followed the 5 ms velocity flipped between 0 and its full
/// value with each step, on the chart and in a device's hand alike.
pub const CUT_VELOCITY_TIME_S: f64 = 0.05;

/// The force renderer's state.
#[derive(Debug, Clone)]
pub struct ForceRenderer {
    /// The renderer's settings.
    pub settings: RenderSettings,
    /// Length of the blade from the tip (0: the tip alone touches).
    blade_length_m: f64,
    mode: Mode,
    proxy: Point3,
    last_pose: Option<ToolPose>,
    /// The tip's velocity, low-passed over about 5 ms: the damping's.
    velocity: Vector3,
    /// The tip's velocity low-passed over [`CUT_VELOCITY_TIME_S`]: the cutting resistance's.
    cut_velocity: Vector3,
    /// The surface where the tip first touched it in the current contact (point, normal).
    touched: Option<(Point3, Vector3)>,
    /// Plane where the current cut began, as the contact model showed it then (until the
    /// simulation publishes the entry it tracks).
    cut_plane: (Point3, Vector3),
    /// Desired (clamped, rate-limited, un-faded) force of the last tick.
    desired: Vector3,
    gain: f64,
    /// Non-finite values met so far (poses, models or forces).
    pub non_finite_count: u64,
}

impl ForceRenderer {
    /// A renderer at rest: no contact, the proxy at the origin, full gain.
    pub fn new(settings: RenderSettings) -> Self {
        Self {
            settings,
            blade_length_m: 0.0,
            mode: Mode::Free,
            proxy: Point3::origin(),
            last_pose: None,
            velocity: Vector3::zeros(),
            cut_velocity: Vector3::zeros(),
            touched: None,
            cut_plane: (Point3::origin(), Vector3::z()),
            desired: Vector3::zeros(),
            gain: 1.0,
            non_finite_count: 0,
        }
    }

    /// The blade collides too, not only the tip: `blade_length_m` from the tip along the
    /// cutting edge (negative or non-finite: the tip alone).
    #[must_use]
    pub fn with_blade_length(mut self, blade_length_m: f64) -> Self {
        self.blade_length_m = if blade_length_m.is_finite() {
            blade_length_m.max(0.0)
        } else {
            0.0
        };
        self
    }

    /// One servo tick: the device's pose (or its fault) and the latest contact model.
    pub fn update(
        &mut self,
        tick: u64,
        pose: Result<ToolPose, DeviceFault>,
        contact: &ContactModel,
    ) -> RenderOutput {
        let s = self.settings;
        let mut faults = 0u8;
        let pose = match pose {
            Ok(p) if p.is_finite() => Some(p),
            Ok(_) => {
                faults |= fault::NON_FINITE;
                None
            }
            Err(DeviceFault::Disconnected) => {
                faults |= fault::DEVICE_LOST;
                None
            }
            Err(DeviceFault::Stale { .. }) => {
                faults |= fault::DEVICE_STALE;
                None
            }
        };
        let stale = if contact.published {
            tick.saturating_sub(contact.source_tick) > s.stale_after_ticks
        } else {
            tick > s.stale_after_ticks
        };
        if stale {
            faults |= fault::SIM_STALLED;
        }
        if contact.published && !contact.is_finite() {
            faults |= fault::NON_FINITE;
        }
        if faults & fault::NON_FINITE != 0 {
            self.non_finite_count += 1;
        }

        let mut desired = self.desired;
        if let Some(p) = pose {
            if let Some(last) = self.last_pose {
                let v = (p.tip_in_world - last.tip_in_world) / s.period_s;
                self.velocity += (v - self.velocity) * 0.2;
                let a = 1.0 - (-s.period_s / CUT_VELOCITY_TIME_S).exp();
                self.cut_velocity += (v - self.cut_velocity) * a;
            }
            self.last_pose = Some(p);
            if faults == 0 {
                desired = self.desired_force(&p, contact);
                if !desired.iter().all(|c| c.is_finite()) {
                    self.non_finite_count += 1;
                    faults |= fault::NON_FINITE;
                    desired = self.desired;
                }
            }
        }

        // Clamp, then rate-limit the change.
        let max = s.limits.max_force_newtons;
        if desired.norm() > max {
            desired *= max / desired.norm();
        }
        let step_max = s.limits.max_force_rate_newtons_per_s * s.period_s;
        let change = desired - self.desired;
        if change.norm() > step_max {
            desired = self.desired + change * (step_max / change.norm());
        }
        self.desired = desired;

        // Fade out on faults, ramp back in when they clear.
        self.gain = if faults != 0 {
            self.gain - 1.0 / s.fade_ticks as f64
        } else {
            self.gain + 1.0 / s.recover_ticks as f64
        };
        // snap the ends exactly (the steps do not add up to 1 in floating point)
        if self.gain < 1e-9 {
            self.gain = 0.0;
        } else if self.gain > 1.0 - 1e-9 {
            self.gain = 1.0;
        }
        let mut force = desired * self.gain;
        if !force.iter().all(|c| c.is_finite()) || force.norm() > max * (1.0 + 1e-12) {
            force = Vector3::zeros();
            self.desired = Vector3::zeros();
        }
        if faults != 0 && self.gain == 0.0 {
            // Faded out: forget the held force. A blade that was cutting when the device or
            // the simulation went stale stays in its cut (its pose is held; it cuts on when
            // they come back, without entering the tissue again); else the tool leaves it.
            self.desired = Vector3::zeros();
            let held = faults & !(fault::DEVICE_STALE | fault::SIM_STALLED) == 0;
            if !(held && self.mode == Mode::Cutting) {
                self.mode = Mode::Free;
            }
        }
        RenderOutput {
            force_newtons: force,
            proxy: self.proxy,
            mode: self.mode,
            faults,
            gain: self.gain,
        }
    }

    /// Forgets the first touch once the tip is at or above it (a blade lifted out).
    fn forget_touch_below(&mut self, tip: &Point3) {
        if self
            .touched
            .is_some_and(|(p0, n0)| (tip - p0).dot(&n0) >= 0.0)
        {
            self.touched = None;
        }
    }

    fn desired_force(&mut self, pose: &ToolPose, c: &ContactModel) -> Vector3 {
        let s = &self.settings;
        let tip = pose.tip_in_world;
        if !c.valid {
            self.mode = Mode::Free;
            self.proxy = tip;
            return Vector3::zeros();
        }
        let n = c.plane_normal;
        match self.mode {
            Mode::Cutting => {
                let (p0, n0) = c.cut_entry.unwrap_or(self.cut_plane);
                if !pose.blade_engaged() || (tip - p0).dot(&n0) > 0.0 {
                    self.mode = Mode::Free;
                    self.proxy = tip;
                    self.forget_touch_below(&tip);
                    return Vector3::zeros();
                }
                self.proxy = tip;
                // bone under the blade pushes the tip back to where it stopped
                let bone = c.blade_stop.map_or(Vector3::zeros(), |(stop, edge)| {
                    edge * ((stop - tip).dot(&edge).max(0.0) * s.max_stiffness_newtons_per_m)
                });
                let speed = self.cut_velocity.norm();
                if speed < 1e-9 {
                    return bone;
                }
                bone - self.cut_velocity / speed
                    * (s.cut_resistance_newtons * (speed / s.cut_resistance_speed_m_per_s).tanh())
            }
            Mode::Free | Mode::Touching if pose.blade_engaged() && c.back_in_wound(&tip) => {
                self.mode = Mode::Cutting;
                self.cut_plane = c.wound.map_or((c.plane_point, n), |w| w.entry);
                self.proxy = tip;
                Vector3::zeros()
            }
            Mode::Free | Mode::Touching => {
                let point = if c.at_heel {
                    pose.blade_heel(self.blade_length_m)
                } else {
                    tip
                };
                let depth = (point - c.plane_point).dot(&n);
                if depth >= 0.0 {
                    self.mode = Mode::Free;
                    self.proxy = tip;
                    self.forget_touch_below(&tip);
                    return Vector3::zeros();
                }
                // a new touch counts how far the tip presses in afresh, unless the engaged
                // blade never rose above where it first touched: the tissue sank away from it
                // or sprang off it, or it left its cut as the tissue under it sank (a thin
                // sheet riding on the tip); then it still counts from that first touch
                let kept = self.mode == Mode::Free
                    && pose.blade_engaged()
                    && self
                        .touched
                        .is_some_and(|(p0, n0)| (tip - p0).dot(&n0) < 0.0);
                if (self.mode == Mode::Free && !kept) || c.at_heel {
                    self.touched = None;
                }
                self.mode = Mode::Touching;
                self.proxy = point - n * depth;
                let k = c
                    .stiffness_newtons_per_m
                    .clamp(0.0, s.max_stiffness_newtons_per_m);
                let mut f = (self.proxy - point) * k
                    - n * (s.damping_newton_seconds_per_m * self.velocity.dot(&n));
                if f.dot(&n) < 0.0 {
                    f = Vector3::zeros();
                }
                // how far the tip has pressed in since it touched (along the normal there)
                let pressed_in = if c.at_heel {
                    0.0
                } else {
                    let (p0, n0) = *self.touched.get_or_insert((c.plane_point, n));
                    (p0 - tip).dot(&n0)
                };
                if pose.blade_engaged()
                    && !c.at_heel
                    && (f.norm() >= s.cut_threshold_newtons || pressed_in >= s.cut_depth_m)
                {
                    self.mode = Mode::Cutting;
                    self.cut_plane = (c.plane_point, n);
                    self.proxy = tip;
                }
                f
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose::BUTTON_BLADE;

    fn plane(tick: u64, k: f64) -> ContactModel {
        ContactModel {
            published: true,
            source_tick: tick,
            at_heel: false,
            valid: true,
            plane_point: Point3::origin(),
            plane_normal: Vector3::z(),
            stiffness_newtons_per_m: k,
            ..ContactModel::default()
        }
    }

    fn at(z: f64, buttons: u32) -> Result<ToolPose, DeviceFault> {
        Ok(ToolPose {
            tip_in_world: Point3::new(0.0, 0.0, z),
            buttons,
            ..ToolPose::default()
        })
    }

    /// Presses `depth` into a plane of stiffness `k` for `ticks` ticks.
    fn press(r: &mut ForceRenderer, depth: f64, k: f64, ticks: u64) -> RenderOutput {
        let mut out = RenderOutput::default();
        for t in 0..ticks {
            out = r.update(t, at(-depth, 0), &plane(t, k));
        }
        out
    }

    #[test]
    fn pressing_gives_spring_force_along_the_normal_rate_limited() {
        let mut r = ForceRenderer::new(RenderSettings::default());
        let first = r.update(0, at(-0.002, 0), &plane(0, 500.0));
        assert!(
            (first.force_newtons.norm() - 0.2).abs() < 1e-12,
            "rate limit 0.2 N per tick: {first:?}"
        );
        let out = press(&mut r, 0.002, 500.0, 50);
        assert!(
            (out.force_newtons - Vector3::new(0.0, 0.0, 1.0)).norm() < 1e-9,
            "{out:?}"
        );
        assert_eq!(out.mode, Mode::Touching);
        assert!((out.proxy - Point3::origin()).norm() < 1e-12);
    }

    #[test]
    fn force_is_clamped_to_the_device_limit() {
        let mut r = ForceRenderer::new(RenderSettings::default());
        let out = press(&mut r, 0.05, 2000.0, 200);
        assert!((out.force_newtons.norm() - 3.3).abs() < 1e-9, "{out:?}");
        let mut r = ForceRenderer::new(RenderSettings {
            limits: DeviceLimits {
                max_force_newtons: 1.5,
                ..DeviceLimits::default()
            },
            ..RenderSettings::default()
        });
        assert!((press(&mut r, 0.05, 2000.0, 200).force_newtons.norm() - 1.5).abs() < 1e-9);
    }

    #[test]
    fn nan_pose_fades_the_force_to_zero_within_a_few_ticks() {
        let mut r = ForceRenderer::new(RenderSettings::default());
        let before = press(&mut r, 0.004, 500.0, 100).force_newtons.norm();
        assert!(before > 1.9);
        let mut norms = Vec::new();
        for t in 100..110 {
            let out = r.update(t, at(f64::NAN, 0), &plane(t, 500.0));
            assert!(out.force_newtons.iter().all(|c| c.is_finite()));
            assert_eq!(out.faults, fault::NON_FINITE);
            norms.push(out.force_newtons.norm());
        }
        assert!(norms.windows(2).all(|w| w[1] <= w[0]), "{norms:?}");
        assert_eq!(norms[4], 0.0, "zero after fade_ticks = 5: {norms:?}");
        assert_eq!(r.non_finite_count, 10);
        // a NaN model does the same
        let mut r = ForceRenderer::new(RenderSettings::default());
        press(&mut r, 0.004, 500.0, 100);
        let mut bad = plane(100, f64::NAN);
        bad.plane_point.x = f64::NAN;
        let out = (100..105)
            .map(|t| r.update(t, at(-0.004, 0), &bad))
            .last()
            .expect("ticks");
        assert_eq!(out.force_newtons, Vector3::zeros());
        // recovery ramps back in
        let back = press(&mut r, 0.004, 500.0, 200);
        assert!((back.force_newtons.norm() - before).abs() < 1e-9);
    }

    #[test]
    fn stalled_sim_and_lost_device_fade_the_force() {
        let mut r = ForceRenderer::new(RenderSettings::default());
        press(&mut r, 0.004, 500.0, 100);
        // the model stops at tick 99
        let frozen = plane(99, 500.0);
        let mut first_zero = None;
        for t in 100..200 {
            let out = r.update(t, at(-0.004, 0), &frozen);
            if out.force_newtons.norm() == 0.0 && first_zero.is_none() {
                first_zero = Some(t);
                assert_eq!(out.faults, fault::SIM_STALLED);
            }
        }
        assert_eq!(
            first_zero,
            Some(99 + 50 + 5),
            "stale after 50 ticks, faded in 5"
        );

        let mut r = ForceRenderer::new(RenderSettings::default());
        press(&mut r, 0.004, 500.0, 100);
        let out = (100..105)
            .map(|t| r.update(t, Err(DeviceFault::Disconnected), &plane(t, 500.0)))
            .last()
            .expect("ticks");
        assert_eq!(
            (out.force_newtons.norm(), out.faults),
            (0.0, fault::DEVICE_LOST)
        );
    }

    #[test]
    fn a_cutting_blade_held_through_a_stall_cuts_on_when_it_ends() {
        // in: the blade pressed 10 mm into a plane of 500 N/m (5 N > the 1 N threshold)
        let cutting = |r: &mut ForceRenderer, from: u64| {
            (from..from + 100)
                .map(|t| r.update(t, at(-0.010, BUTTON_BLADE), &plane(t, 500.0)).mode)
                .last()
        };
        let mut r = ForceRenderer::new(RenderSettings::default());
        assert_eq!(cutting(&mut r, 0), Some(Mode::Cutting));
        // the page stalls (the device stale, the pose held): the force fades, the blade stays
        // in its cut; when the samples come back it cuts on at once, without a new entry
        let stale = Err(DeviceFault::Stale {
            age_nanos: 600_000_000,
        });
        for t in 100..700 {
            let out = r.update(t, stale, &plane(t, 500.0));
            assert_eq!(out.mode, Mode::Cutting, "tick {t}");
        }
        assert_eq!(r.update(699, stale, &plane(699, 500.0)).gain, 0.0);
        let back = r.update(700, at(-0.010, BUTTON_BLADE), &plane(700, 500.0));
        assert_eq!(back.mode, Mode::Cutting);
        // the simulation stalls (its contact model old): the same
        let frozen = plane(700, 500.0);
        let out = (701..800)
            .map(|t| r.update(t, at(-0.010, BUTTON_BLADE), &frozen))
            .last()
            .expect("ticks");
        assert_eq!((out.mode, out.gain), (Mode::Cutting, 0.0));
        assert_eq!(
            r.update(800, at(-0.010, BUTTON_BLADE), &plane(800, 500.0))
                .mode,
            Mode::Cutting
        );
        // a lost device is not held: the blade leaves the tissue once the force has faded
        let out = (801..810)
            .map(|t| r.update(t, Err(DeviceFault::Disconnected), &plane(t, 500.0)))
            .last()
            .expect("ticks");
        assert_eq!(out.mode, Mode::Free);
    }

    #[test]
    fn a_light_touch_does_not_cut_a_firm_press_with_the_blade_does() {
        let mut r = ForceRenderer::new(RenderSettings::default());
        let light = (0..100)
            .map(|t| r.update(t, at(-0.001, BUTTON_BLADE), &plane(t, 500.0)))
            .last()
            .expect("ticks");
        assert_eq!(light.mode, Mode::Touching, "0.5 N < 1 N threshold");
        let mut r = ForceRenderer::new(RenderSettings::default());
        let firm_no_blade = press(&mut r, 0.004, 500.0, 100);
        assert_eq!(firm_no_blade.mode, Mode::Touching, "blade not engaged");
        let mut r = ForceRenderer::new(RenderSettings::default());
        let mut mode = Mode::Free;
        for t in 0..100 {
            mode = r.update(t, at(-0.004, BUTTON_BLADE), &plane(t, 500.0)).mode;
        }
        assert_eq!(mode, Mode::Cutting);
        // moving through the tissue meets resistance against the motion
        let mut out = RenderOutput::default();
        for t in 100..400 {
            let x = (t - 100) as f64 * 2e-5; // 20 mm/s
            out = r.update(
                t,
                Ok(ToolPose {
                    tip_in_world: Point3::new(x, 0.0, -0.004),
                    buttons: BUTTON_BLADE,
                    ..ToolPose::default()
                }),
                &plane(t, 500.0),
            );
        }
        assert_eq!(out.mode, Mode::Cutting);
        assert!(
            out.force_newtons.x < -0.7 && out.force_newtons.x > -0.81,
            "{out:?}"
        );
        // lifting out ends the cut
        let out = r.update(400, at(0.001, BUTTON_BLADE), &plane(400, 500.0));
        assert_eq!(out.mode, Mode::Free);
    }

    /// Issue 62: the blade stops on a rib and the hand feels it: the tip pressed 1 mm past
    /// where it stopped is pushed back at the renderer's largest stiffness (2 N, besides the
    /// fading cutting resistance of the press); above the stop nothing is added.
    #[test]
    fn a_blade_pressed_past_where_it_stopped_on_bone_is_pushed_back() {
        let mut r = ForceRenderer::new(RenderSettings::default());
        for t in 0..100 {
            r.update(t, at(-0.004, BUTTON_BLADE), &plane(t, 500.0));
        }
        let on_rib = |t: u64| ContactModel {
            blade_stop: Some((Point3::new(0.0, 0.0, -0.005), Vector3::z())),
            ..plane(t, 500.0)
        };
        let above = (100..600)
            .map(|t| r.update(t, at(-0.0045, BUTTON_BLADE), &on_rib(t)))
            .last()
            .expect("ticks");
        assert_eq!(above.mode, Mode::Cutting);
        assert!(above.force_newtons.norm() < 0.01, "{above:?}");
        let out = (600..1100)
            .map(|t| r.update(t, at(-0.006, BUTTON_BLADE), &on_rib(t)))
            .last()
            .expect("ticks");
        assert_eq!(out.mode, Mode::Cutting);
        assert!(
            (out.force_newtons - Vector3::new(0.0, 0.0, 2.0)).norm() < 0.02,
            "{out:?}"
        );
    }

    #[test]
    fn a_yielding_tissue_lets_the_blade_in_once_the_tip_has_pressed_the_cut_depth_in() {
        // a soft tissue recedes under the tip: the surface stays 0.5 mm below it, the push
        // stays at 0.01 N (20 N/m), far under the 1 N threshold
        let receding = |t: u64, z: f64| ContactModel {
            plane_point: Point3::new(0.0, 0.0, z + 0.0005),
            ..plane(t, 20.0)
        };
        let press = |r: &mut ForceRenderer, buttons: u32, to_m: f64| {
            let mut out = RenderOutput::default();
            for t in 0..=1000u64 {
                let z = -to_m * t as f64 / 1000.0;
                out = r.update(t, at(z, buttons), &receding(t, z));
                if out.mode == Mode::Cutting {
                    return (out, z);
                }
            }
            (out, -to_m)
        };
        let d = RenderSettings::default().cut_depth_m;
        let mut r = ForceRenderer::new(RenderSettings::default());
        let (out, _) = press(&mut r, BUTTON_BLADE, 0.9 * d - 0.0005);
        assert_eq!(
            out.mode,
            Mode::Touching,
            "not yet pressed the cut depth in: {out:?}"
        );
        assert!(out.force_newtons.norm() < 0.05);
        let mut r = ForceRenderer::new(RenderSettings::default());
        let (out, z) = press(&mut r, BUTTON_BLADE, 1.5 * d);
        assert_eq!(out.mode, Mode::Cutting);
        // the first touch was 0.5 mm above the start: in once the tip is d below it
        assert!((z - (0.0005 - d)).abs() < 2e-5, "went in at {z}");
        let mut r = ForceRenderer::new(RenderSettings::default());
        assert_eq!(
            press(&mut r, 0, 3.0 * d).0.mode,
            Mode::Touching,
            "the blade not engaged: a press, however deep, does not cut"
        );
    }

    #[test]
    fn an_engaged_blade_the_tissue_sank_from_goes_back_in_at_once() {
        let mut r = ForceRenderer::new(RenderSettings::default());
        // pressed 4.5 mm into a surface at 0: in
        let out = r.update(0, at(-0.0045, BUTTON_BLADE), &plane(0, 500.0));
        assert_eq!(out.mode, Mode::Cutting);
        // the tissue under the entry sinks below the tip: the blade reads as lifted out
        let sunk = ContactModel {
            cut_entry: Some((Point3::new(0.0, 0.0, -0.006), Vector3::z())),
            plane_point: Point3::new(0.0, 0.0, -0.006),
            ..plane(1, 20.0)
        };
        assert_eq!(
            r.update(1, at(-0.0045, BUTTON_BLADE), &sunk).mode,
            Mode::Free
        );
        // it rides back up under the tip (0.5 mm above it, a soft push): the tip is still
        // 4.5 mm below where it first touched, so it goes back in at once
        let riding = ContactModel {
            plane_point: Point3::new(0.0, 0.0, -0.004),
            ..plane(2, 20.0)
        };
        assert_eq!(
            r.update(2, at(-0.0045, BUTTON_BLADE), &riding).mode,
            Mode::Cutting
        );
        // lifted above the first touch and pressed again there: counted afresh
        let mut r = ForceRenderer::new(RenderSettings::default());
        r.update(0, at(-0.0045, BUTTON_BLADE), &plane(0, 500.0));
        r.update(1, at(0.001, BUTTON_BLADE), &sunk);
        assert_eq!(
            r.update(2, at(-0.0045, BUTTON_BLADE), &riding).mode,
            Mode::Touching
        );
    }

    #[test]
    fn the_cut_ends_above_the_entry_as_the_tissue_moves_it_not_where_the_press_dented_it() {
        // the press dented the surface 6 mm down; the blade went in there
        let dented = ContactModel {
            plane_point: Point3::new(0.0, 0.0, -0.006),
            ..plane(0, 500.0)
        };
        let mut r = ForceRenderer::new(RenderSettings::default());
        let mode = (0..100)
            .map(|t| {
                r.update(
                    t,
                    at(-0.010, BUTTON_BLADE),
                    &ContactModel {
                        source_tick: t,
                        ..dented
                    },
                )
                .mode
            })
            .last();
        assert_eq!(mode, Some(Mode::Cutting));
        // once in, the tissue springs back up around the blade, which returns to its planned
        // depth, 4 mm down: above the dented plane, below the entry as it is now
        let entry = |t: u64, z: f64| ContactModel {
            source_tick: t,
            cut_entry: Some((Point3::new(0.0, 0.0, z), Vector3::z())),
            ..dented
        };
        let mut fallback = r.clone();
        assert_eq!(
            r.update(100, at(-0.004, BUTTON_BLADE), &entry(100, -0.001))
                .mode,
            Mode::Cutting
        );
        // lifted above the entry: out
        assert_eq!(
            r.update(101, at(0.0005, BUTTON_BLADE), &entry(101, 0.0))
                .mode,
            Mode::Free
        );
        // with no entry published, the plane where the cut began decides
        assert_eq!(
            fallback
                .update(
                    100,
                    at(-0.004, BUTTON_BLADE),
                    &ContactModel {
                        source_tick: 100,
                        ..dented
                    }
                )
                .mode,
            Mode::Free
        );
    }

    #[test]
    fn the_blade_laid_on_the_tissue_presses_with_its_heel_and_does_not_cut() {
        // the edge runs from the tip down into the plane: the heel, 20 mm away, is 1.9 mm deep
        let edge = Vector3::new(1.0, 0.0, -0.2).normalize();
        let world_from_tool =
            crate::Rotation::rotation_between(&Vector3::z(), &edge).expect("rotation");
        let pose = Ok(ToolPose {
            tip_in_world: Point3::new(0.0, 0.0, 0.002),
            world_from_tool,
            buttons: BUTTON_BLADE,
        });
        let heel = Point3::new(0.0, 0.0, 0.002) + edge * 0.02;
        let under_heel = |t: u64, k: f64| ContactModel {
            at_heel: true,
            ..plane(t, k)
        };
        // the tip alone is above the plane: free
        let mut r = ForceRenderer::new(RenderSettings::default()).with_blade_length(0.02);
        assert_eq!(r.update(0, pose, &plane(0, 500.0)).mode, Mode::Free);
        // the simulation says the surface is under the heel
        let out = (1..100)
            .map(|t| r.update(t, pose, &under_heel(t, 500.0)))
            .last()
            .expect("ticks");
        assert_eq!(out.mode, Mode::Touching);
        assert!(
            (out.force_newtons - Vector3::new(0.0, 0.0, -500.0 * heel.z)).norm() < 1e-9,
            "{out:?}"
        );
        assert!(
            (out.proxy - Point3::new(heel.x, heel.y, 0.0)).norm() < 1e-12,
            "the proxy is the heel on the plane: {out:?}"
        );
        // pressed hard (3.3 N, over the cut threshold), engaged: no cut
        let hard = (100..200)
            .map(|t| r.update(t, pose, &under_heel(t, 5000.0)))
            .last()
            .expect("ticks");
        assert_eq!(hard.mode, Mode::Touching);
        assert!(hard.force_newtons.z > 3.0);
    }

    #[test]
    fn a_blade_put_back_into_its_wound_cuts_on_at_once() {
        // the last cut ended 6 mm down; the wall of its wound is the nearest surface
        let wall = |t: u64| ContactModel {
            plane_normal: -Vector3::x(),
            plane_point: Point3::new(0.001, 0.0, -0.006),
            wound: Some(Wound {
                end_m: Point3::new(0.0, 0.0, -0.006),
                entry: (Point3::new(-0.03, 0.0, 0.0), Vector3::z()),
            }),
            ..plane(t, 500.0)
        };
        let mode = |z: f64, buttons: u32| {
            let mut r = ForceRenderer::new(RenderSettings::default());
            r.update(0, at(z, buttons), &wall(0)).mode
        };
        // pressed again where it stopped (a reload, a release): it cuts on
        assert_eq!(mode(-0.006, BUTTON_BLADE), Mode::Cutting);
        assert_eq!(mode(-0.0045, BUTTON_BLADE), Mode::Cutting);
        // not without the button, nor far from where the wound ends, nor above its entry
        assert_ne!(mode(-0.006, 0), Mode::Cutting);
        assert_ne!(mode(-0.0095, BUTTON_BLADE), Mode::Cutting);
        let mut r = ForceRenderer::new(RenderSettings::default());
        let above = ContactModel {
            wound: Some(Wound {
                end_m: Point3::new(0.0, 0.0, -0.001),
                entry: (Point3::new(-0.03, 0.0, 0.0), Vector3::z()),
            }),
            ..plane(0, 500.0)
        };
        assert_ne!(
            r.update(0, at(0.0005, BUTTON_BLADE), &above).mode,
            Mode::Cutting
        );
    }

    #[test]
    fn a_blade_moving_in_pixel_steps_meets_a_steady_resistance() {
        // a pointer's stroke at 4 mm/s: a 0.2 mm pixel every 50 ms, each step played over a
        // 60 Hz frame (16.7 ms), still between them
        let wall = |t: u64| ContactModel {
            wound: Some(Wound {
                end_m: Point3::new(0.0, 0.0, -0.006),
                entry: (Point3::new(-0.03, 0.0, 0.0), Vector3::z()),
            }),
            ..plane(t, 500.0)
        };
        let x = |t: u64| {
            let (step, into) = (t / 50, (t % 50) as f64 / 16.7);
            0.0002 * (step as f64 + into.min(1.0))
        };
        let mut r = ForceRenderer::new(RenderSettings::default());
        let forces: Vec<f64> = (0..2000)
            .map(|t| {
                let pose = Ok(ToolPose {
                    tip_in_world: Point3::new(x(t), 0.0, -0.006),
                    buttons: BUTTON_BLADE,
                    ..ToolPose::default()
                });
                let out = r.update(t, pose, &wall(t));
                assert_eq!(out.mode, Mode::Cutting, "tick {t}");
                out.force_newtons.norm()
            })
            .collect();
        // after the stroke's first 0.3 s: the resistance of 4 mm/s (0.8 tanh 0.8 = 0.53 N),
        // give or take the steps; it followed each step from 0 to 0.8 N before
        let (lo, hi) = forces[300..]
            .iter()
            .fold((f64::MAX, 0.0_f64), |(lo, hi), &f| (lo.min(f), hi.max(f)));
        assert!(lo > 0.35 && hi < 0.75, "resistance {lo:.3}..{hi:.3} N");
    }
}
