//! Baking: sample any [`IndexField`] into a [`BakedField`], choosing the coarsest
//! resolution and cheapest storage that meet an error budget, cropped to where the field
//! differs from ambient, under a memory cap; and measuring the error on random points.
//!
//! Error budget (the default, [`DEFAULT_ERROR_BUDGET`]): the max |n_baked - n_source| over
//! random points inside the medium, relative to the field's delta_n range
//! max |n - n_ambient| over the grid.
//!
//! One concept, one file: resolution search, crop and error measurement are one policy.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use crate::baked::{BakeProvenance, BakedField, GridGeometry, Interp, Outside, Storage, Voxels};
use crate::bounds::Bounds;
use crate::field::{FieldError, IndexField};

/// Default error budget: 0.1 % of the delta_n range (max error, random points).
pub const DEFAULT_ERROR_BUDGET: f64 = 1e-3;
/// Default memory cap for the baked grid (voxels plus spline coefficients): 1 GiB.
pub const DEFAULT_MAX_MEMORY: u64 = 1 << 30;
/// The fixed resolution people would otherwise use (nodes along the longest axis).
pub const DEFAULT_RESOLUTION: usize = 128;
/// Resolutions tried by the automatic search, coarse to fine (nodes along the longest axis).
pub const CANDIDATE_RESOLUTIONS: [usize; 12] =
    [12, 16, 24, 32, 48, 64, 96, 128, 192, 256, 384, 512];
/// Extra nodes beyond the crop on every side for trilinear sampling, so the Runge-Kutta
/// stages just outside the medium read real data.
pub const GRID_MARGIN_TRILINEAR: usize = 2;
/// The same for the tricubic spline: its mirror boundary condition is only 2nd order, and
/// the prefilter carries that error inwards as 0.27^k per node, so 6 nodes keep it
/// (0.27^6 ~ 4e-4 of an O(h^2) term) below the spline's 4th-order error inside the medium.
pub const GRID_MARGIN_TRICUBIC: usize = 6;
/// The automatic search accepts a resolution when its sampled error is within this
/// fraction of the budget, so an independent set of random points still meets it.
pub const BUDGET_SAFETY: f64 = 0.8;
/// Share of the error points drawn inside the grid's box (where the field varies); the
/// rest are uniform over the medium.
const ERROR_POINTS_IN_GRID: f64 = 0.75;
/// Central-difference step for sources without an exact gradient, in voxels.
pub const CD_STEP_VOXELS: f64 = 0.25;
/// Probe points per axis used to find the active region.
pub const CROP_PROBE_POINTS: usize = 48;
/// The crop keeps nodes with |delta_n| above this fraction of (budget * delta_n range), so
/// what it drops costs at most a tenth of the budget.
pub const CROP_FRACTION_OF_BUDGET: f64 = 0.1;
/// i16 storage is chosen when its rounding error (half a step) is at most this fraction of
/// the budget.
pub const QUANT_FRACTION_OF_BUDGET: f64 = 0.1;
/// Random points inside the medium used to measure the error.
pub const DEFAULT_ERROR_POINTS: usize = 20_000;
/// Bytes per voxel of the tricubic spline coefficients kept beside the voxels.
const COEFF_BYTES_PER_VOXEL: u64 = 16;

/// Where the gradient stored at each node comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GradientMode {
    /// The source's own `grad_n` (analytic, expression and noise fields).
    Exact,
    /// Central differences of the source's n at [`CD_STEP_VOXELS`] of a voxel (VDB grids,
    /// whose own gradient is only that of their interpolation).
    CentralDifference,
}

impl GradientMode {
    /// The mode for a scene's field: VDB grids have no exact gradient, so their source is
    /// differenced at sub-voxel spacing; every other kind gives its own.
    pub fn for_field(spec: &grin_scene::FieldSpec) -> Self {
        match spec {
            grin_scene::FieldSpec::Vdb(_) => GradientMode::CentralDifference,
            _ => GradientMode::Exact,
        }
    }
}

