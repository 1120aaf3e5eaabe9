//! Finite-element materials: Young's modulus, Poisson's ratio and Rayleigh damping per region.
//! Density and pre-tension stay in [`crate::model::Material`], shared with the springs.

use serde::{Deserialize, Serialize};

/// The elastic and damping parameters of a region for the finite elements.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FemMaterial {
    /// Young's modulus E in Pa.
    pub youngs_modulus_pa: f64,
    /// Poisson's ratio nu, -1 < nu < 0.5.
    pub poisson_ratio: f64,
    /// Rayleigh mass-proportional damping alpha in 1/s (`C = alpha M + beta K`).
    #[serde(default)]
    pub rayleigh_mass_per_s: f64,
    /// Rayleigh stiffness-proportional damping beta in s.
    #[serde(default)]
    pub rayleigh_stiffness_s: f64,
}

impl FemMaterial {
    /// Default chest wall (subcutaneous fat over skeletal muscle, treated as one isotropic,
    /// linear material at small strain). Sources of each number:
    ///
    /// - `E = 30 kPa`: a value inside the range the literature reports for the two tissues:
    ///   fat 3.25 +/- 0.91 kPa (Samani, Zubovits and Plewes 2007, "Elastic moduli of normal and
    ///   pathological human breast tissues", Phys. Med. Biol. 52:1565) and passive skeletal
    ///   muscle loaded across its fibres, initial shear modulus 15.6 +/- 5.4 kPa, i.e.
    ///   `E = 3 mu` = 47 kPa for an incompressible solid (Bosboom et al. 2001, "Passive
    ///   transverse mechanical properties of skeletal muscle under in vivo compression",
    ///   J. Biomech. 34:1365). Muscle dominates the chest wall's thickness; 30 kPa is a
    ///   modelling choice between the two, not a measurement.
    /// - `nu = 0.45`: soft tissue is nearly incompressible (0.5; muscle under compression along
    ///   its fibres shows 0.5, Pietsch et al. 2014, J. Biomech. Eng. 136(11)). Linear tetrahedra
    ///   lock volumetrically as nu approaches 0.5, so 0.45 is the customary compromise of
    ///   surgical simulators.
    /// - Rayleigh damping `alpha = 1 /s`, `beta = 0.01 s`: not a tissue measurement (the
    ///   measured viscoelastic time constant of muscle is about 6 s, Bosboom et al. 2001, a
    ///   relaxation this linear model does not represent); chosen to damp the lowest modes
    ///   of the chest wall (a few Hz) within about a second, as the paper's dampers do.
    pub const CHEST_WALL: Self = Self {
        youngs_modulus_pa: 30e3,
        poisson_ratio: 0.45,
        rayleigh_mass_per_s: 1.0,
        rayleigh_stiffness_s: 0.01,
    };

    /// The Lame parameters `(mu, lambda)` in Pa: `mu = E / (2 (1 + nu))`,
    /// `lambda = E nu / ((1 + nu) (1 - 2 nu))`.
    pub fn lame_pa(&self) -> (f64, f64) {
        let (e, nu) = (self.youngs_modulus_pa, self.poisson_ratio);
        (
            e / (2.0 * (1.0 + nu)),
            e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
        )
    }

    /// Checks the ranges; the error names the first problem.
    pub fn check(&self) -> Result<(), FemMaterialError> {
        let e = self.youngs_modulus_pa;
        if !(e > 0.0 && e.is_finite()) {
            return Err(FemMaterialError::YoungsModulus(e));
        }
        let nu = self.poisson_ratio;
        if !(nu > -1.0 && nu < 0.5) {
            return Err(FemMaterialError::PoissonRatio(nu));
        }
        for (name, value) in [
            ("rayleigh_mass_per_s", self.rayleigh_mass_per_s),
            ("rayleigh_stiffness_s", self.rayleigh_stiffness_s),
        ] {
            if !(value >= 0.0 && value.is_finite()) {
                return Err(FemMaterialError::Rayleigh { name, value });
            }
        }
        Ok(())
    }
}

/// A [`FemMaterial`] parameter out of range (with the value given).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum FemMaterialError {
    /// Young's modulus (given) is not positive and finite.
    #[error("Young's modulus must be positive and finite, got {0} Pa")]
    YoungsModulus(f64),
    /// Poisson's ratio (given) is outside `(-1, 0.5)`.
    #[error("Poisson's ratio must satisfy -1 < nu < 0.5, got {0}")]
    PoissonRatio(f64),
    /// A Rayleigh damping coefficient is negative or not finite.
    #[error("{name} must be non-negative and finite, got {value}")]
    Rayleigh {
        /// The coefficient's name.
        name: &'static str,
        /// Its value.
        value: f64,
    },
}

impl Default for FemMaterial {
    fn default() -> Self {
        Self::CHEST_WALL
    }
}
