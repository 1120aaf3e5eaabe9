//! Reading single-file NIfTI-1 label volumes (`.nii`, `.nii.gz`).
//!
//! The header is parsed with the `nifti` crate; everything that could panic or allocate on
//! the say-so of a corrupt header (affine, voxel decoding) is done here with checks, and every
//! problem becomes a [`ReadError`] naming the file.
//!
//! Compression is detected from the gzip magic bytes `1f 8b`, not from the file name.

use std::io::Read;
use std::path::Path;

use nalgebra::{Matrix3, Matrix4, Vector3};
use nifti::{Endianness, NiftiHeader};

use crate::ReadError;

/// NIfTI-1 header size (`sizeof_hdr`).
const HEADER_SIZE: usize = 348;
/// Labels stored as floating point (or scaled by `scl_slope`/`scl_inter`) are accepted when
/// they lie within this distance of an integer, which absorbs `f32` round-off but rejects
/// genuinely fractional values such as those of a linear-interpolating resampler.
pub const INTEGRAL_TOLERANCE: f64 = 1e-3;

/// What a NIfTI file contributes to a [`super::LabelVolume`].
#[derive(Debug)]
pub(super) struct RawLabels {
    pub dims: [usize; 3],
    pub labels: Vec<u32>,
    /// Voxel index (centre) to world, in metres.
    pub world_from_voxel: Matrix4<f64>,
}