/// What to bake and how.
#[derive(Debug, Clone)]
pub struct BakeOptions {
    /// Nodes along the crop's longest axis; `None` chooses it from the error budget.
    pub resolution: Option<usize>,
    /// Relative error budget (see the module docs).
    pub error_budget: f64,
    /// Memory cap in bytes for the baked grid in memory.
    pub max_memory: u64,
    /// Interpolation the field is sampled (and its error measured) with.
    pub interp: Interp,
    /// Storage; `None` picks i16 when its rounding fits the budget.
    pub storage: Option<Storage>,
    /// Crop to the region where |n - ambient| is above the threshold.
    pub crop: bool,
    /// For a source with its own spacing (a VDB grid) whose grid at that spacing misses
    /// the budget: go on with tricubic grids at it, 2x and 4x finer (memory cap allowing)
    /// before reporting `source_limited`.
    pub cubic_past_source: bool,
    pub gradient: GradientMode,
    pub error_points: usize,
    /// Seed of the random error points.
    pub seed: u64,
}

impl Default for BakeOptions {
    fn default() -> Self {
        BakeOptions {
            resolution: None,
            error_budget: DEFAULT_ERROR_BUDGET,
            max_memory: DEFAULT_MAX_MEMORY,
            interp: Interp::Trilinear,
            storage: None,
            crop: true,
            cubic_past_source: true,
            gradient: GradientMode::Exact,
            error_points: DEFAULT_ERROR_POINTS,
            seed: 1,
        }
    }
}

/// Why a bake failed.
#[derive(Debug, thiserror::Error)]
pub enum BakeError {
    #[error(
        "a {nx}x{ny}x{nz} grid needs {need} bytes, over the memory cap of {cap} bytes (raise --max-memory or lower --resolution)"
    )]
    MemoryCap {
        nx: usize,
        ny: usize,
        nz: usize,
        need: u64,
        cap: u64,
    },
    #[error(
        "cannot meet the error budget {budget:e} under the memory cap of {cap} bytes: the finest grid that fits ({resolution} nodes) has relative error {best:e} (raise --max-memory or --error)"
    )]
    BudgetNotMet {
        budget: f64,
        cap: u64,
        resolution: usize,
        best: f64,
    },
    #[error(
        "a sparse bake needs more than the memory cap of {cap} bytes ({need} bytes{}; raise --max-memory or --error)", sparse_progress(*done, *active)
    )]
    SparseMemory {
        need: u64,
        cap: u64,
        done: usize,
        active: usize,
    },
    #[error(
        "cannot meet the error budget {budget:e} with bricks down to a spacing of {spacing}: the sparse bake's relative error is {best:e} ({limited} bricks at their finest level; raise --error or --bricks)"
    )]
    SparseBudgetNotMet {
        budget: f64,
        best: f64,
        spacing: f64,
        limited: usize,
    },
    #[error("invalid bake option: {0}")]
    Option(String),
    #[error(transparent)]
    Memory(#[from] crate::alloc::AllocError),
    #[error("source field `{field}`: n = {n} at ({x}, {y}, {z}) is not finite")]
    NonFinite {
        field: String,
        n: f64,
        x: f64,
        y: f64,
        z: f64,
    },
    #[error(transparent)]
    Field(#[from] FieldError),
}

/// Error of a baked field against its source on random points inside the medium.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ErrorStats {
    pub max_err_n: f64,
    pub rms_err_n: f64,
    pub max_err_grad: f64,
    pub rms_err_grad: f64,
    pub points: usize,
    /// The largest |n - ambient| of the source at the points: with the nodes' own, the
    /// scale the error budget is relative to (a feature narrower than the nodes' spacing
    /// shows here, not at the nodes).
    pub max_source_delta_n: f64,
}

/// One resolution the automatic search tried.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trial {
    pub resolution: usize,
    pub dims: [usize; 3],
    pub storage: Storage,
    pub interp: Interp,
    pub relative_error: f64,
}

