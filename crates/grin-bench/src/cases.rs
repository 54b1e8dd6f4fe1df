//! The reference cases of `grin bench accuracy`: a field, a bundle of rays through it and,
//! where one is known, the exact way each ray leaves.
//!
//! Exact solutions (derivations in docs/accuracy.md):
//! - **Luneburg** (n^2 = 2 - (r/R)^2, ambient 1): a ray parallel to +z at impact parameter
//!   p leaves at the antipode (0, 0, R) of its entry direction, with |d x z| = p / R (angular
//!   momentum), and the optical path inside is pi R / 2 + sqrt(R^2 - p^2) (Fermat: every ray
//!   of the parallel beam has the same optical path to the focus).
//! - **Maxwell fish-eye** (n = n0 / (1 + (r/a)^2), bounds r < a, ambient n0 / 2): rays are
//!   circles through a point r0 and its conjugate -a^2 r0 / |r0|^2; the exit point and
//!   direction are where that circle meets the sphere (the optical path is measured against
//!   the numerical reference).
//! - **GRIN rod** (n^2 = n0^2 (1 - a^2 rho^2), axis z, box bounds): in the t parameter the
//!   transverse motion is harmonic, x(t) = x_e cos(w t) + (T_x / w) sin(w t) with w = n0 a,
//!   and T_z is constant; the exit face, point, direction (Snell at the face) and optical
//!   path (the integral of n^2 dt) are closed forms.
//!
//! The other fields (Gaussian plume, an `expr` formula, fBm noise, and baked grids of the
//! analytic ones) have no closed form: their reference is the Dormand-Prince pair at a
//! tolerance of 1e-14 R in f64 with the bisection exit on the *unbaked* source, so a baked
//! case's error includes what the bake itself lost.
//!
//! Over 600 lines: one concept, the cases and the grids they are baked to (dense and sparse
//! at a matched error).

use std::f64::consts::PI;
use std::path::Path;
use std::sync::Arc;

use anyhow::Context;
use glam::DVec3;
use grin_field::IndexField;
use grin_field::bake::{self, BakeOptions};
use grin_field::baked::{Interp, Storage};
use grin_field::sparse::SparseField;
use grin_field::sparse::bake::{SparseOptions, SparseReport, bake_sparse};
use grin_gpu::GpuGrid;
use grin_scene::MediumSpec;

/// How a ray leaves the medium (what every method is measured on).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Exit {
    pub position: DVec3,
    pub direction: DVec3,
    /// Optical path inside the medium; `None` where the exact solution gives none.
    pub opl: Option<f64>,
}

/// One reference case.
#[derive(Debug, Clone)]
pub struct Case {
    /// Short name used in file names, CSV and charts (`luneburg`, `plume-baked-tricubic-f32`).
    pub name: String,
    /// The field traced.
    pub field: Arc<dyn IndexField>,
    /// The field the reference is computed on (the unbaked source of a baked case).
    pub source: Arc<dyn IndexField>,
    /// Rays (origin, unit direction).
    pub rays: Vec<(DVec3, DVec3)>,
    /// The pilot rays `auto` chooses its method on: [`PILOT_RAYS`] other rays from the
    /// same family (a render's pilots are a coarse grid of its own pixels).
    pub pilots: Vec<(DVec3, DVec3)>,
    /// Exact exits, one per ray, where known.
    pub exact: Option<Vec<Exit>>,
    /// The field is smooth (C2 at least) inside and has no error floor of its own (not
    /// baked): convergence orders are measured on it.
    pub smooth: bool,
    /// The highest convergence order the field itself allows, where it is less than a
    /// method's own: an index that is C^k, its (k+1)-th derivative jumping across surfaces
    /// the rays cross a fixed number of times, gives every step that straddles one a local
    /// error of O(h^(k+1)), so no method converges faster than order k+1 (Perlin noise,
    /// quintic fade: C2, so 3). None: smooth everywhere (C-infinity).
    pub order_limit: Option<u32>,
    /// Length scale errors are divided by (the bounds' radius).
    pub scale: f64,
    /// `field` itself where it is a baked grid (dense or sparse): the GPU column traces it.
    pub grid: Option<GpuGrid>,
    /// The bake's relative error in n (measured by the bake) where `grid` is one.
    pub bake_error: Option<f64>,
}