fn format_err(path: &Path, message: impl Into<String>) -> ReadError {
    ReadError::Format {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// Reads the whole file, gunzipping it when it starts with the gzip magic bytes.
fn read_bytes(path: &Path) -> Result<Vec<u8>, ReadError> {
    let raw = std::fs::read(path).map_err(|source| ReadError::Io {
        path: path.to_path_buf(),
        error: source,
    })?;
    if !raw.starts_with(&[0x1f, 0x8b]) {
        return Ok(raw);
    }
    let mut out = Vec::new();
    flate2::read::MultiGzDecoder::new(&raw[..])
        .read_to_end(&mut out)
        .map_err(|e| format_err(path, format!("corrupt or truncated gzip data: {e}")))?;
    Ok(out)
}

/// Checks the size field and magic before handing the bytes to the `nifti` crate, so that a
/// non-NIfTI file gets a clear message.
fn check_signature(path: &Path, bytes: &[u8]) -> Result<(), ReadError> {
    if bytes.len() < HEADER_SIZE + 4 {
        return Err(format_err(
            path,
            format!(
                "not a NIfTI-1 file: {} bytes, shorter than a NIfTI-1 header",
                bytes.len()
            ),
        ));
    }
    let size = [bytes[0], bytes[1], bytes[2], bytes[3]];
    let (le, be) = (i32::from_le_bytes(size), i32::from_be_bytes(size));
    if le == 540 || be == 540 {
        return Err(format_err(
            path,
            "NIfTI-2 files are not supported (NIfTI-1 only)",
        ));
    }
    if le != HEADER_SIZE as i32 && be != HEADER_SIZE as i32 {
        return Err(format_err(
            path,
            format!("not a NIfTI-1 file: header size field is {le}, expected 348"),
        ));
    }
    match &bytes[344..348] {
        b"n+1\0" => Ok(()),
        b"ni1\0" => Err(format_err(
            path,
            "header-only NIfTI-1 (.hdr/.img pair) is not supported; use a single .nii/.nii.gz",
        )),
        m => Err(format_err(
            path,
            format!("not a NIfTI-1 file: bad magic {m:?}"),
        )),
    }
}

/// Reads a 3-D label volume: dimensions, integer labels (x fastest) and the voxel-to-world
/// affine in metres. See [`super::LabelVolume::read`] for the conventions.
pub(super) fn read_labels(path: &Path) -> Result<RawLabels, ReadError> {
    let bytes = read_bytes(path)?;
    check_signature(path, &bytes)?;
    let header = NiftiHeader::from_reader(&bytes[..])
        .map_err(|e| format_err(path, format!("invalid NIfTI-1 header: {e}")))?;
    let dims = dims_3d(&header).map_err(|m| format_err(path, m))?;
    let world_from_voxel = affine_metres(&header).map_err(|m| format_err(path, m))?;
    let labels = decode_labels(&header, &bytes, dims).map_err(|m| format_err(path, m))?;
    Ok(RawLabels {
        dims,
        labels,
        world_from_voxel,
    })
}

/// The three spatial dimensions; volumes with fewer axes are padded with 1, volumes with more
/// than one entry along axes 4..7 (time series, vector images) are rejected.
fn dims_3d(h: &NiftiHeader) -> Result<[usize; 3], String> {
    let ndim = h.dim[0] as usize;
    if !(1..=7).contains(&ndim) {
        return Err(format!("invalid dim[0] = {} (must be 1..7)", h.dim[0]));
    }
    let mut d = [1usize; 7];
    for a in 0..ndim {
        let v = h.dim[a + 1] as i16; // NIfTI dims are signed shorts
        if v <= 0 {
            return Err(format!("invalid dim[{}] = {v} (must be positive)", a + 1));
        }
        d[a] = v as usize;
    }
    let extra: usize = d[3..].iter().product();
    if extra > 1 {
        return Err(format!(
            "{ndim}-D volume with {extra} 3-D volumes (dim = {:?}); a label volume must be 3-D",
            &d[..ndim]
        ));
    }
    Ok([d[0], d[1], d[2]])
}

/// Metres per unit of the header's spatial unit (`xyzt_units & 7`); unknown (0) is taken
/// as millimetres, the unit of virtually every medical image.
fn metres_per_unit(h: &NiftiHeader) -> Result<f64, String> {
    match h.xyzt_units & 0x07 {
        0 | 2 => Ok(1e-3),
        1 => Ok(1.0),
        3 => Ok(1e-6),
        u => Err(format!("invalid spatial unit code {u} in xyzt_units")),
    }
}

/// The voxel-to-world affine in metres: sform if `sform_code > 0`, else the quaternion
/// qform if `qform_code > 0`, else plain `pixdim` scaling (NIfTI "method 1"). It maps the
/// voxel index `(i, j, k)` to the world position (RAS+) of that voxel's centre.
pub(super) fn affine_metres(h: &NiftiHeader) -> Result<Matrix4<f64>, String> {
    let mut a = if h.sform_code > 0 {
        let r = [h.srow_x, h.srow_y, h.srow_z];
        Matrix4::from_fn(|i, j| {
            if i < 3 {
                r[i][j] as f64
            } else if j == 3 {
                1.0
            } else {
                0.0
            }
        })
    } else if h.qform_code > 0 {
        qform(h)?
    } else {
        let s = spacing(h)?;
        Matrix4::new_nonuniform_scaling(&Vector3::new(s[0], s[1], s[2]))
    };
    let unit = metres_per_unit(h)?;
    for i in 0..3 {
        for j in 0..4 {
            a[(i, j)] *= unit;
        }
    }
    if !a.iter().all(|x| x.is_finite()) {
        return Err("voxel-to-world affine has a non-finite entry".into());
    }
    if a.fixed_view::<3, 3>(0, 0).determinant() == 0.0 {
        return Err("voxel-to-world affine is singular (zero voxel volume)".into());
    }
    Ok(a)
}

fn spacing(h: &NiftiHeader) -> Result<[f64; 3], String> {
    let s = [h.pixdim[1], h.pixdim[2], h.pixdim[3]].map(f64::from);
    if !s.iter().all(|&x| x.is_finite() && x > 0.0) {
        return Err(format!(
            "voxel spacing pixdim[1..4] = {s:?} must be positive"
        ));
    }
    Ok(s)
}

/// qform (NIfTI "method 2"): `x = R diag(dx, dy, qfac dz) (i, j, k) + (qx, qy, qz)` with the
/// rotation `R` of the unit quaternion `(a, b, c, d)`, `a = sqrt(1 - b^2 - c^2 - d^2)`, and
/// `qfac = pixdim[0]` (-1 flips the third axis; any other value counts as +1).
fn qform(h: &NiftiHeader) -> Result<Matrix4<f64>, String> {
    let [b, c, d] = [h.quatern_b, h.quatern_c, h.quatern_d].map(f64::from);
    let s2 = b * b + c * c + d * d;
    if !s2.is_finite() {
        return Err("non-finite qform quaternion".into());
    }
    // As nifti1_io: a slightly super-unit (b, c, d) is normalised with a = 0.
    let (a, b, c, d) = if s2 > 1.0 {
        let n = s2.sqrt();
        (0.0, b / n, c / n, d / n)
    } else {
        ((1.0 - s2).sqrt(), b, c, d)
    };
    #[rustfmt::skip]
    let r = Matrix3::new(
        a * a + b * b - c * c - d * d, 2.0 * (b * c - a * d),         2.0 * (b * d + a * c),
        2.0 * (b * c + a * d),         a * a + c * c - b * b - d * d, 2.0 * (c * d - a * b),
        2.0 * (b * d - a * c),         2.0 * (c * d + a * b),         a * a + d * d - c * c - b * b,
    );
    let qfac = if h.pixdim[0] < 0.0 { -1.0 } else { 1.0 };
    let s = spacing(h)?;
    let m = r * Matrix3::from_diagonal(&Vector3::new(s[0], s[1], s[2] * qfac));
    let mut out = Matrix4::identity();
    out.fixed_view_mut::<3, 3>(0, 0).copy_from(&m);
    out[(0, 3)] = h.quatern_x as f64;
    out[(1, 3)] = h.quatern_y as f64;
    out[(2, 3)] = h.quatern_z as f64;
    Ok(out)
}

/// Decodes the voxel data (x fastest, as stored) into integer labels. Integer types are
/// taken as they are; floats and scaled values must be integral within
/// [`INTEGRAL_TOLERANCE`]; negative labels and labels above `u32::MAX` are errors.
fn decode_labels(h: &NiftiHeader, bytes: &[u8], dims: [usize; 3]) -> Result<Vec<u32>, String> {
    let (size, kind) = match h.datatype {
        2 => (1, Kind::U),
        256 => (1, Kind::I),
        4 => (2, Kind::I),
        512 => (2, Kind::U),
        8 => (4, Kind::I),
        768 => (4, Kind::U),
        1024 => (8, Kind::I),
        1280 => (8, Kind::U),
        16 => (4, Kind::F),
        64 => (8, Kind::F),
        t => {
            return Err(format!(
                "unsupported voxel datatype code {t} for a label volume"
            ));
        }
    };
    let count = dims.iter().try_fold(1usize, |acc, &d| acc.checked_mul(d));
    let offset = h.vox_offset;
    if !(offset.is_finite() && offset >= (HEADER_SIZE + 4) as f32 && offset.fract() == 0.0) {
        return Err(format!("invalid vox_offset {offset}"));
    }
    let offset = offset as usize;
    let needed = count
        .and_then(|n| n.checked_mul(size))
        .and_then(|n| n.checked_add(offset));
    let Some(needed) = needed else {
        return Err(format!("volume {dims:?} is too large"));
    };
    if bytes.len() < needed {
        return Err(format!(
            "truncated voxel data: {dims:?} voxels of {size} bytes from offset {offset} need \
             {needed} bytes, the (decompressed) file has {}",
            bytes.len()
        ));
    }
    let big = h.endianness == Endianness::Big;
    let (slope, inter) = (h.scl_slope as f64, h.scl_inter as f64);
    let scaled =
        slope != 0.0 && slope.is_finite() && inter.is_finite() && (slope != 1.0 || inter != 0.0);
    let data = &bytes[offset..needed];
    let mut labels = Vec::with_capacity(data.len() / size);
    for (n, chunk) in data.chunks_exact(size).enumerate() {
        let raw = kind.value(chunk, big);
        let v = if scaled { raw * slope + inter } else { raw };
        let r = v.round();
        if !((v - r).abs() <= INTEGRAL_TOLERANCE && (0.0..=u32::MAX as f64).contains(&r)) {
            let (nx, ny) = (dims[0], dims[1]);
            let ijk = [n % nx, (n / nx) % ny, n / (nx * ny)];
            return Err(format!(
                "voxel {ijk:?} holds {v}, not a label (labels are integers 0..=4294967295)"
            ));
        }
        labels.push(r as u32);
    }
    Ok(labels)
}

#[derive(Clone, Copy)]
enum Kind {
    U,
    I,
    F,
}

impl Kind {
    /// Value of one stored element of 1, 2, 4 or 8 bytes as `f64` (exact for every integer
    /// that can be a `u32` label).
    fn value(self, b: &[u8], big: bool) -> f64 {
        let mut w = [0u8; 8];
        w[..b.len()].copy_from_slice(b);
        if big {
            w[..b.len()].reverse();
        }
        let bits = u64::from_le_bytes(w);
        let width = 8 * b.len() as u32;
        match self {
            Kind::U => bits as f64,
            Kind::I => {
                let shift = 64 - width;
                (((bits << shift) as i64) >> shift) as f64
            }
            Kind::F if b.len() == 4 => f32::from_bits(bits as u32) as f64,
            Kind::F => f64::from_bits(bits),
        }
    }
}