/// What a bake chose and measured.
#[derive(Debug, Clone)]
pub struct BakeReport {
    pub resolution: usize,
    pub dims: [usize; 3],
    /// World box of the grid nodes.
    pub grid_min: DVec3,
    pub grid_max: DVec3,
    pub cropped: bool,
    pub storage: Storage,
    pub interp: Interp,
    /// Bytes of voxel data (what the file stores).
    pub bytes: u64,
    pub errors: ErrorStats,
    /// max |n - ambient| over the grid nodes.
    pub delta_n_range: f64,
    /// errors.max_err_n / delta_n_range.
    pub relative_error: f64,
    pub budget: f64,
    pub meets_budget: bool,
    /// The automatic search reached the source's own spacing (a VDB's voxel size) and,
    /// past it, the finest tricubic grid it may try, without meeting the budget: the
    /// error left is the baked interpolation against the source's (Catmull-Rom) one
    /// between the same data, not missing data. The bake is kept (the most accurate one
    /// tried); a larger memory cap or a fixed `--resolution` reduce it.
    pub source_limited: bool,
    /// The automatic search stopped at a grid over the memory cap (else it ran out of
    /// candidates, or met the budget).
    pub memory_capped: bool,
    pub trials: Vec<Trial>,
    pub seconds: f64,
    /// Source evaluations spent on grid nodes (all trials).
    pub source_evals: u64,
    /// Fraction of macro cells that are homogeneous (straight flights).
    pub homogeneous_cells: f64,
}

/// Progress callback: (stage, done, total).
pub type Progress<'a> = &'a (dyn Fn(&str, u64, u64) + Sync);

/// A bake's error in n relative to the range of delta_n seen: infinite where an error
/// was measured over no range (a feature between the nodes; not met), 0 where neither.
pub(crate) fn relative_error(max_err_n: f64, range: f64) -> f64 {
    if range > 0.0 {
        max_err_n / range
    } else if max_err_n > 0.0 {
        f64::INFINITY
    } else {
        0.0
    }
}

/// The options both bakes share, dense and sparse: a positive error budget, at least one
/// error point.
pub(crate) fn check_budget_and_points(budget: f64, points: usize) -> Result<(), BakeError> {
    if !(budget.is_finite() && budget > 0.0) {
        return Err(BakeError::Option(format!(
            "error budget {budget} must be positive"
        )));
    }
    if points == 0 {
        return Err(BakeError::Option("error_points must be at least 1".into()));
    }
    Ok(())
}

/// Where a sparse bake stood when it passed its memory cap: after how many of its active
/// bricks (nothing when the brick table alone is over it).
fn sparse_progress(done: usize, active: usize) -> String {
    if active == 0 {
        " for the brick table alone".into()
    } else {
        format!(" after {done} of {active} active bricks")
    }
}