/// Which cases a run includes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Suite {
    /// A few cases, few rays: CI's smoke test.
    Quick,
    /// Every case.
    Full,
}

/// The field of a `[medium]` table given as TOML text.
pub(crate) fn medium(toml_text: &str) -> anyhow::Result<Arc<dyn IndexField>> {
    let spec: MediumSpec = toml::from_str(toml_text)?;
    Ok(grin_field::build_field(&spec, Path::new("."))?)
}

/// Pilot rays of every case: as many as a render traces by default.
pub const PILOT_RAYS: usize = grin_scene::DEFAULT_PILOT_RAYS as usize;

/// Rays parallel to +z from z = -2R through a disc of impact parameters up to 0.85 R, at
/// several azimuths (3D, not one plane).
fn parallel_beam(count: usize, radius: f64) -> (Vec<(DVec3, DVec3)>, Vec<f64>) {
    let mut rays = Vec::with_capacity(count);
    let mut impacts = Vec::with_capacity(count);
    for i in 0..count {
        let p = radius * (0.05 + 0.8 * (i as f64 + 0.5) / count as f64);
        let phi = 2.399_963 * i as f64; // golden angle
        let o = DVec3::new(p * phi.cos(), p * phi.sin(), -2.0 * radius);
        rays.push((o, DVec3::Z));
        impacts.push(p);
    }
    (rays, impacts)
}

/// The Luneburg lens of radius `r` centred at the origin, with its exact exits.
pub fn luneburg(count: usize) -> anyhow::Result<Case> {
    let r = 1.0;
    let field = medium(
        "bounds = { sphere = { center = [0.0, 0.0, 0.0], radius = 1.0 } }\nfield = { kind = \"luneburg\" }",
    )?;
    let (rays, impacts) = parallel_beam(count, r);
    let pilots = parallel_beam(PILOT_RAYS, r).0;
    let exact = rays
        .iter()
        .zip(&impacts)
        .map(|((o, _), &p)| {
            let e = DVec3::new(o.x, o.y, 0.0) / p;
            let s = p / r;
            Exit {
                position: DVec3::new(0.0, 0.0, r),
                direction: -e * s + DVec3::Z * (1.0 - s * s).sqrt(),
                opl: Some(PI * r / 2.0 + (r * r - p * p).sqrt()),
            }
        })
        .collect();
    Ok(Case {
        name: "luneburg".into(),
        source: field.clone(),
        field,
        rays,
        pilots,
        exact: Some(exact),
        smooth: true,
        order_limit: None,
        scale: r,
        grid: None,
        bake_error: None,
    })
}

/// Maxwell's fish-eye (n0 = 2, a = 1): rays start inside, at points off the centre, in
/// assorted directions; exact exits from the circle through each start and its conjugate.
pub fn fish_eye(count: usize) -> anyhow::Result<Case> {
    let a = 1.0;
    let field = medium(
        "bounds = { sphere = { center = [0.0, 0.0, 0.0], radius = 1.0 } }\nambient_index = 1.0\nfield = { kind = \"maxwell-fish-eye\", n0 = 2.0, a = 1.0 }",
    )?;
    let rays = fish_eye_rays(count);
    let exact = rays
        .iter()
        .map(|&(r0, d0)| fish_eye_exit(r0, d0, a))
        .collect();
    Ok(Case {
        name: "fish-eye".into(),
        source: field.clone(),
        field,
        rays,
        pilots: fish_eye_rays(PILOT_RAYS),
        exact: Some(exact),
        smooth: true,
        order_limit: None,
        scale: a,
        grid: None,
        bake_error: None,
    })
}

/// Fish-eye rays: starts off the centre, directions spread over a cone around +y
/// (never radial).
fn fish_eye_rays(count: usize) -> Vec<(DVec3, DVec3)> {
    (0..count)
        .map(|i| {
            let f = (i as f64 + 0.5) / count as f64;
            let phi = 2.399_963 * i as f64;
            let r0 = DVec3::new(0.2 + 0.4 * f, 0.15 * phi.sin(), 0.1 * phi.cos());
            let d0 = DVec3::new(0.3 * phi.cos(), 1.0, 0.4 * phi.sin()).normalize();
            (r0, d0)
        })
        .collect()
}

