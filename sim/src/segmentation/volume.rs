//! [`LabelVolume`]: a 3-D grid of integer labels with its voxel-to-world affine.

use std::path::Path;

use nalgebra::{Matrix4, Vector4};

use super::nifti_io;
use crate::{Point3, ReadError, SegmentationError};

/// A 3-D label image: `dims[0] x dims[1] x dims[2]` voxels, label 0 = background.
///
/// Conventions:
/// - `labels` is stored with x fastest: voxel `(i, j, k)` is at `i + nx (j + ny k)` (the NIfTI
///   on-disk order);
/// - `world_from_voxel` maps the homogeneous voxel index `(i, j, k, 1)` to the world position
///   of the voxel's **centre**, in **metres** (NIfTI world coordinates are RAS+ millimetres;
///   they are scaled by 1e-3 on reading, so the world frame is the scanner's RAS frame);
/// - voxel `(i, j, k)` occupies the parallelepiped with corners at the half-integer indices
///   `(i ± 1/2, j ± 1/2, k ± 1/2)`; its volume is `|det A|` with `A` the upper-left 3x3 block.
#[derive(Debug, Clone, PartialEq)]
pub struct LabelVolume {
    dims: [usize; 3],
    labels: Vec<u32>,
    world_from_voxel: Matrix4<f64>,
}

impl LabelVolume {
    /// A volume from its parts. Fails when the label count is not `dims[0] dims[1] dims[2]`,
    /// a dimension is zero, or the affine is not finite, not affine (bottom row `0 0 0 1`) or
    /// singular.
    pub fn new(
        dims: [usize; 3],
        labels: Vec<u32>,
        world_from_voxel: Matrix4<f64>,
    ) -> Result<Self, SegmentationError> {
        let bad = |m: String| Err(SegmentationError::InvalidVolume(m));
        let count = dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
        if dims.contains(&0) || count != Some(labels.len()) {
            return bad(format!("{} labels for dimensions {dims:?}", labels.len()));
        }
        if !world_from_voxel.iter().all(|x| x.is_finite()) {
            return bad("voxel-to-world affine has a non-finite entry".into());
        }
        if world_from_voxel.row(3) != Vector4::new(0.0, 0.0, 0.0, 1.0).transpose() {
            return bad("voxel-to-world matrix is not affine (bottom row must be 0 0 0 1)".into());
        }
        if world_from_voxel.fixed_view::<3, 3>(0, 0).determinant() == 0.0 {
            return bad("voxel-to-world affine is singular".into());
        }
        Ok(Self {
            dims,
            labels,
            world_from_voxel,
        })
    }

    /// Reads a NIfTI-1 label volume (`.nii` or `.nii.gz`, gzip detected from the content).
    ///
    /// - Affine: sform if `sform_code > 0`, else the quaternion qform if `qform_code > 0`,
    ///   else `diag(pixdim[1..4])`; converted from the header's spatial unit (millimetres when
    ///   unspecified) to metres.
    /// - Data: any integer datatype, or `float32`/`float64` (and `scl_slope`/`scl_inter`
    ///   scaling) when every value is an integer within
    ///   [`INTEGRAL_TOLERANCE`](super::INTEGRAL_TOLERANCE); negative values are errors.
    /// - 1-D/2-D images are read as volumes one voxel thick; 4-D and higher are rejected
    ///   unless the extra axes have length 1.
    ///
    /// Every failure (missing file, corrupt gzip, truncated data, not NIfTI) is a
    /// [`ReadError`] naming the file.
    pub fn read(path: impl AsRef<Path>) -> Result<Self, ReadError> {
        let path = path.as_ref();
        let raw = nifti_io::read_labels(path)?;
        Self::new(raw.dims, raw.labels, raw.world_from_voxel).map_err(|e| ReadError::Format {
            path: path.to_path_buf(),
            message: e.to_string(),
        })
    }