/// Bake `source` per `opts`.
pub fn bake(
    source: &dyn IndexField,
    opts: &BakeOptions,
    progress: Progress<'_>,
) -> Result<(BakedField, BakeReport), BakeError> {
    let start = Instant::now();
    check_budget_and_points(opts.error_budget, opts.error_points)?;
    if let Some(n) = opts.resolution
        && n < 2
    {
        return Err(BakeError::Option(format!(
            "resolution {n} must be at least 2"
        )));
    }
    let bounds = source.bounds();
    let ambient = source.ambient_index();
    let (crop_lo, crop_hi, cropped) = active_region(source, opts);
    let evals = AtomicU64::new(0);

    let mut trials = Vec::new();
    let mut candidates: Vec<(usize, Interp)> = match opts.resolution {
        Some(n) => vec![(n, opts.interp)],
        None => candidate_resolutions(crop_hi - crop_lo, source.source_spacing())
            .into_iter()
            .map(|r| (r, opts.interp))
            .collect(),
    };
    // The finest candidate when it is the source's own spacing: past it a grid resolves
    // the source's interpolation between the same data, so the search goes on there
    // only with `cubic_past_source` (tricubic, 2x and 4x finer, within the memory cap).
    let source_resolution = match (opts.resolution, source.source_spacing()) {
        (None, Some(_)) => candidates.last().map(|c| c.0),
        _ => None,
    };
    if let Some(r) = source_resolution
        && opts.cubic_past_source
    {
        let at_source = (opts.interp == Interp::Trilinear).then_some((r, Interp::Tricubic));
        candidates.extend(at_source);
        candidates.extend([2, 4].map(|f| (f * (r - 1) + 1, Interp::Tricubic)));
    }
    let mut best: Option<(BakedField, ErrorStats, f64, f64, usize)> = None;
    let mut memory_capped = false;
    for (ci, &(res, interp)) in candidates.iter().enumerate() {
        let geometry = grid_geometry(crop_lo, crop_hi, res, grid_margin(interp));
        let storage_guess = opts.storage.unwrap_or(Storage::I16);
        let need = memory_bytes(&geometry, storage_guess, interp);
        if need > opts.max_memory {
            if opts.resolution.is_some() || trials.is_empty() {
                let [nx, ny, nz] = geometry.dims;
                return Err(BakeError::MemoryCap {
                    nx,
                    ny,
                    nz,
                    need,
                    cap: opts.max_memory,
                });
            }
            memory_capped = true;
            break;
        }
        let stage = format!(
            "bake {}x{}x{}",
            geometry.dims[0], geometry.dims[1], geometry.dims[2]
        );
        let shell = grid_margin(interp) as f64 * geometry.spacing.max_element();
        let raw = sample_grid(
            source,
            &geometry,
            opts.gradient,
            shell,
            &evals,
            &stage,
            progress,
        )?;
        let range = delta_n_range_inside(&raw, &geometry, bounds);
        let storage = opts
            .storage
            .unwrap_or_else(|| choose_storage(range, opts.error_budget));
        let need = memory_bytes(&geometry, storage, interp);
        if need > opts.max_memory {
            if opts.resolution.is_some() || trials.is_empty() {
                let [nx, ny, nz] = geometry.dims;
                return Err(BakeError::MemoryCap {
                    nx,
                    ny,
                    nz,
                    need,
                    cap: opts.max_memory,
                });
            }
            memory_capped = true;
            break;
        }
        let voxels = match storage {
            Storage::F32 => Voxels::F32(raw),
            Storage::I16 => Voxels::quantize(&raw),
        };
        let outside = if cropped {
            Outside::Ambient
        } else {
            Outside::Clamp
        };
        let field = BakedField::new(
            geometry,
            voxels,
            interp,
            outside,
            bounds,
            ambient,
            BakeProvenance {
                source: source.describe(),
                ..Default::default()
            },
        )?;
        progress("measure error", 0, 1);
        let mut points = error_points(bounds, crop_lo, crop_hi, opts.error_points, opts.seed);
        // The field's finest features too: random points miss a narrow one.
        points.extend(source.feature_points());
        // And where the grid varies, when that is a small part of it: eight plumes of a
        // 1000-unit cube are 0.3% of it, and 20 000 points over the cube (it is the crop)
        // met a 135^3 grid that steps over them as within the budget.
        points.extend(varying_points(&field, opts.error_points / 2, opts.seed));
        let errors = measure_error_at(source, &field, opts.gradient, &points);
        progress("measure error", 1, 1);
        // A feature between the nodes (a plume narrower than their spacing) leaves them
        // at the ambient: the range is what the nodes or the error points saw, and an
        // error with no range seen is not met (a 16^3 bake of a 933^3-voxel cache's eight
        // small plumes reported a range of 0 and "met" with an error of 1.3e-4).
        let range = range.max(errors.max_source_delta_n);
        let rel = relative_error(errors.max_err_n, range);
        trials.push(Trial {
            resolution: res,
            dims: geometry.dims,
            storage,
            interp,
            relative_error: rel,
        });
        let met = rel <= opts.error_budget * BUDGET_SAFETY;
        if best.as_ref().is_none_or(|b| rel <= b.3) {
            best = Some((field, errors, range, rel, res));
        }
        if met || ci + 1 == candidates.len() || opts.resolution.is_some() {
            break;
        }
    }
    let Some((mut field, errors, range, rel, res)) = best else {
        return Err(BakeError::Option("no resolution was tried".into()));
    };
    let source_limited = source_resolution.is_some_and(|r| res >= r) && rel > opts.error_budget;
    if opts.resolution.is_none() && rel > opts.error_budget && !source_limited {
        return Err(BakeError::BudgetNotMet {
            budget: opts.error_budget,
            cap: opts.max_memory,
            resolution: res,
            best: rel,
        });
    }
    field.set_provenance(BakeProvenance {
        source: source.describe(),
        max_err_n: errors.max_err_n,
        rms_err_n: errors.rms_err_n,
        max_err_grad: errors.max_err_grad,
        rms_err_grad: errors.rms_err_grad,
    });
    let (grid_min, grid_max) = field.geometry().world_box();
    let report = BakeReport {
        resolution: res,
        dims: field.dims(),
        grid_min,
        grid_max,
        cropped,
        storage: field.storage(),
        interp: field.interp(),
        bytes: field.data_bytes() as u64,
        errors,
        delta_n_range: range,
        relative_error: rel,
        budget: opts.error_budget,
        meets_budget: rel <= opts.error_budget,
        source_limited,
        memory_capped,
        trials,
        seconds: start.elapsed().as_secs_f64(),
        source_evals: evals.load(Ordering::Relaxed),
        homogeneous_cells: field.macro_grid().homogeneous_fraction(),
    };
    Ok((field, report))
}