/// Where the fish-eye ray from `r0` (|r0| < a) along unit `d0` leaves the sphere r = a.
pub fn fish_eye_exit(r0: DVec3, d0: DVec3, a: f64) -> Exit {
    let conj = -r0 * (a * a / r0.length_squared());
    // Unit normal to d0 in the plane of r0 and d0 (that plane holds the conjugate point).
    let m = (r0 - d0 * r0.dot(d0)).normalize();
    let q = r0 - conj;
    // Centre c = r0 + rho m with |c - conj| = |rho|.
    let rho = -q.length_squared() / (2.0 * m.dot(q));
    let c = r0 + m * rho;
    let radius = rho.abs();
    // Orthonormal in-plane frame at the centre: u towards r0, v along the travel at r0.
    let u = (r0 - c) / radius;
    let v = d0;
    // Points c + radius (cos s u + sin s v): first s > 0 where |x| = a.
    // |x|^2 = |c|^2 + radius^2 + 2 radius (cos s (c.u) + sin s (c.v)) = a^2.
    let (cu, cv) = (c.dot(u), c.dot(v));
    let k = (a * a - c.length_squared() - radius * radius) / (2.0 * radius);
    let amp = (cu * cu + cv * cv).sqrt();
    let base = cv.atan2(cu);
    let delta = (k / amp).clamp(-1.0, 1.0).acos();
    let wrap = |s: f64| {
        let t = s.rem_euclid(2.0 * PI);
        if t < 1e-12 { t + 2.0 * PI } else { t }
    };
    let s = wrap(base + delta).min(wrap(base - delta));
    let position = c + (u * s.cos() + v * s.sin()) * radius;
    let direction = (-u * s.sin() + v * s.cos()).normalize();
    Exit {
        position,
        direction,
        opl: None,
    }
}

/// A GRIN rod (n0 = 1.5, a = 0.8, axis z) in the box [-0.5, 0.5]^2 x [-1, 1] in air, rays
/// entering the z = -1 face slightly tilted; all of them leave through z = +1.
pub fn grin_rod(count: usize) -> anyhow::Result<Case> {
    let (n0, a) = (1.5, 0.8);
    let field = medium(
        "bounds = { box = { min = [-0.5, -0.5, -1.0], max = [0.5, 0.5, 1.0] } }\nfield = { kind = \"grin-rod\", n0 = 1.5, a = 0.8, axis = \"z\" }",
    )?;
    let entries = rod_entries(count);
    let rays = entries
        .iter()
        .map(|&(e, d)| (e - d * (0.5 / d.z), d))
        .collect();
    let exact = entries
        .iter()
        .map(|&(e, d)| rod_exit(e, d, n0, a, 1.0))
        .collect();
    Ok(Case {
        name: "grin-rod".into(),
        source: field.clone(),
        field,
        rays,
        pilots: rod_entries(PILOT_RAYS)
            .into_iter()
            .map(|(e, d)| (e - d * (0.5 / d.z), d))
            .collect(),
        exact: Some(exact),
        smooth: true,
        order_limit: None,
        scale: DVec3::new(0.5, 0.5, 1.0).length(),
        grid: None,
        bake_error: None,
    })
}

/// Where the rod's rays enter the z = -1 face and their directions (slightly tilted).
fn rod_entries(count: usize) -> Vec<(DVec3, DVec3)> {
    (0..count)
        .map(|i| {
            let f = (i as f64 + 0.5) / count as f64;
            let phi = 2.399_963 * i as f64;
            let e = DVec3::new(0.25 * f * phi.cos(), 0.25 * f * phi.sin(), -1.0);
            let d = DVec3::new(0.1 * phi.sin(), -0.08 * phi.cos(), 1.0).normalize();
            (e, d)
        })
        .collect()
}

