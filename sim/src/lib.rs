//! cutlab-sim: a pre-tensioned particle model of soft tissue on a tetrahedral mesh, after
//! Nakao et al., "Combining Volumetric Soft Tissue Cuts for Interventional Surgery
//! Simulation".
//!
//! Pure, deterministic data and functions: no threads, clocks, files of sessions, databases or
//! the web. SI units throughout (metres, kilograms, seconds, newtons), `f64` everywhere.
//!
//! - [`mesh`]: the tetrahedral mesh, its topology, validation and quality measures;
//! - [`io`]: mesh readers (Gmsh, TetGen, VTK) and the `.vtu` writer;
//! - [`segmentation`]: NIfTI label volumes to conforming voxel tetrahedral meshes;
//! - [`generate`]: built-in structured meshes (slabs, sheets, bars);
//! - [`model`]: the particle/spring/damper model with pre-tension;
//! - [`fem`]: co-rotational linear tetrahedral finite elements (the converging alternative);
//! - [`solver`]: time integrators and static equilibrium;
//! - [`cut`]: volumetric cutting: vertex movement, minimal subdivision, particle remodelling;
//! - [`scene`]: scene files and built-in scenes;
//! - [`reference`]: reference problems with known answers (patch test, cantilever, wound
//!   opening, free vibration);
//! - [`stability`]: stability stress cases (sweeps of step, stiffness, damping, mass ratio);
//! - [`stats`]: percentiles and summaries of samples (timings);
//! - [`rng`]: a small seeded random number generator (SplitMix64).

#![warn(missing_docs)]

pub mod cut;
pub mod error;
pub mod fem;
pub mod generate;
pub mod hash;
pub mod io;
pub mod mesh;
pub mod model;
mod parallel;
pub mod reference;
pub mod rng;
pub mod scene;
pub mod segmentation;
pub mod solver;
pub mod stability;
pub mod stats;

pub use error::{MeshError, ReadError, SegmentationError};
pub use mesh::TetMesh;

/// 3-D point in metres.
pub type Point3 = nalgebra::Point3<f64>;
/// 3-D vector (displacement in metres, velocity in m/s, force in N, by context).
pub type Vector3 = nalgebra::Vector3<f64>;