/// The resolutions the automatic search tries for a crop of size `extent`: the
/// [`CANDIDATE_RESOLUTIONS`], and for a source with its own sample spacing (a VDB grid)
/// only those coarser than it, then the one at that spacing (when within the largest
/// candidate).
pub fn candidate_resolutions(extent: DVec3, source_spacing: Option<f64>) -> Vec<usize> {
    let all = CANDIDATE_RESOLUTIONS.to_vec();
    let Some(h) = source_spacing.filter(|h| *h > 0.0 && h.is_finite()) else {
        return all;
    };
    let longest = extent.max_element();
    let at_source = (longest / h - 1e-9).ceil().max(1.0) as usize + 1;
    let largest = CANDIDATE_RESOLUTIONS[CANDIDATE_RESOLUTIONS.len() - 1];
    if at_source > largest {
        return all;
    }
    let mut out: Vec<usize> = all.into_iter().filter(|&r| r < at_source).collect();
    out.push(at_source.max(2));
    out
}

/// Memory of a baked field in use: voxels, plus spline coefficients for tricubic.
pub fn memory_bytes(geometry: &GridGeometry, storage: Storage, interp: Interp) -> u64 {
    let n = geometry.dims.iter().map(|&d| d as u64).product::<u64>();
    let per = storage.bytes_per_voxel() as u64
        + match interp {
            Interp::Trilinear => 0,
            Interp::Tricubic => COEFF_BYTES_PER_VOXEL,
        };
    n.saturating_mul(per)
}

/// i16 if half a quantization step of the delta_n range fits the budget share.
pub(crate) fn choose_storage(range: f64, budget: f64) -> Storage {
    let half_step = 0.5 / f64::from(i16::MAX);
    if range == 0.0 || half_step <= QUANT_FRACTION_OF_BUDGET * budget {
        Storage::I16
    } else {
        Storage::F32
    }
}

/// Nodes of margin around the crop for `interp`.
pub fn grid_margin(interp: Interp) -> usize {
    match interp {
        Interp::Trilinear => GRID_MARGIN_TRILINEAR,
        Interp::Tricubic => GRID_MARGIN_TRICUBIC,
    }
}