/// The rod ray entering at `e` (on z = -z_half) along unit `d` from air: exact exit
/// through z = +z_half (the caller keeps the transverse amplitude inside the box).
pub fn rod_exit(e: DVec3, d: DVec3, n0: f64, a: f64, z_half: f64) -> Exit {
    let w = n0 * a;
    let n2 = |x: f64, y: f64| n0 * n0 * (1.0 - a * a * (x * x + y * y));
    // Snell at the entry face: T's tangential part is the incoming one (ambient 1).
    let (tx, ty) = (d.x, d.y);
    let tz = (n2(e.x, e.y) - tx * tx - ty * ty).sqrt();
    let t_end = 2.0 * z_half / tz;
    let (c, s) = ((w * t_end).cos(), (w * t_end).sin());
    let x = e.x * c + tx / w * s;
    let y = e.y * c + ty / w * s;
    let vx = -e.x * w * s + tx * c;
    let vy = -e.y * w * s + ty * c;
    // integral of x^2 over [0, t] for x = A cos wt + B sin wt.
    let sq = |aa: f64, bb: f64| {
        aa * aa * (t_end / 2.0 + (2.0 * w * t_end).sin() / (4.0 * w))
            + bb * bb * (t_end / 2.0 - (2.0 * w * t_end).sin() / (4.0 * w))
            + aa * bb * s * s / w
    };
    let rho2 = sq(e.x, tx / w) + sq(e.y, ty / w);
    let opl = n0 * n0 * (t_end - a * a * rho2);
    let out_z = (1.0 - vx * vx - vy * vy).sqrt();
    Exit {
        position: DVec3::new(x, y, z_half),
        direction: DVec3::new(vx, vy, out_z),
        opl: Some(opl),
    }
}

/// Rays across a box along +z, on a grid of (x, y) offsets.
fn box_rays(count: usize, lo: DVec3, hi: DVec3) -> Vec<(DVec3, DVec3)> {
    let side = (count as f64).sqrt().ceil() as usize;
    let mut rays = Vec::with_capacity(count);
    for i in 0..count {
        let (ix, iy) = (i % side, i / side);
        let fx = (ix as f64 + 0.5) / side as f64;
        let fy = (iy as f64 + 0.5) / side as f64;
        let x = lo.x + (hi.x - lo.x) * (0.1 + 0.8 * fx);
        let y = lo.y + (hi.y - lo.y) * (0.1 + 0.8 * fy);
        let d = DVec3::new(0.05 * (fy - 0.5), 0.05 * (fx - 0.5), 1.0).normalize();
        rays.push((DVec3::new(x, y, lo.z - 0.5), d));
    }
    rays
}

fn numeric_case(
    name: &str,
    field: Arc<dyn IndexField>,
    rays: Vec<(DVec3, DVec3)>,
    pilots: Vec<(DVec3, DVec3)>,
) -> Case {
    let scale = field.bounds().radius();
    Case {
        name: name.into(),
        source: field.clone(),
        field,
        rays,
        pilots,
        exact: None,
        smooth: true,
        order_limit: None,
        scale,
        grid: None,
        bake_error: None,
    }
}

/// Hot air: two Gaussian plumes (delta_n 6e-3 and 4e-3, widths 0.25 and 0.15) in a box.
pub fn plume(count: usize) -> anyhow::Result<Case> {
    let field = medium(
        "bounds = { box = { min = [-1.0, -1.0, -1.0], max = [1.0, 1.0, 1.0] } }\nambient_index = 1.000293\nfield = { kind = \"plume\", plumes = [ { a = 6.0e-3, center = [0.0, 0.0, 0.0], s = 0.25 }, { a = 4.0e-3, center = [0.3, -0.2, 0.4], s = 0.15 } ] }",
    )?;
    let (lo, hi) = (DVec3::splat(-0.6), DVec3::splat(0.6));
    let (rays, pilots) = (box_rays(count, lo, hi), box_rays(PILOT_RAYS, lo, hi));
    Ok(numeric_case("plume", field, rays, pilots))
}

