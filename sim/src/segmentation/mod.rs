//! Segmentation to mesh: a NIfTI label volume and a set of labels become a conforming
//! tetrahedral mesh in world coordinates (metres), with the label as material region.
//!
//! Pipeline of [`mesh_labels`]:
//! 1. keep the requested labels, set every other voxel to background 0
//!    ([`LabelVolume::select`]);
//! 2. optionally coarsen by integer factors with a majority vote ([`Resample`],
//!    [`LabelVolume::coarsen`]);
//! 3. optionally keep only the largest face-connected component of the selected voxels
//!    (all labels together);
//! 4. optionally fill voxels until the voxel surface is a 2-manifold ([`NonManifold`]);
//! 5. split every selected voxel into the six Kuhn tetrahedra (identical split in every
//!    voxel, hence conforming, also between labels); only corners of selected voxels become
//!    vertices, at `A (i - 1/2, j - 1/2, k - 1/2, 1)` with `A` the voxel-to-world affine;
//! 6. optionally smooth the boundary (Taubin, orientation-preserving).
//!
//! Without resampling, repair or smoothing the mesh has exactly 6 tetrahedra per selected
//! voxel and its volume is the voxel count times `|det A|`.
//!
//! Coordinates: NIfTI world coordinates are RAS+ millimetres (the header's unit, mm when
//! unspecified); cutlab works in metres, so they are scaled by 1e-3. A left-handed index
//! frame (`det A < 0`, common for radiological storage order) is handled by the vertex order
//! of the tetrahedra, which always come out positively oriented.

mod hex;
mod nifti_io;
mod smooth;
mod volume;
mod voxels;

pub use hex::KUHN_TETS;
pub use nifti_io::INTEGRAL_TOLERANCE;
pub use smooth::MIN_VOLUME_RATIO;
pub use volume::LabelVolume;

use crate::{SegmentationError, TetMesh};

/// How to resample the label grid before meshing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Resample {
    /// Coarsen by the same integer factor along all three axes (1 = unchanged).
    Factor(usize),
    /// Coarsen by an integer factor per index axis.
    Factors([usize; 3]),
    /// Coarsen towards a voxel size in metres per index axis: the factor along each axis is
    /// `max(1, round(target / spacing))`, so the result is the nearest integer multiple of
    /// the original spacing (never finer than it).
    Spacing([f64; 3]),
}

impl Resample {
    /// Integer coarsening factors for a volume with voxel edge lengths `spacing` (metres).
    pub fn factors(&self, spacing: [f64; 3]) -> Result<[usize; 3], SegmentationError> {
        let f = match *self {
            Resample::Factor(f) => [f; 3],
            Resample::Factors(f) => f,
            Resample::Spacing(t) => {
                if !t.iter().all(|x| x.is_finite() && *x > 0.0) {
                    return Err(SegmentationError::InvalidOptions(format!(
                        "target spacing {t:?} must be positive"
                    )));
                }
                [0, 1, 2].map(|a| ((t[a] / spacing[a]).round() as usize).max(1))
            }
        };
        if f.contains(&0) {
            return Err(SegmentationError::InvalidOptions(format!(
                "coarsening factors {f:?} must be >= 1"
            )));
        }
        Ok(f)
    }
}

/// What to do where voxels touch only along an edge or at a vertex (or a void is pinched
/// that way), so that the voxel surface is not a 2-manifold there. The tetrahedral mesh is
/// conforming and valid either way.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NonManifold {
    /// Mesh the voxels as they are (default): exact voxel volume, possibly a self-touching
    /// boundary. The count is reported in [`MeshingReport::non_manifold_vertices`].
    #[default]
    Keep,
    /// Fill background voxels around offending vertices until the surface is manifold; the
    /// filled voxels take the majority label of their block. Adds volume.
    Fill,
}