/// The grid for `res` nodes along the longest axis of [lo, hi], with `margin` extra
/// nodes on every side, centred.
pub fn grid_geometry(lo: DVec3, hi: DVec3, res: usize, margin: usize) -> GridGeometry {
    let extent = (hi - lo).max(DVec3::splat(1e-12));
    let h = extent.max_element() / (res.max(2) - 1) as f64;
    let mut dims = [0usize; 3];
    let mut origin = DVec3::ZERO;
    let center = (lo + hi) * 0.5;
    for a in 0..3 {
        let inner = ((extent[a] / h) - 1e-9).ceil().max(1.0) as usize + 1;
        dims[a] = inner + 2 * margin;
        origin[a] = center[a] - h * (dims[a] - 1) as f64 * 0.5;
    }
    GridGeometry {
        dims,
        origin,
        spacing: DVec3::splat(h),
    }
}

/// The box to bake: the bounds' AABB, or (if `opts.crop`) the part where
/// |n - ambient| exceeds the crop threshold, probed on a coarse grid. Returns (lo, hi, cropped).
fn active_region(source: &dyn IndexField, opts: &BakeOptions) -> (DVec3, DVec3, bool) {
    let bounds = source.bounds();
    let (lo, hi) = bounds.aabb();
    if !opts.crop {
        return (lo, hi, false);
    }
    let m = CROP_PROBE_POINTS;
    let ambient = source.ambient_index();
    let step = (hi - lo) / (m - 1) as f64;
    let mut probes: Vec<(DVec3, f64)> = (0..m * m * m)
        .into_par_iter()
        .filter_map(|idx| {
            let (i, j, k) = (idx % m, (idx / m) % m, idx / (m * m));
            let p = lo + step * DVec3::new(i as f64, j as f64, k as f64);
            bounds
                .contains(p)
                .then(|| (p, (source.n(p) - ambient).abs()))
        })
        .collect();
    // Features between the probes (a bump 1/100 of the bounds wide) are where the field
    // says they are.
    probes.extend(
        source
            .feature_points()
            .into_iter()
            .map(|p| (p, (source.n(p) - ambient).abs())),
    );
    let range = probes.iter().fold(
        0.0f64,
        |a, &(_, d)| if d.is_finite() { a.max(d) } else { a },
    );
    let threshold = CROP_FRACTION_OF_BUDGET * opts.error_budget * range;
    let mut a_lo = DVec3::splat(f64::INFINITY);
    let mut a_hi = DVec3::splat(f64::NEG_INFINITY);
    for &(p, d) in &probes {
        if d > threshold {
            a_lo = a_lo.min(p);
            a_hi = a_hi.max(p);
        }
    }
    if range == 0.0 || !a_lo.is_finite() {
        // Uniform field: a minimal grid at the centre.
        let c = bounds.center();
        return (c - step, c + step, true);
    }
    // One probe spacing of slack: the active region may reach between probes.
    let c_lo = (a_lo - step).max(lo);
    let c_hi = (a_hi + step).min(hi);
    let covers = (c_lo - lo).max_element() <= 1e-12 * (hi - lo).max_element()
        && (hi - c_hi).max_element() <= 1e-12 * (hi - lo).max_element();
    if covers {
        (lo, hi, false)
    } else {
        (c_lo, c_hi, true)
    }
}

/// Sample source at every node: [delta_n, grad n] as f32.
fn sample_grid(
    source: &dyn IndexField,
    geometry: &GridGeometry,
    mode: GradientMode,
    shell: f64,
    evals: &AtomicU64,
    stage: &str,
    progress: Progress<'_>,
) -> Result<Vec<[f32; 4]>, BakeError> {
    let [nx, ny, nz] = geometry.dims;
    let ambient = source.ambient_index();
    let bounds = source.bounds();
    let h_cd = CD_STEP_VOXELS * geometry.spacing.min_element();
    let mut data = crate::alloc::try_filled(
        geometry.voxel_count(),
        [0.0f32; 4],
        &format!("a {nx}x{ny}x{nz} baked grid"),
    )?;
    let done = AtomicU64::new(0);
    let total = nz as u64;
    progress(stage, 0, total);
    data.par_chunks_mut(nx * ny).enumerate().try_for_each(
        |(k, slab)| -> Result<(), BakeError> {
            for j in 0..ny {
                for i in 0..nx {
                    let p = geometry.node_world(i, j, k);
                    slab[i + nx * j] = sample_node(source, bounds, ambient, p, mode, h_cd, shell)?;
                }
            }
            let per_node = match mode {
                GradientMode::Exact => 1,
                GradientMode::CentralDifference => 7,
            };
            evals.fetch_add((nx * ny * per_node) as u64, Ordering::Relaxed);
            let d = done.fetch_add(1, Ordering::Relaxed) + 1;
            progress(stage, d, total);
            Ok(())
        },
    )?;
    Ok(data)
}