/// A user formula: a ring of warm air whose strength varies along z.
pub fn expr(count: usize) -> anyhow::Result<Case> {
    let field = medium(
        "bounds = { box = { min = [-1.0, -1.0, -1.0], max = [1.0, 1.0, 1.0] } }\nambient_index = 1.0003\nfield = { kind = \"expr\", n = \"1.0003 - 5e-3*exp(-((x*x+y*y-0.12)^2)/0.005)*(1+0.5*sin(3*z))\" }",
    )?;
    let (lo, hi) = (DVec3::splat(-0.7), DVec3::splat(0.7));
    let (rays, pilots) = (box_rays(count, lo, hi), box_rays(PILOT_RAYS, lo, hi));
    Ok(numeric_case("expr", field, rays, pilots))
}

/// fBm noise (3 octaves, delta_n up to 2e-3) in a ball.
pub fn noise(count: usize) -> anyhow::Result<Case> {
    let field = medium(
        "bounds = { sphere = { center = [0.0, 0.0, 0.0], radius = 1.0 } }\nambient_index = 1.0003\nfield = { kind = \"noise\", noise = \"fbm\", octaves = 3, frequency = 2.0, amplitude = 2e-3, seed = 7 }",
    )?;
    let (rays, _) = parallel_beam(count, 1.0);
    let pilots = parallel_beam(PILOT_RAYS, 1.0).0;
    let mut case = numeric_case("noise", field, rays, pilots);
    // Improved Perlin noise interpolates with the quintic fade 6t^5 - 15t^4 + 10t^3: the
    // index is C2 and its third derivative jumps at every lattice plane (and at the
    // taper's edge, a C2 quintic smoothstep too).
    case.order_limit = Some(3);
    Ok(case)
}