    /// Combines binary masks on a common grid into one label volume: voxels where the mask
    /// of `masks[n]` is non-zero get label `masks[n].1`. Where masks overlap, the **first**
    /// mask in the list wins. All masks must have the same dimensions and affine (to 1e-6 of
    /// the largest affine entry), else the first mismatching file is named in the error.
    /// Labels must be non-zero (0 is background).
    pub fn from_mask_files<P: AsRef<Path>>(masks: &[(P, u32)]) -> Result<Self, SegmentationError> {
        let Some(((first_path, _), _)) = masks.split_first() else {
            return Err(SegmentationError::InvalidOptions(
                "no mask files given".into(),
            ));
        };
        if let Some((_, l)) = masks.iter().find(|(_, l)| *l == 0) {
            return Err(SegmentationError::InvalidOptions(format!(
                "mask label {l} is the background label"
            )));
        }
        let mut combined: Option<LabelVolume> = None;
        for (path, label) in masks {
            let path = path.as_ref();
            let mask = Self::read(path)?;
            let Some(out) = combined.as_mut() else {
                let labels = mask
                    .labels
                    .iter()
                    .map(|&v| if v != 0 { *label } else { 0 })
                    .collect();
                combined = Some(Self { labels, ..mask });
                continue;
            };
            if let Some(why) = out.grid_mismatch(&mask) {
                return Err(ReadError::Format {
                    path: path.to_path_buf(),
                    message: format!(
                        "grid differs from the first mask {}: {why}",
                        first_path.as_ref().display()
                    ),
                }
                .into());
            }
            for (o, &m) in out.labels.iter_mut().zip(&mask.labels) {
                if *o == 0 && m != 0 {
                    *o = *label;
                }
            }
        }
        combined.ok_or_else(|| SegmentationError::InvalidOptions("no mask files given".into()))
    }

    /// Why `other` is not on the same grid as `self`, if it is not.
    pub fn grid_mismatch(&self, other: &LabelVolume) -> Option<String> {
        if self.dims != other.dims {
            return Some(format!("dimensions {:?} vs {:?}", other.dims, self.dims));
        }
        let scale = self
            .world_from_voxel
            .amax()
            .max(other.world_from_voxel.amax());
        let diff = (self.world_from_voxel - other.world_from_voxel).amax();
        if diff > 1e-6 * scale {
            return Some(format!(
                "voxel-to-world affines differ by up to {diff:e} m:\n{}vs{}",
                other.world_from_voxel, self.world_from_voxel
            ));
        }
        None
    }

    /// Number of voxels along x, y, z.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// All labels, x fastest.
    pub fn labels(&self) -> &[u32] {
        &self.labels
    }

    /// Mutable labels (same grid), for the meshing pipeline.
    pub(super) fn labels_mut(&mut self) -> &mut [u32] {
        &mut self.labels
    }

    /// Voxel index (centre) to world, metres.
    pub fn world_from_voxel(&self) -> &Matrix4<f64> {
        &self.world_from_voxel
    }

