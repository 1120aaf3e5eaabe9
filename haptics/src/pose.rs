//! The tool's pose and a small seeded random number generator.

use crate::{Point3, Rotation, Vector3};

/// Button bit: the blade is engaged (the trainee means to cut).
pub const BUTTON_BLADE: u32 = 1;

/// Pose of the scalpel: its tip in the world, its orientation and its buttons.
///
/// Tool frame: origin at the blade's tip, +z along the cutting edge towards the handle, +x the
/// cutting direction (the sharp side).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToolPose {
    pub tip_in_world: Point3,
    pub world_from_tool: Rotation,
    pub buttons: u32,
}

impl Default for ToolPose {
    fn default() -> Self {
        Self {
            tip_in_world: Point3::origin(),
            world_from_tool: Rotation::identity(),
            buttons: 0,
        }
    }
}

impl ToolPose {
    /// True when every number is finite.
    pub fn is_finite(&self) -> bool {
        self.tip_in_world.iter().all(|c| c.is_finite())
            && self.world_from_tool.coords.iter().all(|c| c.is_finite())
    }

    /// Unit vector from the tip along the cutting edge towards the handle, in the world.
    pub fn edge_direction(&self) -> Vector3 {
        self.world_from_tool * Vector3::z()
    }

    /// The heel of a blade `blade_length_m` long: the end of the cutting edge away from the
    /// tip, in the world.
    pub fn blade_heel(&self, blade_length_m: f64) -> Point3 {
        self.tip_in_world + self.edge_direction() * blade_length_m
    }

    pub fn blade_engaged(&self) -> bool {
        self.buttons & BUTTON_BLADE != 0
    }
}

/// SplitMix64: a tiny, fast, seedable generator (deterministic on every platform).
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed ^ 0x5851_f42d_4c95_7f2d)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Standard normal (Box-Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform(); // (0, 1]
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rng_is_seeded_and_roughly_normal() {
        let mut a = Rng::new(7);
        let mut b = Rng::new(7);
        assert_eq!(a.next_u64(), b.next_u64());
        let n = 20_000;
        let xs: Vec<f64> = (0..n).map(|_| a.normal()).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        assert!(
            mean.abs() < 0.03 && (var - 1.0).abs() < 0.05,
            "{mean} {var}"
        );
    }
}