/// The plume case's index sampled onto an OpenVDB grid (voxels of 0.04, delta_n / 1e-3
/// stored, written by grin's own writer to a temporary file) and read back through the
/// VDB pipeline (`kind = "vdb"`, linear map): what a simulation cache gives. The
/// reference is traced on the VDB field itself (its interpolant between voxels), so the
/// methods are measured, not the sampling; not smooth for orders (C1 between voxels).
pub fn vdb_plume(count: usize) -> anyhow::Result<Case> {
    let analytic = plume(count)?;
    let (h, half, k) = (0.04, 25, 1e-3);
    let ambient = analytic.source.ambient_index();
    let side = (2 * half + 1) as usize;
    let mut values = Vec::with_capacity(side * side * side);
    for kk in -half..=half {
        for j in -half..=half {
            for i in -half..=half {
                let p = DVec3::new(f64::from(i), f64::from(j), f64::from(kk)) * h;
                values.push(((analytic.source.sample(p).n - ambient) / k) as f32);
            }
        }
    }
    let grid = vdb_sys::DenseGrid {
        bbox: vdb_sys::IndexBox {
            min: [-half; 3],
            max: [half; 3],
        },
        world_from_index: vdb_sys::Transform::uniform(h, [0.0; 3]),
        values,
    };
    let dir = std::env::temp_dir().join(format!("grin-bench-vdb-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let path = dir.join("plume.vdb");
    let mut writer = vdb_sys::VdbWriter::new()?;
    writer.add_float("dn", &grid, &vdb_sys::WriteOptions::default())?;
    writer.write(&path)?;
    let field = medium(&format!(
        "bounds = {{ box = {{ min = [-0.98, -0.98, -0.98], max = [0.98, 0.98, 0.98] }} }}\n\
         ambient_index = {ambient}\n\
         field = {{ kind = \"vdb\", path = \"{}\", grid = \"dn\", map = {{ linear = {{ k = {k} }} }} }}",
        path.display()
    ));
    // The field holds the grid in memory: the file is no longer needed.
    std::fs::remove_dir_all(&dir).ok();
    let mut case = numeric_case("vdb-plume", field?, analytic.rays, analytic.pilots);
    case.smooth = false;
    Ok(case)
}

/// `base` baked at `resolution` nodes with `interp` and `storage`; the reference stays
/// the unbaked source's (exact where known).
pub fn baked(
    base: &Case,
    resolution: usize,
    interp: Interp,
    storage: Storage,
) -> anyhow::Result<Case> {
    Ok(baked_with_error(base, resolution, interp, storage)?.0)
}

/// [`baked`], and the bake's measured relative error.
fn baked_with_error(
    base: &Case,
    resolution: usize,
    interp: Interp,
    storage: Storage,
) -> anyhow::Result<(Case, f64)> {
    let opts = BakeOptions {
        resolution: Some(resolution),
        interp,
        storage: Some(storage),
        error_points: 2000,
        ..BakeOptions::default()
    };
    let (field, report) = bake::bake(base.source.as_ref(), &opts, &|_, _, _| {})?;
    let (interp_name, storage_name) = (interp.name(), storage.name());
    let name = format!(
        "{}-baked{resolution}-{interp_name}-{storage_name}",
        base.name
    );
    let grid = GpuGrid::from(Arc::new(field));
    let error = report.relative_error;
    Ok((grid_case(base, name, grid, error), error))
}

/// `base` baked sparsely (`grin bake --sparse`, `interp`: trilinear or Catmull-Rom) at
/// relative error `error`: what a dense bake's rows are compared with at the same error.
/// The reference stays the source's.
pub fn sparse(base: &Case, error: f64, interp: Interp) -> anyhow::Result<Case> {
    let (field, report) = sparse_at(base.source.as_ref(), error, interp, &base.name)?;
    let kind = match interp {
        Interp::Trilinear => "",
        Interp::Tricubic => "catmull-rom-",
    };
    let name = format!("{}-sparse-{kind}{}", base.name, report.storage.name());
    let grid = GpuGrid::from(Arc::new(field));
    Ok(grid_case(base, name, grid, report.relative_error))
}

/// `source` (named `name` in an error) baked sparsely at relative error `error`, with the
/// default options: what the benches hold against a dense grid of that error.
pub fn sparse_at(
    source: &dyn IndexField,
    error: f64,
    interp: Interp,
    name: &str,
) -> anyhow::Result<(SparseField, SparseReport)> {
    let opts = SparseOptions {
        error_budget: error,
        interp,
        ..SparseOptions::default()
    };
    bake_sparse(source, &opts, &|_, _, _| {})
        .with_context(|| format!("{name}: sparse bake at relative error {error:.2e}"))
}

/// "The same error" for a sparse bake held against a dense one: measured relative errors
/// within 1% of each other. Both are maxima over random points (20,000 for a sparse bake,
/// the dense bake's own set), not exact values: a sparse bake at the dense grid's own
/// spacing measures 1.8614e-4 on paper (a) where the dense grid measures 1.8602e-4.
pub const SAME_ERROR: f64 = 1.01;

/// Sparse bakes [`sparse_matching`] makes at most after the first.
const MATCH_BAKES: usize = 6;

/// The coarsest sparse bake of `source` (named `name` in an error) whose measured relative
/// error is at most `error` ([`SAME_ERROR`]): what "the same error" means for a sparse bake
/// held against a dense grid of measured error `error`. A sparse bake asked for a budget
/// lands below it (each brick meets 0.8 of it, judged by its nodes' curvature too, on a
/// ladder of levels 1.25x apart), so where the first measures under 0.9 of `error`, larger
/// budgets are tried: raised by the ratio it missed by (at most 2x), doubled while they
/// still measure within `error`, then bisected (geometrically) between the largest that
/// did and the smallest that did not. The bake with the fewest bytes within `error` is
/// kept, else the first.
pub fn sparse_matching(
    source: &dyn IndexField,
    error: f64,
    interp: Interp,
    name: &str,
) -> anyhow::Result<(SparseField, SparseReport)> {
    let limit = error * SAME_ERROR;
    let first = sparse_at(source, error, interp, name)?;
    let measured = first.1.relative_error;
    if measured >= 0.9 * error || measured <= 0.0 {
        return Ok(first);
    }
    let mut best = first;
    // Budgets known to measure within the limit (`within`) and over it (`over`).
    let (mut within, mut over) = (error, None::<f64>);
    let mut budget = error * (error / measured).min(2.0);
    for _ in 0..MATCH_BAKES {
        let next = sparse_at(source, budget, interp, name)?;
        if next.1.relative_error <= limit {
            within = budget;
            if next.1.memory_bytes < best.1.memory_bytes {
                best = next;
            }
        } else {
            over = Some(budget);
        }
        budget = match over {
            Some(o) if o / within < 1.05 => break,
            Some(o) => (within * o).sqrt(),
            None => within * 2.0,
        };
    }
    Ok(best)
}

/// A case tracing `grid` (baked from `base`'s source to relative error `error`) with
/// `base`'s rays and reference.
fn grid_case(base: &Case, name: String, grid: GpuGrid, error: f64) -> Case {
    Case {
        name,
        field: grid.field(),
        grid: Some(grid),
        bake_error: Some(error),
        source: base.source.clone(),
        rays: base.rays.clone(),
        pilots: base.pilots.clone(),
        exact: base.exact.clone(),
        // The bake's own error is a floor under every method: no order is measured on it.
        smooth: false,
        order_limit: base.order_limit,
        scale: base.scale,
    }
}

/// The cases `want` names (`grin bench accuracy --case`): the case of that whole name
/// alone (`plume`, not `vdb-plume` and the baked plumes too), else every case whose name
/// contains it (`baked`); an error naming the suite's cases where none does.
pub fn select(mut cases: Vec<Case>, want: &str) -> anyhow::Result<Vec<Case>> {
    let names: Vec<String> = cases.iter().map(|c| c.name.to_string()).collect();
    if cases.iter().any(|c| c.name == want) {
        cases.retain(|c| c.name == want);
    } else {
        cases.retain(|c| c.name.contains(want));
    }
    anyhow::ensure!(
        !cases.is_empty(),
        "--case {want}: no case of this suite matches (cases: {})",
        names.join(", ")
    );
    Ok(cases)
}

/// The cases of a suite.
pub fn suite(suite: Suite) -> anyhow::Result<Vec<Case>> {
    Ok(match suite {
        Suite::Quick => {
            let l = luneburg(12)?;
            let p = plume(9)?;
            let lb = baked(&l, 32, Interp::Tricubic, Storage::F32)?;
            let (pb, error) = baked_with_error(&p, 32, Interp::Trilinear, Storage::F32)?;
            let ps = sparse(&p, error, Interp::Trilinear)?;
            vec![l, p, lb, pb, ps]
        }
        Suite::Full => {
            let l = luneburg(48)?;
            let p = plume(36)?;
            let (fish, rod) = (fish_eye(32)?, grin_rod(32)?);
            let (e, n, vdb) = (expr(36)?, noise(32)?, vdb_plume(36)?);
            let mut v = vec![
                l.clone(),
                fish.clone(),
                rod.clone(),
                p.clone(),
                e.clone(),
                n.clone(),
                vdb.clone(),
            ];
            let others = [fish, rod, e, n, vdb];
            // Every reference field baked: the lens and the plume with every
            // interpolation and storage, the others with the two ends of it (the most
            // accurate grid, tricubic f32, and the most compact, trilinear i16).
            for base in [&l, &p] {
                for (interp, storage) in [
                    (Interp::Trilinear, Storage::I16),
                    (Interp::Trilinear, Storage::F32),
                    (Interp::Tricubic, Storage::F32),
                    (Interp::Tricubic, Storage::I16),
                ] {
                    v.push(baked(base, 64, interp, storage)?);
                }
            }
            for base in &others {
                for (interp, storage) in [
                    (Interp::Trilinear, Storage::I16),
                    (Interp::Tricubic, Storage::F32),
                ] {
                    v.push(baked(base, 64, interp, storage)?);
                }
            }
            // Every reference field baked sparsely, trilinear and Catmull-Rom, at the error
            // its 64-node trilinear i16 grid has: the rows to hold against that grid's
            // (`--case -i16` runs all three).
            for base in [&l, &p].into_iter().chain(&others) {
                let (_, error) = baked_with_error(base, 64, Interp::Trilinear, Storage::I16)?;
                for interp in [Interp::Trilinear, Interp::Tricubic] {
                    v.push(sparse(base, error, interp)?);
                }
            }
            v
        }
    })
}

#[cfg(test)]
mod tests;
