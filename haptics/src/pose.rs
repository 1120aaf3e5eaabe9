//! The tool's pose.

use crate::{Point3, Rotation, Vector3};

/// Button bit: the blade is engaged (the trainee means to cut).
pub const BUTTON_BLADE: u32 = 1;

/// Button bit of a grasper: its jaws are closed (the second hand holds what is between them;
/// the pose's tip is the jaws' centre).
pub const BUTTON_JAWS: u32 = 2;

/// Button bit of the scalpel's device: the trainee holds a wound retractor set in the
/// incision ([`crate::retraction`]).
pub const BUTTON_RETRACT: u32 = 4;

/// Pose of the scalpel: its tip in the world, its orientation and its buttons.
///
/// Tool frame: origin at the blade's tip, +z along the cutting edge towards the handle, +x the
/// cutting direction (the sharp side).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToolPose {
    /// The blade's tip, in the world frame, m.
    pub tip_in_world: Point3,
    /// The tool frame's orientation in the world.
    pub world_from_tool: Rotation,
    /// The device's buttons, one bit each ([`BUTTON_BLADE`]: the blade engaged).
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

    /// Whether a grasper's jaws are closed.
    pub fn jaws_closed(&self) -> bool {
        self.buttons & BUTTON_JAWS != 0
    }

    /// The pose as a rigid transform, `world_from_tool` placed at the tip.
    pub fn isometry(&self) -> nalgebra::Isometry3<f64> {
        nalgebra::Isometry3::from_parts(
            nalgebra::Translation3::from(self.tip_in_world.coords),
            self.world_from_tool,
        )
    }

    /// Whether the blade is engaged (may cut).
    pub fn blade_engaged(&self) -> bool {
        self.buttons & BUTTON_BLADE != 0
    }
}
