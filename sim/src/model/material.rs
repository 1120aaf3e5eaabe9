//! Materials of the particle model: density, spring stiffness, damping and pre-tension.

use serde::{Deserialize, Serialize};

/// How the spring constant of an edge is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum SpringStiffness {
    /// The same constant on every edge (the paper: 100 N/m).
    Uniform {
        /// The spring constant in N/m.
        newtons_per_metre: f64,
    },
    /// Derived from Young's modulus after van Gelder:
    /// `k_e = sum over tets t sharing edge e of E_t V_t / |l_e|^2`.
    YoungsModulus {
        /// Young's modulus `E` in Pa, the same in every tet of the region.
        pascals: f64,
    },
}

/// Material of a region of the mesh.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// Mass density rho in kg/m^3 (the paper's chest wall: 0.90 g/cm^3 = 900 kg/m^3).
    pub density_kg_per_m3: f64,
    /// How each edge's spring constant is chosen.
    pub stiffness: SpringStiffness,
    /// Damper coefficient along each edge in N s/m (the paper: 0.05).
    pub damping_newton_seconds_per_metre: f64,
    /// Tension parameter s of `l = d (1 - s)`, 0 <= s < 1 (the paper's chest wall: 0.04).
    pub pretension: f64,
}

impl Material {
    /// The paper's chest wall: 0.90 g/cm^3, 100 N/m, 0.05 N s/m, 4 % tension.
    pub const PAPER_CHEST_WALL: Self = Self {
        density_kg_per_m3: 900.0,
        stiffness: SpringStiffness::Uniform {
            newtons_per_metre: 100.0,
        },
        damping_newton_seconds_per_metre: 0.05,
        pretension: 0.04,
    };

    /// Checks that every parameter is finite and in range; the error names the first problem.
    pub fn check(&self) -> Result<(), MaterialError> {
        let k = match self.stiffness {
            SpringStiffness::Uniform { newtons_per_metre } => newtons_per_metre,
            SpringStiffness::YoungsModulus { pascals } => pascals,
        };
        if !(self.density_kg_per_m3 > 0.0 && self.density_kg_per_m3.is_finite()) {
            return Err(MaterialError::Density(self.density_kg_per_m3));
        }
        if !(k > 0.0 && k.is_finite()) {
            return Err(MaterialError::Stiffness(k));
        }
        let c = self.damping_newton_seconds_per_metre;
        if !(c >= 0.0 && c.is_finite()) {
            return Err(MaterialError::Damping(c));
        }
        if !(0.0..1.0).contains(&self.pretension) {
            return Err(MaterialError::Pretension(self.pretension));
        }
        Ok(())
    }
}

/// A [`Material`] parameter out of range (with the value given).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum MaterialError {
    /// The density (given) is not positive and finite.
    #[error("density must be positive and finite, got {0}")]
    Density(f64),
    /// The stiffness (given) is not positive and finite.
    #[error("stiffness must be positive and finite, got {0}")]
    Stiffness(f64),
    /// The damping (given) is negative or not finite.
    #[error("damping must be non-negative and finite, got {0}")]
    Damping(f64),
    /// The pre-tension (given) is outside `[0, 1)`.
    #[error("pretension s must satisfy 0 <= s < 1, got {0}")]
    Pretension(f64),
}

impl Default for Material {
    fn default() -> Self {
        Self::PAPER_CHEST_WALL
    }
}