pub(crate) fn sample_node(
    source: &dyn IndexField,
    bounds: Bounds,
    ambient: f64,
    p: DVec3,
    mode: GradientMode,
    h_cd: f64,
    shell: f64,
) -> Result<[f32; 4], BakeError> {
    let eval = |q: DVec3| -> (f64, DVec3) {
        let s = source.sample(q);
        let grad = match mode {
            GradientMode::Exact => s.grad_n,
            GradientMode::CentralDifference => {
                let d = |e: DVec3| (source.n(q + e * h_cd) - source.n(q - e * h_cd)) / (2.0 * h_cd);
                DVec3::new(d(DVec3::X), d(DVec3::Y), d(DVec3::Z))
            }
        };
        (s.n, grad)
    };
    // Beyond a shell of the margin's width outside the medium, nothing samples the field
    // but the interpolation stencils: hold the value of the shell's surface there instead
    // of extrapolating the formula far out (Luneburg's n^2 = 2 - r^2 goes negative).
    let sd = bounds.signed_distance(p);
    let p = if sd > shell {
        p - bounds.normal(p) * (sd - shell)
    } else {
        p
    };
    let sd = sd.min(shell);
    let (mut n, mut grad) = eval(p);
    if !(n.is_finite() && grad.is_finite()) && sd > 0.0 {
        // A margin node where the source has no extension: use the nearest surface point.
        (n, grad) = eval(p - bounds.normal(p) * sd);
    }
    if !(n.is_finite() && grad.is_finite()) {
        return Err(BakeError::NonFinite {
            field: source.describe(),
            n,
            x: p.x,
            y: p.y,
            z: p.z,
        });
    }
    Ok([
        (n - ambient) as f32,
        grad.x as f32,
        grad.y as f32,
        grad.z as f32,
    ])
}

/// max |delta_n| over the nodes inside the medium (the scale the budget is relative to).
fn delta_n_range_inside(raw: &[[f32; 4]], geometry: &GridGeometry, bounds: Bounds) -> f64 {
    let [nx, ny, _] = geometry.dims;
    raw.par_iter()
        .enumerate()
        .filter(|(idx, _)| {
            bounds.contains(geometry.node_world(idx % nx, (idx / nx) % ny, idx / (nx * ny)))
        })
        .map(|(_, v)| f64::from(v[0]).abs())
        .reduce(|| 0.0, f64::max)
}

/// SplitMix64: a tiny deterministic generator for the error points.
#[derive(Debug, Clone)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// `count` uniform random points inside `bounds` (deterministic for a seed).
pub fn random_points_inside(bounds: Bounds, count: usize, seed: u64) -> Vec<DVec3> {
    let (lo, hi) = bounds.aabb();
    let mut rng = SplitMix64(seed);
    let mut out = Vec::with_capacity(count);
    while out.len() < count {
        let u = DVec3::new(rng.next_f64(), rng.next_f64(), rng.next_f64());
        let p = lo + (hi - lo) * u;
        if bounds.contains(p) {
            out.push(p);
        }
    }
    out
}

/// Error points: most inside the part of the grid box within the medium (where the field
/// varies), the rest anywhere in the medium.
fn error_points(bounds: Bounds, lo: DVec3, hi: DVec3, count: usize, seed: u64) -> Vec<DVec3> {
    let in_grid = (count as f64 * ERROR_POINTS_IN_GRID) as usize;
    let mut pts = random_points_inside(bounds, count - in_grid, seed);
    let mut rng = SplitMix64(seed ^ 0xA5A5_5A5A);
    let mut tries = 0usize;
    while pts.len() < count && tries < 1000 * count {
        tries += 1;
        let u = DVec3::new(rng.next_f64(), rng.next_f64(), rng.next_f64());
        let p = lo + (hi - lo) * u;
        if bounds.contains(p) {
            pts.push(p);
        }
    }
    pts
}

