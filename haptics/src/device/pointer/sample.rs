//! One sample of the station page's pointer (or pen), and the checks it passes before the
//! servo loop uses it.

use serde::{Deserialize, Serialize};

/// A sample's surface point farther than this from the world's origin is absurd, m.
pub const MAX_DISTANCE_FROM_ORIGIN_M: f64 = 10.0;
/// Depths below the surface accepted, m (negative: above it).
pub const MIN_DEPTH_M: f64 = -0.05;
/// See [`MIN_DEPTH_M`].
pub const MAX_DEPTH_M: f64 = 0.1;
/// A page clock that jumps forward by more than this between two accepted samples is absurd,
/// ms.
pub const MAX_TIME_JUMP_MS: f64 = 10_000.0;
/// An orientation quaternion whose norm is farther than this from 1 is absurd (one within it
/// is normalised).
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// What the page saw and the trainee did at one instant.
///
/// The tip is `depth_m` from `surface_in_world_m` into the tissue along the blade: against the
/// tool's edge direction (`world_from_tool * z`, from the tip towards the handle), so with a
/// scalpel pointing down the tip goes `depth_m` below the surface point.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PointerSample {
    /// The page's clock (`performance.now()` or the event's `timeStamp`), ms. Strictly
    /// increasing from sample to sample; its origin does not matter.
    pub t_ms: f64,
    /// The point under the cursor on the tissue surface, world frame, m.
    pub surface_in_world_m: [f64; 3],
    /// How deep the trainee pushes the tip below the surface (wheel, pen pressure or keys), m,
    /// in [[`MIN_DEPTH_M`], [`MAX_DEPTH_M`]].
    pub depth_m: f64,
    /// The button is held: the blade is engaged (the trainee means to cut).
    pub blade_engaged: bool,
    /// A pen's pressure, 0 to 1 (`PointerEvent.pressure`); checked, not used for the pose.
    #[serde(default)]
    pub pressure: Option<f64>,
    /// The tool's orientation, `world_from_tool` as a quaternion `x, y, z, w` (the order of
    /// three.js and glTF), used when the device's orientation is
    /// [`super::PointerOrientation::PerSample`].
    #[serde(default)]
    pub world_from_tool_xyzw: Option<[f64; 4]>,
    /// The trainee holds the wound retractor set (the scalpel's
    /// [`crate::pose::BUTTON_RETRACT`]; a grasper's sample ignores it).
    #[serde(default)]
    pub retractor: bool,
}

/// What the checks made of a sample, before its time is compared with the last one's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SampleCheck {
    /// Every number finite and in range.
    Usable,
    /// A NaN or an infinity somewhere: the page is broken (the device faults).
    NonFinite,
    /// Finite but out of range (dropped and counted).
    Absurd,
}

impl PointerSample {
    /// A sample at `t_ms` with the cursor on `surface_in_world_m`, the tip `depth_m` below it.
    pub fn new(t_ms: f64, surface_in_world_m: [f64; 3], depth_m: f64, blade_engaged: bool) -> Self {
        Self {
            t_ms,
            surface_in_world_m,
            depth_m,
            blade_engaged,
            pressure: None,
            world_from_tool_xyzw: None,
            retractor: false,
        }
    }

    /// True when every number of the sample is finite.
    pub fn is_finite(&self) -> bool {
        self.t_ms.is_finite()
            && self.surface_in_world_m.iter().all(|c| c.is_finite())
            && self.depth_m.is_finite()
            && self.pressure.is_none_or(f64::is_finite)
            && self
                .world_from_tool_xyzw
                .is_none_or(|q| q.iter().all(|c| c.is_finite()))
    }

    /// Checks the numbers of the sample on their own (the order of samples is the device's
    /// business).
    pub fn check(&self) -> SampleCheck {
        if !self.is_finite() {
            return SampleCheck::NonFinite;
        }
        let distance_m = self
            .surface_in_world_m
            .iter()
            .map(|c| c * c)
            .sum::<f64>()
            .sqrt();
        let quaternion_ok = self.world_from_tool_xyzw.is_none_or(|q| {
            let norm = q.iter().map(|c| c * c).sum::<f64>().sqrt();
            (norm - 1.0).abs() <= QUATERNION_NORM_TOLERANCE
        });
        if distance_m <= MAX_DISTANCE_FROM_ORIGIN_M
            && (MIN_DEPTH_M..=MAX_DEPTH_M).contains(&self.depth_m)
            && self.pressure.is_none_or(|p| (0.0..=1.0).contains(&p))
            && quaternion_ok
        {
            SampleCheck::Usable
        } else {
            SampleCheck::Absurd
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checks_sort_samples_into_usable_non_finite_and_absurd() {
        let good = PointerSample::new(10.0, [0.01, 0.02, 0.0], 0.003, true);
        assert_eq!(good.check(), SampleCheck::Usable);
        let with = |f: fn(&mut PointerSample)| {
            let mut s = good;
            f(&mut s);
            s.check()
        };
        assert_eq!(with(|s| s.t_ms = f64::NAN), SampleCheck::NonFinite);
        assert_eq!(
            with(|s| s.surface_in_world_m[1] = f64::INFINITY),
            SampleCheck::NonFinite
        );
        assert_eq!(
            with(|s| s.depth_m = f64::NEG_INFINITY),
            SampleCheck::NonFinite
        );
        assert_eq!(
            with(|s| s.pressure = Some(f64::NAN)),
            SampleCheck::NonFinite
        );
        assert_eq!(
            with(|s| s.world_from_tool_xyzw = Some([0.0, 0.0, f64::NAN, 1.0])),
            SampleCheck::NonFinite
        );
        assert_eq!(
            with(|s| s.surface_in_world_m = [8.0, 8.0, 0.0]),
            SampleCheck::Absurd
        );
        assert_eq!(with(|s| s.depth_m = 0.2), SampleCheck::Absurd);
        assert_eq!(with(|s| s.depth_m = -0.06), SampleCheck::Absurd);
        assert_eq!(with(|s| s.pressure = Some(1.5)), SampleCheck::Absurd);
        assert_eq!(
            with(|s| s.world_from_tool_xyzw = Some([0.0, 0.0, 0.0, 0.0])),
            SampleCheck::Absurd
        );
        assert_eq!(
            with(|s| s.world_from_tool_xyzw = Some([0.0, 0.0, 0.0, 1.0005])),
            SampleCheck::Usable
        );
        // the wire form: optional fields may be left out
        let parsed: PointerSample = serde_json::from_str(
            r#"{"t_ms":1.5,"surface_in_world_m":[0,0.01,0],"depth_m":0.002,"blade_engaged":false}"#,
        )
        .expect("json");
        assert_eq!(
            parsed,
            PointerSample::new(1.5, [0.0, 0.01, 0.0], 0.002, false)
        );
    }
}
