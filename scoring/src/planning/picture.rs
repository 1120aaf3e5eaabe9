//! The field as a picture: the opened wound and the target behind it as the scene's viewpoint
//! sees them, one ray per pixel through the tissue's current surface and onto the target.
//!
//! A pixel's ray from the eye `e` along `d` takes the nearest of the tissue's surface (each
//! triangle in the colour of the region of its tetrahedron, so the wound's walls show their
//! layers) and the target's ellipsoid `|(p - c) / r| = 1` (solved in closed form). It is
//! lit from the eye: colour `k (A + (1 - A) |n . d|)` with [`AMBIENT`], and written as sRGB.
//! Nothing hit is the background.

use nalgebra::{Point3, Vector3};
use parry3d_f64::query::RayCast;
use parry3d_f64::shape::TriMesh;

use cutlab_sim::scene::SceneSpec;
use cutlab_sim::solver::Simulation;

use crate::error::{Result, ScoreError};
use crate::metrics::exposure::{Ellipsoid, ray};

/// The share of a surface's colour it keeps when it turns away from the eye.
pub const AMBIENT: f64 = 0.3;
/// A region's colour when its scene gives none (linear RGB).
pub const TISSUE_RGB: [f64; 3] = [0.80, 0.55, 0.50];
/// The target's colour (linear RGB): a deep red, redder than any muscle of the wall (its
/// red over green is more than 3 in every light, the muscles' under 2).
pub const TARGET_RGB: [f64; 3] = [0.55, 0.02, 0.03];
/// A structure to spare's colour (linear RGB): the lung's pink grey.
pub const SPARE_RGB: [f64; 3] = [0.62, 0.42, 0.45];
/// Where a ray meets nothing (linear RGB).
pub const BACKGROUND_RGB: [f64; 3] = [0.02, 0.02, 0.025];

/// An 8-bit sRGB image, rows top to bottom.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Picture {
    /// Pixels across.
    pub width_px: u32,
    /// Pixels down.
    pub height_px: u32,
    /// `r, g, b` of each pixel, row by row.
    pub rgb: Vec<u8>,
}

impl Picture {
    /// The picture as a PNG file's bytes.
    pub fn png(&self) -> Result<Vec<u8>> {
        let mut out = Vec::new();
        let mut encoder = png::Encoder::new(&mut out, self.width_px, self.height_px);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let fail = |e: png::EncodingError| ScoreError::InvalidInput(format!("the picture: {e}"));
        let mut writer = encoder.write_header().map_err(fail)?;
        writer.write_image_data(&self.rgb).map_err(fail)?;
        writer.finish().map_err(fail)?;
        Ok(out)
    }
}

/// Where a picture is taken from and what it frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// The eye, m.
    pub eye_m: Point3<f64>,
    /// The point at the picture's centre, m.
    pub look_at_m: Point3<f64>,
    /// The direction shown upwards (need not be square to the view).
    pub top: Vector3<f64>,
    /// Half the picture's width at the distance of `look_at_m`, m.
    pub half_width_m: f64,
    /// Pixels across and down.
    pub size_px: u32,
}

impl Camera {
    /// The scene's viewpoint looking at `look_at_m`, framing `half_width_m` either side of
    /// it, with the scene's `along` as the picture's right where it can be; none without a
    /// viewpoint.
    pub fn of_scene(
        scene: &SceneSpec,
        look_at_m: Point3<f64>,
        half_width_m: f64,
        size_px: u32,
    ) -> Option<Self> {
        let eye_m = Point3::from(scene.viewpoint.as_ref()?.eye_mm) * 1e-3;
        let (up, along) = scene.incision.unit().ok()?;
        let forward = (look_at_m - eye_m).try_normalize(1e-12)?;
        let mut top = up.cross(&along);
        if top.cross(&forward).norm() < 0.1 {
            top = up;
        }
        Some(Self {
            eye_m,
            look_at_m,
            top,
            half_width_m,
            size_px,
        })
    }
}

/// The colour of each of `sim`'s surface triangles: its region's, from `scene`.
pub fn triangle_colours(scene: &SceneSpec, sim: &Simulation) -> Vec<[f64; 3]> {
    let mesh = &sim.model.mesh;
    let topology = mesh.topology();
    topology
        .boundary
        .iter()
        .map(|&face| {
            let region = topology
                .tets_of_face(face)
                .next()
                .map(|t| mesh.regions()[t as usize]);
            scene
                .materials
                .iter()
                .find(|m| Some(m.region) == region)
                .and_then(|m| m.colour_rgb)
                .unwrap_or(TISSUE_RGB)
        })
        .collect()
}

