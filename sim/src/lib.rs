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
//!
//! A first cut: load a built-in scene, settle it, draw a scalpel across it while the
//! simulation steps, and write the result as a `.vtu` file (here into a string;
//! [`io::write_vtu`] writes a file). `sim/examples/first_cut.rs` is the same, runnable.
//!
//! ```
//! use cutlab_sim::cut::{Blade, Cutter};
//! use cutlab_sim::io::{PointData, vtu_string};
//! use cutlab_sim::scene::{BuildOptions, Scene};
//! use cutlab_sim::solver::StaticSettings;
//!
//! let scene = Scene::load("chest-wall", BuildOptions { min_tets: Some(2_000) })?;
//! let mut sim = scene.simulation();
//! assert!(sim.settle(StaticSettings::default()).converged);
//! let tets_before = sim.model.mesh.tet_count();
//! let mut cutter = Cutter::default();
//! for k in 0..=20 {
//!     // the blade normal to the wall's outer surface (radius 150 mm), 8 mm deep
//!     let x_m = -0.01 + 0.001 * k as f64;
//!     let blade = Blade::normal_to_curved_slab(x_m, 0.0004, 0.15, 0.008, 0.005);
//!     cutter.advance(&mut sim, blade)?;
//!     sim.step()?;
//! }
//! assert!(sim.model.mesh.tet_count() > tets_before); // tetrahedra were split
//! let vtu = vtu_string(
//!     &sim.model.mesh,
//!     &[("velocity", PointData::Vector(&sim.state.velocities))],
//! )?;
//! assert!(vtu.contains("UnstructuredGrid"));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]

pub mod cut;
pub mod cut_stress;
pub mod error;
pub mod fem;
pub mod generate;
pub mod grasp;
pub mod hash;
pub mod io;
pub mod mesh;
pub mod model;
mod parallel;
pub mod reference;
pub mod retractor;
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