/// `count` random points in the macro cells of `field` that are not homogeneous (inside
/// its bounds), when those are under half of its cells; none otherwise (uniform points
/// already land there).
fn varying_points(field: &BakedField, count: usize, seed: u64) -> Vec<DVec3> {
    let grid = field.macro_grid();
    let varying: Vec<[usize; 3]> = (0..grid.dims[2])
        .flat_map(|k| {
            (0..grid.dims[1]).flat_map(move |j| (0..grid.dims[0]).map(move |i| [i, j, k]))
        })
        .filter(|&c| !grid.homogeneous(c))
        .collect();
    if varying.is_empty() || 2 * varying.len() >= grid.max_grad.len() {
        return Vec::new();
    }
    let g = field.geometry();
    let gmax = g.grid_max();
    let bounds = crate::field::IndexField::bounds(field);
    let cell = grid.cell as f64;
    let mut rng = SplitMix64(seed ^ 0x3C3C_C3C3);
    let mut out = Vec::with_capacity(count);
    let mut tries = 0usize;
    while out.len() < count && tries < 100 * count {
        tries += 1;
        let c = varying[(rng.next_u64() % varying.len() as u64) as usize];
        let u = DVec3::new(rng.next_f64(), rng.next_f64(), rng.next_f64());
        let gp = ((DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64) + u) * cell).min(gmax);
        let p = g.origin + g.spacing * gp;
        if bounds.contains(p) {
            out.push(p);
        }
    }
    out
}

/// Max and RMS error of n and grad n of `baked` against `source` on random points inside
/// the medium. With [`GradientMode::CentralDifference`], the reference gradient is the
/// central difference of the source at 1e-6 of the bounds' radius.
pub fn measure_error(
    source: &dyn IndexField,
    baked: &dyn IndexField,
    mode: GradientMode,
    count: usize,
    seed: u64,
) -> ErrorStats {
    let points = random_points_inside(source.bounds(), count, seed);
    measure_error_at(source, baked, mode, &points)
}

/// [`measure_error`] at given points.
pub fn measure_error_at(
    source: &dyn IndexField,
    baked: &dyn IndexField,
    mode: GradientMode,
    points: &[DVec3],
) -> ErrorStats {
    let h = 1e-6 * source.bounds().radius();
    let ambient = source.ambient_index();
    let errs: Vec<(f64, f64, f64)> = points
        .par_iter()
        .map(|&p| {
            let s = source.sample(p);
            let g_ref = match mode {
                GradientMode::Exact => s.grad_n,
                GradientMode::CentralDifference => {
                    let d = |e: DVec3| (source.n(p + e * h) - source.n(p - e * h)) / (2.0 * h);
                    DVec3::new(d(DVec3::X), d(DVec3::Y), d(DVec3::Z))
                }
            };
            let b = baked.sample(p);
            (
                (b.n - s.n).abs(),
                (b.grad_n - g_ref).length(),
                (s.n - ambient).abs(),
            )
        })
        .collect();
    let n = errs.len().max(1) as f64;
    let mut st = ErrorStats {
        points: errs.len(),
        ..Default::default()
    };
    let (mut s_n, mut s_g) = (0.0, 0.0);
    for (en, eg, dn) in errs {
        st.max_err_n = st.max_err_n.max(en);
        st.max_source_delta_n = st.max_source_delta_n.max(dn);
        st.max_err_grad = st.max_err_grad.max(eg);
        s_n += en * en;
        s_g += eg * eg;
    }
    st.rms_err_n = (s_n / n).sqrt();
    st.rms_err_grad = (s_g / n).sqrt();
    st
}

pub mod device;
#[cfg(test)]
mod tests;