/// Where a ray from `o` along unit `d` first meets `e`, and the outward normal there.
fn hit_ellipsoid(e: &Ellipsoid, o: &Point3<f64>, d: &Vector3<f64>) -> Option<(f64, Vector3<f64>)> {
    let (oc, dr) = (
        (o - e.centre_m).component_div(&e.radii_m),
        d.component_div(&e.radii_m),
    );
    let (a, b, c) = (dr.dot(&dr), 2.0 * oc.dot(&dr), oc.dot(&oc) - 1.0);
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return None;
    }
    let t = (-b - disc.sqrt()) / (2.0 * a);
    let normal = (o + d * t - e.centre_m)
        .component_div(&e.radii_m.component_mul(&e.radii_m))
        .try_normalize(1e-15)?;
    (t > 0.0).then_some((t, normal))
}

fn srgb(linear: f64) -> u8 {
    (linear.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0).round() as u8
}

/// What a picture shows: the tissue's surface, its triangles' colours, the target and the
/// structures to spare behind it.
#[derive(Debug, Clone)]
pub struct Shown<'a> {
    pub tissue: &'a TriMesh,
    pub colours: Vec<[f64; 3]>,
    pub target: &'a Ellipsoid,
    pub spare: &'a [Ellipsoid],
    /// The way out of the body: the target and the structures to spare are shown only
    /// under the tissue, within its bounds across `up` (the lung reaches beyond a window).
    pub up: Vector3<f64>,
}

impl<'a> Shown<'a> {
    /// `sim`'s tissue, whose surface is `tissue`, in `scene`'s region colours
    /// ([`triangle_colours`]), with `target` and `spare` behind it.
    pub fn new(
        scene: &SceneSpec,
        sim: &Simulation,
        tissue: &'a TriMesh,
        target: &'a Ellipsoid,
        spare: &'a [Ellipsoid],
        up: Vector3<f64>,
    ) -> Self {
        Self {
            tissue,
            colours: triangle_colours(scene, sim),
            target,
            spare,
            up,
        }
    }

    /// The nearest thing along the ray from `eye` along unit `d`: its colour and normal.
    fn hit(&self, eye: &Point3<f64>, d: &Vector3<f64>) -> Option<([f64; 3], Vector3<f64>)> {
        let mut best: Option<(f64, [f64; 3], Vector3<f64>)> = None;
        let mut take = |t: f64, colour: [f64; 3], n: Vector3<f64>| {
            if best.is_none_or(|b| t < b.0) {
                best = Some((t, colour, n));
            }
        };
        if let Some(s) = self
            .tissue
            .cast_local_ray_and_get_normal(&ray(eye, d), 10.0, false)
        {
            let colour = self.colours.get(s.subshape as usize).copied();
            let n = Vector3::new(s.normal.x, s.normal.y, s.normal.z);
            take(s.time_of_impact, colour.unwrap_or(TISSUE_RGB), n);
        }
        let aabb = self.tissue.local_aabb();
        let under = |t: f64| {
            let p = eye + d * t;
            (0..3).all(|k| self.up[k].abs() > 0.5 || (aabb.mins[k]..=aabb.maxs[k]).contains(&p[k]))
        };
        let behind = std::iter::once((self.target, TARGET_RGB))
            .chain(self.spare.iter().map(|e| (e, SPARE_RGB)));
        for (e, colour) in behind {
            if let Some((t, n)) = hit_ellipsoid(e, eye, d).filter(|&(t, _)| under(t)) {
                take(t, colour, n);
            }
        }
        best.map(|(_, colour, n)| (colour, n))
    }
}

/// What `shown` holds as `camera` sees it.
pub fn render(shown: &Shown<'_>, camera: &Camera) -> Picture {
    let n = camera.size_px.max(1);
    let to = camera.look_at_m - camera.eye_m;
    let forward = to.normalize();
    let right = forward.cross(&camera.top).normalize();
    let up = right.cross(&forward);
    let half = camera.half_width_m / to.norm();
    let mut rgb = Vec::with_capacity(3 * (n * n) as usize);
    for row in 0..n {
        let v = (1.0 - 2.0 * (f64::from(row) + 0.5) / f64::from(n)) * half;
        for col in 0..n {
            let u = (2.0 * (f64::from(col) + 0.5) / f64::from(n) - 1.0) * half;
            let d = (forward + right * u + up * v).normalize();
            let pixel = match shown.hit(&camera.eye_m, &d) {
                Some((colour, normal)) => {
                    let light = AMBIENT + (1.0 - AMBIENT) * normal.dot(&d).abs().min(1.0);
                    colour.map(|c| srgb(c * light))
                }
                None => BACKGROUND_RGB.map(srgb),
            };
            rgb.extend(pixel);
        }
    }
    Picture {
        width_px: n,
        height_px: n,
        rgb,
    }
}