    /// Linear index of voxel `(i, j, k)`.
    #[inline]
    pub fn index(&self, [i, j, k]: [usize; 3]) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }

    /// Label of voxel `(i, j, k)`.
    #[inline]
    pub fn label(&self, ijk: [usize; 3]) -> u32 {
        self.labels[self.index(ijk)]
    }

    /// World position (metres) of a point given in continuous voxel-index coordinates:
    /// integers are voxel centres, half-integers voxel corners.
    pub fn world(&self, ijk: [f64; 3]) -> Point3 {
        let p = self.world_from_voxel * Vector4::new(ijk[0], ijk[1], ijk[2], 1.0);
        Point3::new(p.x, p.y, p.z)
    }

    /// Signed volume of a voxel, `det A` in m^3: negative when the index-to-world map is
    /// left-handed.
    pub fn signed_voxel_volume(&self) -> f64 {
        self.world_from_voxel.fixed_view::<3, 3>(0, 0).determinant()
    }

    /// Volume of a voxel, `|det A|` in m^3.
    pub fn voxel_volume(&self) -> f64 {
        self.signed_voxel_volume().abs()
    }

    /// Edge lengths of a voxel along the three index axes (column norms of `A`), metres.
    pub fn spacing(&self) -> [f64; 3] {
        [0, 1, 2].map(|c| self.world_from_voxel.fixed_view::<3, 1>(0, c).norm())
    }

    /// Number of voxels carrying each non-zero label, ascending by label.
    pub fn label_counts(&self) -> Vec<(u32, usize)> {
        let mut l: Vec<u32> = self.labels.iter().copied().filter(|&v| v != 0).collect();
        l.sort_unstable();
        let mut out: Vec<(u32, usize)> = Vec::new();
        for v in l {
            match out.last_mut() {
                Some((last, n)) if *last == v => *n += 1,
                _ => out.push((v, 1)),
            }
        }
        out
    }

    /// A copy where every label not in `keep` is replaced by 0.
    pub fn select(&self, keep: &[u32]) -> LabelVolume {
        let labels = self
            .labels
            .iter()
            .map(|&v| if keep.contains(&v) { v } else { 0 })
            .collect();
        Self {
            labels,
            ..self.clone()
        }
    }

    /// Coarsens by integer `factors` per axis with a majority vote: coarse voxel `(I, J, K)`
    /// gathers the fine voxels `f I .. f I + f - 1` along each axis (fewer at the far end
    /// when `f` does not divide the size) and takes their most frequent value, background
    /// included; a tie goes to the tied value met first in x-fastest order within the block
    /// (a corner-anchored rule that erodes and dilates equally often on a closed surface).
    /// The coarse grid has `ceil(n / f)` voxels per axis and the affine
    /// `A' = A [diag(f) | (f - 1) / 2]`, so each coarse voxel's centre is the centre of its
    /// (full-size) block; blocks that stick out of the fine grid extend beyond it.
    pub fn coarsen(&self, factors: [usize; 3]) -> Result<LabelVolume, SegmentationError> {
        if factors.contains(&0) {
            return Err(SegmentationError::InvalidOptions(
                "coarsening factor 0".into(),
            ));
        }
        let [fx, fy, fz] = factors;
        let cd = [0, 1, 2].map(|a| self.dims[a].div_ceil(factors[a]));
        let mut labels = Vec::with_capacity(cd[0] * cd[1] * cd[2]);
        let mut tally: Vec<(u32, u32)> = Vec::with_capacity(fx * fy * fz);
        for ck in 0..cd[2] {
            for cj in 0..cd[1] {
                for ci in 0..cd[0] {
                    tally.clear();
                    for k in ck * fz..((ck + 1) * fz).min(self.dims[2]) {
                        for j in cj * fy..((cj + 1) * fy).min(self.dims[1]) {
                            for i in ci * fx..((ci + 1) * fx).min(self.dims[0]) {
                                let v = self.label([i, j, k]);
                                match tally.iter_mut().find(|(l, _)| *l == v) {
                                    Some((_, n)) => *n += 1,
                                    None => tally.push((v, 1)),
                                }
                            }
                        }
                    }
                    // Strictly greater: the earliest value wins a tie.
                    let mut best = (0u32, 0u32);
                    for &(l, n) in &tally {
                        if n > best.1 {
                            best = (l, n);
                        }
                    }
                    labels.push(best.0);
                }
            }
        }
        let mut fine_from_coarse = Matrix4::identity();
        for a in 0..3 {
            fine_from_coarse[(a, a)] = factors[a] as f64;
            fine_from_coarse[(a, 3)] = (factors[a] as f64 - 1.0) / 2.0;
        }
        Self::new(cd, labels, self.world_from_voxel * fine_from_coarse)
    }
}