/// Options of [`mesh_labels`]. `MeshingOptions::new(labels)` gives the plain voxel mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshingOptions {
    /// Labels to mesh; each becomes the region id of its tetrahedra. Must be non-empty and
    /// must not contain the background label 0.
    pub labels: Vec<u32>,
    /// Coarsening before meshing, `None` for the original grid.
    pub resample: Option<Resample>,
    /// Keep only the largest face-connected component of the selected voxels (all selected
    /// labels together), dropping disconnected islands.
    pub keep_largest_component: bool,
    /// Handling of edge/vertex contacts of the voxel surface.
    pub non_manifold: NonManifold,
    /// Taubin (lambda = 0.5, mu = -0.53) smoothing iterations of the boundary vertices
    /// (0 = none), neighbours taken along boundary edges; the negative mu step undoes the
    /// shrinkage of plain Laplacian smoothing. Vertices move one at a time and a move is
    /// undone when a tetrahedron around the vertex would fall below [`MIN_VOLUME_RATIO`] of
    /// its unsmoothed volume, so all tetrahedra stay positively oriented.
    pub smooth_iterations: usize,
}

impl MeshingOptions {
    /// The requested labels, no resampling, no clean-up, no smoothing.
    pub fn new(labels: impl Into<Vec<u32>>) -> Self {
        Self {
            labels: labels.into(),
            resample: None,
            keep_largest_component: false,
            non_manifold: NonManifold::Keep,
            smooth_iterations: 0,
        }
    }
}

/// What [`mesh_labels_with_report`] did.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MeshingReport {
    /// Coarsening factors applied per axis (`[1, 1, 1]` without resampling).
    pub factors: [usize; 3],
    /// Voxel edge lengths of the meshed grid, metres.
    pub voxel_size: [f64; 3],
    /// Meshed voxels per label, ascending by label.
    pub voxels_per_label: Vec<(u32, usize)>,
    /// Face-connected components before [`MeshingOptions::keep_largest_component`] (0 when
    /// the option is off).
    pub components: usize,
    /// Voxels dropped with the smaller components.
    pub island_voxels_removed: usize,
    /// Grid vertices where the voxel surface was not manifold (before any repair).
    pub non_manifold_vertices: usize,
    /// Voxels added by [`NonManifold::Fill`].
    pub voxels_filled: usize,
    /// Boundary vertex moves undone by the smoothing to keep tetrahedra well oriented.
    pub smoothing_moves_rejected: usize,
}

impl MeshingReport {
    /// Total number of meshed voxels.
    pub fn voxel_count(&self) -> usize {
        self.voxels_per_label.iter().map(|(_, n)| n).sum()
    }
}

/// Meshes the voxels carrying `options.labels`; see the module documentation.
pub fn mesh_labels(
    volume: &LabelVolume,
    options: &MeshingOptions,
) -> Result<TetMesh, SegmentationError> {
    mesh_labels_with_report(volume, options).map(|(mesh, _)| mesh)
}

/// [`mesh_labels`], also returning what was done to the voxels.
pub fn mesh_labels_with_report(
    volume: &LabelVolume,
    options: &MeshingOptions,
) -> Result<(TetMesh, MeshingReport), SegmentationError> {
    if options.labels.is_empty() {
        return Err(SegmentationError::InvalidOptions(
            "no labels selected".into(),
        ));
    }
    if options.labels.contains(&0) {
        return Err(SegmentationError::InvalidOptions(
            "label 0 is the background and cannot be meshed".into(),
        ));
    }
    let mut report = MeshingReport {
        factors: [1; 3],
        ..Default::default()
    };
    let mut vol = volume.select(&options.labels);
    if let Some(resample) = options.resample {
        report.factors = resample.factors(volume.spacing())?;
        if report.factors != [1; 3] {
            vol = vol.coarsen(report.factors)?;
        }
    }
    report.voxel_size = vol.spacing();
    let dims = vol.dims();
    if options.keep_largest_component {
        let (components, removed) = voxels::keep_largest_component(dims, vol.labels_mut());
        report.components = components;
        report.island_voxels_removed = removed;
    }
    report.non_manifold_vertices = voxels::non_manifold_vertices(dims, vol.labels()).len();
    if options.non_manifold == NonManifold::Fill && report.non_manifold_vertices > 0 {
        let (filled, _left) = voxels::fill_non_manifold(dims, vol.labels_mut(), usize::MAX);
        report.voxels_filled = filled;
    }
    report.voxels_per_label = vol.label_counts();
    let Some(m) = hex::voxel_tets(&vol) else {
        return Err(SegmentationError::NoVoxels {
            labels: options.labels.clone(),
        });
    };
    let mut mesh = TetMesh::new(m.positions, m.tets, m.regions)?;
    report.smoothing_moves_rejected = smooth::smooth_boundary(&mut mesh, options.smooth_iterations);
    Ok((mesh, report))
}
