//! The sparse bake: find the bricks where the field differs from ambient, then bake each
//! one at the coarsest level whose own measured error meets the budget. No dense box of
//! the medium is ever made; time and memory follow the active bricks.
//!
//! 1. Probe: every brick of the top grid that meets the medium is probed at its level-0
//!    nodes (`(BASE_CELLS + 1)^3` points) and asked for a proven bound on |n - ambient|
//!    ([`IndexField::delta_bound`]). The largest |delta_n| probed (and at the field's
//!    feature points) is the range the budget is relative to.
//! 2. Classify: a brick is active when its bound (where the field proves one, else its
//!    probes' maximum) exceeds [`CROP_FRACTION_OF_BUDGET`] of the budget's share of the
//!    range, or a feature point in it does; what empty bricks drop costs at most a tenth
//!    of the budget.
//! 3. Bake: each active brick tries levels 0, 1, ... and keeps the first whose max error
//!    at [`ERROR_POINTS_PER_BRICK`] random points inside it (and at the feature points in
//!    it) is within [`BUDGET_SAFETY`] of the budget. A source with its own spacing (a VDB
//!    grid) stops at half that spacing: finer resolves only its interpolation.
//! 4. Measure: the whole field's error on random points, as a dense bake's is (most of
//!    them in active bricks), which decides whether the budget is met.
//!
//! Over 600 lines: one concept, the sparse bake's policy (probe, brick size, level search,
//! refinement, assembly).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use super::{
    BASE_CELLS, Brick, EMPTY, MAX_LEVEL, Pool, SparseField, TopGrid, apron_of, catmull_rom_weights,
    cells_of, nodes_of,
};
use crate::bake::{
    BUDGET_SAFETY, BakeError, CROP_FRACTION_OF_BUDGET, DEFAULT_ERROR_BUDGET, DEFAULT_ERROR_POINTS,
    DEFAULT_MAX_MEMORY, ErrorStats, GRID_MARGIN_TRILINEAR, GradientMode, Progress, SplitMix64,
    choose_storage, measure_error_at, random_points_inside, sample_node,
};
use crate::baked::{BakeProvenance, Interp, Storage};
use crate::field::IndexField;

/// Bricks along the medium's longest axis.
pub const DEFAULT_TOP_BRICKS: usize = 32;
/// Most probe bricks along an axis when the brick size is chosen (64^3 probe bricks is
/// 33 M probes).
pub const MAX_PROBE_BRICKS: usize = 64;
/// Most bricks along an axis (a table of 1024^3 entries is 4 GiB).
pub const MAX_TOP_BRICKS: usize = 1024;
/// Random points a brick's level search measures its error at.
pub const ERROR_POINTS_PER_BRICK: usize = 64;
/// Bricks are merged only where no probe brick needs more than this many times the
/// probes' own cells a side.
const MERGE_PROBE_LIMIT: usize = 4;
/// Rounds of baking again the bricks whose measured error is over their share.
const REFINE_ROUNDS: u64 = 3;
/// Share of the final error points drawn inside active bricks.
const ERROR_POINTS_IN_BRICKS: f64 = 0.75;

/// What to bake and how.
#[derive(Debug, Clone)]
pub struct SparseOptions {
    /// Relative error budget, as a dense bake's.
    pub error_budget: f64,
    /// Cap in bytes on the field in memory (voxels, table, brick records).
    pub max_memory: u64,
    /// Storage; `None` picks i16 when its rounding fits the budget.
    pub storage: Option<Storage>,
    /// Bricks along the medium's longest axis; `None` chooses: the medium is probed on
    /// [`DEFAULT_TOP_BRICKS`] and bricks of 1, 2, 4 or 8 of those a side are kept, whichever
    /// the probes' curvature predicts holds the budget in the fewest voxels (small bricks
    /// pay for their shared faces, (cells + 1)^3 nodes for cells^3 cells, (cells + 3)^3
    /// with a Catmull-Rom apron; large ones are as fine everywhere as their finest
    /// corner). The prediction is the sampling's own (second differences and h^2 for
    /// trilinear, third differences and h^3 for Catmull-Rom). A Catmull-Rom bake of data
    /// on a lattice (a VDB grid) takes that lattice's bricks instead.
    pub top_bricks: Option<usize>,
    pub gradient: GradientMode,
    /// Random points the final error is measured at.
    pub error_points: usize,
    pub seed: u64,
    /// Trilinear, or tricubic Catmull-Rom (bricks with an apron: see the module docs of
    /// `sparse`).
    pub interp: Interp,
}

impl Default for SparseOptions {
    fn default() -> Self {
        SparseOptions {
            error_budget: DEFAULT_ERROR_BUDGET,
            max_memory: DEFAULT_MAX_MEMORY,
            storage: None,
            top_bricks: None,
            gradient: GradientMode::Exact,
            error_points: DEFAULT_ERROR_POINTS,
            seed: 1,
            interp: Interp::Trilinear,
        }
    }
}

/// What a sparse bake chose and measured.
#[derive(Debug, Clone)]
pub struct SparseReport {
    pub top: TopGrid,
    pub active_bricks: usize,
    /// Bricks of the top grid.
    pub total_bricks: usize,
    /// Active bricks per level (`LEVEL_CELLS[level]` cells a side).
    pub levels: [usize; MAX_LEVEL as usize + 1],
    pub finest_spacing: f64,
    pub storage: Storage,
    /// Bytes of voxel data (what the file stores after its table).
    pub bytes: u64,
    /// Bytes in memory (voxels, table, brick records).
    pub memory_bytes: u64,
    /// Bytes a dense grid at the finest spacing would need over the box of the active
    /// bricks, at the same storage: what sparsity and adaptivity saved.
    pub dense_bytes: u64,
    pub errors: ErrorStats,
    pub delta_n_range: f64,
    pub relative_error: f64,
    pub budget: f64,
    pub meets_budget: bool,
    /// Bricks that reached their finest allowed level without meeting the budget there.
    pub limited_bricks: usize,
    /// The budget is missed only where bricks reached the source's own spacing (a VDB
    /// grid): what is left is its interpolation, not missing data; the bake is kept.
    pub source_limited: bool,
    /// Whether the source proved its empty bricks empty (else they were probed).
    pub proven_empty: bool,
    pub seconds: f64,
    pub source_evals: u64,
}

/// One brick's bake.
struct BakedBrick {
    level: u8,
    voxels: BrickVoxels,
    scale: [f32; 2],
    limited: bool,
    apron: u8,
}

enum BrickVoxels {
    F32(Vec<[f32; 4]>),
    I16(Vec<[i16; 4]>),
}

/// Bake `source` sparsely per `opts`.
pub fn bake_sparse(
    source: &dyn IndexField,
    opts: &SparseOptions,
    progress: Progress<'_>,
) -> Result<(SparseField, SparseReport), BakeError> {
    let start = Instant::now();
    crate::bake::check_budget_and_points(opts.error_budget, opts.error_points)?;
    let probe_bricks = opts
        .top_bricks
        .unwrap_or_else(|| probe_grid(source.bounds(), source.feature_size()));
    if !(1..=MAX_TOP_BRICKS).contains(&probe_bricks) {
        return Err(BakeError::Option(format!(
            "{probe_bricks} bricks along the longest axis: must be 1 to {MAX_TOP_BRICKS}"
        )));
    }
    let bounds = source.bounds();
    let ambient = source.ambient_index();
    // A Catmull-Rom bake of data on an axis-aligned lattice (a VDB grid) puts its nodes on
    // that lattice: its interpolant is then the source's own.
    let lattice = match (opts.interp, opts.top_bricks) {
        (Interp::Tricubic, None) => source.source_lattice(),
        _ => None,
    };
    let top = match lattice {
        Some((origin, h)) => lattice_grid(bounds.aabb(), origin, h)?,
        None => top_grid(bounds.aabb(), probe_bricks),
    };
    let table_bytes = 4 * top.brick_count() as u64;
    if table_bytes > opts.max_memory {
        return Err(BakeError::SparseMemory {
            need: table_bytes,
            cap: opts.max_memory,
            done: 0,
            active: 0,
        });
    }
    let evals = AtomicU64::new(0);

    // 1. Probe.
    let count = top.brick_count();
    let features = source.feature_points();
    let done = AtomicU64::new(0);
    progress("probe bricks", 0, count as u64);
    // Per brick meeting the medium: max |delta_n| probed, the proven bound, the probes'
    // curvature error (what a level-0 grid would miss).
    let probes: Vec<Option<(f64, Option<f64>, f64)>> = (0..count)
        .into_par_iter()
        .map(|idx| {
            let at = top.at(idx);
            let (lo, hi) = top.brick_box(at);
            let d = done.fetch_add(1, Ordering::Relaxed) + 1;
            if d.is_multiple_of(1024) || d == count as u64 {
                progress("probe bricks", d, count as u64);
            }
            if !bounds.meets_box(lo, hi, 0.0) {
                return None;
            }
            let m = BASE_CELLS + 1;
            let h = top.edge / BASE_CELLS as f64;
            let mut max = 0.0f64;
            let mut nodes = [[0.0f32; 4]; (BASE_CELLS + 1) * (BASE_CELLS + 1) * (BASE_CELLS + 1)];
            let node =
                |i: usize, j: usize, k: usize| lo + h * DVec3::new(i as f64, j as f64, k as f64);
            for k in 0..m {
                for j in 0..m {
                    for i in 0..m {
                        let p = node(i, j, k);
                        let d = source.n(p) - ambient;
                        nodes[i + m * (j + m * k)][0] = d as f32;
                        if bounds.contains(p) {
                            max = max.max(d.abs());
                        }
                    }
                }
            }
            evals.fetch_add((m * m * m) as u64, Ordering::Relaxed);
            // What the sampling's own error predictor makes of the probes: Catmull-Rom's
            // third differences read the 5^3 probes as 2 cells and their apron.
            let inside =
                |i: usize, j: usize, k: usize| bounds.signed_distance(node(i, j, k)) <= 0.0;
            let curvature = match opts.interp {
                Interp::Trilinear => predicted_error(&nodes, BASE_CELLS, opts.interp, inside),
                Interp::Tricubic => predicted_error(&nodes, BASE_CELLS - 2, opts.interp, inside),
            };
            Some((max, source.delta_bound(lo, hi), curvature))
        })
        .collect();
    let mut range = probes.iter().flatten().map(|p| p.0).fold(0.0f64, f64::max);
    let feature_deltas: Vec<(DVec3, f64)> = features
        .iter()
        .map(|&p| (p, (source.n(p) - ambient).abs()))
        .collect();
    range = feature_deltas.iter().map(|f| f.1).fold(range, f64::max);

    // 2. Classify.
    let threshold = CROP_FRACTION_OF_BUDGET * opts.error_budget * range;
    let mut active: Vec<usize> = probes
        .iter()
        .enumerate()
        .filter_map(|(idx, p)| {
            let (max, bound, _) = (*p)?;
            (bound.unwrap_or(max) > threshold).then_some(idx)
        })
        .collect();
    for &(p, d) in &feature_deltas {
        if d > threshold
            && let Some(idx) = brick_of(&top, p)
            && probes[idx].is_some()
        {
            active.push(idx);
        }
    }
    active.sort_unstable();
    active.dedup();
    let proven_empty = probes.iter().flatten().all(|p| p.1.is_some());
    let tolerance = BUDGET_SAFETY * opts.error_budget * range;

    // The bricks: the probe grid's, or (chosen) blocks of f x f x f of them.
    let (top, active) = match (opts.top_bricks, lattice) {
        (Some(_), _) | (None, Some(_)) => (top, active),
        (None, None) => {
            let needed: Vec<(usize, f64)> = active
                .iter()
                .map(|&idx| {
                    let e = probes[idx].map_or(0.0, |p| p.2);
                    let ratio = order_root(opts.interp, e / tolerance);
                    (idx, BASE_CELLS as f64 * ratio * 1.05)
                })
                .collect();
            // Where the probes are 4x coarser than a brick needs, their curvature is
            // aliased (a sheet 1.3 probe spacings thick predicted bricks 3x too coarse):
            // no merging then.
            let resolved = needed
                .iter()
                .all(|&(_, c)| c <= (MERGE_PROBE_LIMIT * BASE_CELLS) as f64);
            let f = [1usize, 2, 4, 8]
                .into_iter()
                .filter(|&f| f == 1 || (resolved && top.dims.iter().any(|&d| d >= f)))
                .min_by_key(|&f| {
                    let voxels = predicted_voxels(&top, &needed, f, apron_of(opts.interp));
                    (voxels, usize::MAX - f)
                })
                .unwrap_or(1);
            merged(&top, &active, f)
        }
    };
    let count = top.brick_count();
    let table_bytes = 4 * count as u64;

    // 3. Bake the active bricks.
    let storage = opts
        .storage
        .unwrap_or_else(|| choose_storage(range, opts.error_budget));
    // On the source's lattice every brick takes the level whose nodes are its voxels.
    let (first_level, level_max) = match lattice {
        Some(_) => (LATTICE_LEVEL, LATTICE_LEVEL),
        None => (
            0,
            finest_level(top.edge, source.source_spacing(), opts.interp),
        ),
    };
    let job = BrickJob {
        top: &top,
        features: &features,
        level_max,
        predict: lattice.is_none(),
        tolerance,
        storage,
        opts,
        evals: &evals,
    };
    progress("bake bricks", 0, active.len() as u64);
    let todo: Vec<(usize, u8)> = active.iter().map(|&idx| (idx, first_level)).collect();
    let baked = bake_within(source, &job, &todo, table_bytes, active.len(), progress)?;

    // 4. Assemble and measure. Bricks where the measured error is over their share are
    // baked again finer: a level search judges a brick by 64 points and its nodes'
    // curvature, which a field its grid under-resolves (noise at a loose budget) can fool.
    let mut points = error_points(&top, &active, bounds, opts.error_points, opts.seed);
    points.extend(features.iter().copied());
    let mut baked = baked;
    let mut round = 0u64;
    let (mut field, errors, range, rel) = loop {
        progress("measure error", round, REFINE_ROUNDS + 1);
        // On the source's lattice the gradient is the derivative of the interpolated
        // delta_n, as the source's own is.
        let field = assemble(&top, &active, &mut baked, storage, bounds, ambient, source)?
            .with_apron(apron_of(opts.interp))
            .and_then(|f| f.with_gradient_of_n(lattice.is_some()))
            .map_err(BakeError::Option)?;
        let errors = measure_error_at(source, &field, opts.gradient, &points);
        let range = range.max(errors.max_source_delta_n);
        let rel = crate::bake::relative_error(errors.max_err_n, range);
        if rel <= opts.error_budget || round == REFINE_ROUNDS {
            break (field, errors, range, rel);
        }
        let tol = BUDGET_SAFETY * opts.error_budget * range;
        let mut worst = std::collections::BTreeMap::new();
        for &p in &points {
            let err = (field.sample(p).n - source.n(p)).abs();
            if err > tol
                && let Some(idx) = brick_of(&top, p)
                && let Ok(pos) = active.binary_search(&idx)
            {
                let w = worst.entry(pos).or_insert(0.0f64);
                *w = w.max(err);
            }
        }
        let redo: Vec<(usize, u8)> = worst
            .into_iter()
            .filter(|&(pos, _)| baked[pos].level < level_max)
            .map(|(pos, err)| {
                let wanted =
                    cells_of(baked[pos].level) as f64 * order_root(opts.interp, err / tol) * 1.05;
                let level = (baked[pos].level + 1..=level_max)
                    .find(|&l| cells_of(l) as f64 >= wanted)
                    .unwrap_or(level_max);
                (pos, level)
            })
            .collect();
        if redo.is_empty() {
            break (field, errors, range, rel);
        }
        // What stays is counted against the cap with what the bricks baked again take.
        let staying = field.memory_bytes() as u64
            - redo
                .iter()
                .map(|&(pos, _)| baked_bytes(baked[pos].level, job.storage, apron_of(opts.interp)))
                .sum::<u64>();
        disassemble(field, &mut baked);
        let todo: Vec<(usize, u8)> = redo
            .iter()
            .map(|&(pos, level)| (active[pos], level))
            .collect();
        let rebaked = bake_within(source, &job, &todo, staying, active.len(), &|_, _, _| {})?;
        for (&(pos, _), b) in redo.iter().zip(rebaked) {
            baked[pos] = b;
        }
        round += 1;
    };
    let limited_bricks = baked.iter().filter(|b| b.limited).count();
    if field.memory_bytes() as u64 > opts.max_memory {
        return Err(BakeError::SparseMemory {
            need: field.memory_bytes() as u64,
            cap: opts.max_memory,
            done: active.len(),
            active: active.len(),
        });
    }
    progress("measure error", REFINE_ROUNDS + 1, REFINE_ROUNDS + 1);
    let source_limited =
        rel > opts.error_budget && limited_bricks > 0 && source.source_spacing().is_some();
    if rel > opts.error_budget && !source_limited {
        return Err(BakeError::SparseBudgetNotMet {
            budget: opts.error_budget,
            best: rel,
            spacing: top.edge / cells_of(level_max) as f64,
            limited: limited_bricks,
        });
    }
    field.set_provenance(BakeProvenance {
        source: source.describe(),
        max_err_n: errors.max_err_n,
        rms_err_n: errors.rms_err_n,
        max_err_grad: errors.max_err_grad,
        rms_err_grad: errors.rms_err_grad,
    });
    let report = SparseReport {
        top,
        active_bricks: field.bricks().len(),
        total_bricks: count,
        levels: field.level_counts(),
        finest_spacing: field.finest_spacing(),
        storage,
        bytes: field.data_bytes() as u64,
        memory_bytes: field.memory_bytes() as u64,
        dense_bytes: dense_equivalent_bytes(&field),
        errors,
        delta_n_range: range,
        relative_error: rel,
        budget: opts.error_budget,
        meets_budget: rel <= opts.error_budget,
        limited_bricks,
        source_limited,
        proven_empty,
        seconds: start.elapsed().as_secs_f64(),
        source_evals: evals.load(Ordering::Relaxed),
    };
    Ok((field, report))
}

/// Probe bricks along the longest axis for a chosen brick size: [`DEFAULT_TOP_BRICKS`],
/// or up to [`MAX_PROBE_BRICKS`] (a power of two) where the field's finest feature is
/// narrower than half a brick (eight plumes 9 units wide in a 1000-unit cube: 31-unit
/// bricks held 156 MB where 16-unit ones held 65).
fn probe_grid(bounds: crate::bounds::Bounds, feature: Option<f64>) -> usize {
    let (lo, hi) = bounds.aabb();
    let longest = (hi - lo).max_element();
    let Some(fs) = feature.filter(|f| f.is_finite() && *f > 0.0) else {
        return DEFAULT_TOP_BRICKS;
    };
    let wanted = (longest / (2.0 * fs)).min(MAX_PROBE_BRICKS as f64);
    let mut n = DEFAULT_TOP_BRICKS;
    while (n as f64) < wanted && n < MAX_PROBE_BRICKS {
        n *= 2;
    }
    n
}

/// Voxels the bricks of `f` x `f` x `f` probe bricks would hold, each at the level the
/// finest of its probe bricks needs (`needed`: probe brick, cells it needs a side).
fn predicted_voxels(top: &TopGrid, needed: &[(usize, f64)], f: usize, apron: u8) -> u64 {
    let mut finest = std::collections::HashMap::new();
    for &(idx, cells) in needed {
        let parent = parent_of(top, idx, f);
        let e = finest.entry(parent).or_insert(0.0f64);
        *e = e.max(cells * f as f64);
    }
    finest
        .values()
        .map(|&c| {
            let level = (0..=MAX_LEVEL)
                .find(|&l| cells_of(l) as f64 >= c)
                .unwrap_or(MAX_LEVEL);
            (nodes_of(cells_of(level), apron) as u64).pow(3)
        })
        .sum()
}

/// The index, in the grid of `f`-fold bricks, of probe brick `idx`'s block.
fn parent_of(top: &TopGrid, idx: usize, f: usize) -> usize {
    let pd = top.dims.map(|d| d.div_ceil(f));
    let at = top.at(idx).map(|a| a / f);
    at[0] + pd[0] * (at[1] + pd[1] * at[2])
}

/// The grid of `f`-fold bricks (same origin) and its active bricks (those holding an
/// active probe brick).
fn merged(top: &TopGrid, active: &[usize], f: usize) -> (TopGrid, Vec<usize>) {
    let grid = TopGrid {
        origin: top.origin,
        edge: top.edge * f as f64,
        dims: top.dims.map(|d| d.div_ceil(f)),
    };
    let mut out: Vec<usize> = active.iter().map(|&idx| parent_of(top, idx, f)).collect();
    out.sort_unstable();
    out.dedup();
    (grid, out)
}

/// The level of a brick on a source's lattice ([`lattice_grid`]): 16 cells, one a voxel
/// (its apron costs (19/16)^3 = 1.67x the voxels; at 8 cells it would be 2.6x).
const LATTICE_LEVEL: u8 = 6;

/// Bricks of [`LATTICE_LEVEL`]'s cells of spacing `h` covering the box, their nodes on the
/// lattice of node `origin` and spacing `h`.
fn lattice_grid((lo, hi): (DVec3, DVec3), origin: DVec3, h: f64) -> Result<TopGrid, BakeError> {
    let cells = cells_of(LATTICE_LEVEL) as f64;
    let corner = origin + h * ((lo - origin) / h).floor();
    let edge = cells * h;
    let dims = [0, 1, 2].map(|a| (((hi[a] - corner[a]) / edge).ceil().max(1.0)) as usize);
    if dims.iter().any(|&d| d > MAX_TOP_BRICKS) || !corner.is_finite() {
        return Err(BakeError::Option(format!(
            "a lattice of spacing {h} over the medium needs {dims:?} bricks of {cells} voxels (at most {MAX_TOP_BRICKS} an axis)"
        )));
    }
    Ok(TopGrid {
        origin: corner,
        edge,
        dims,
    })
}

/// Cubic bricks of edge `longest / bricks` covering the box, centred on it.
fn top_grid((lo, hi): (DVec3, DVec3), bricks: usize) -> TopGrid {
    let extent = (hi - lo).max(DVec3::splat(1e-12));
    let edge = extent.max_element() / bricks as f64;
    let dims = [0, 1, 2].map(|a| ((extent[a] / edge) - 1e-9).ceil().max(1.0) as usize);
    let span = DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64) * edge;
    TopGrid {
        origin: (lo + hi) * 0.5 - span * 0.5,
        edge,
        dims,
    }
}

/// The top-grid index of the brick holding `p`.
fn brick_of(top: &TopGrid, p: DVec3) -> Option<usize> {
    let g = (p - top.origin) / top.edge;
    let mut at = [0usize; 3];
    for a in 0..3 {
        if !(g[a] >= 0.0 && g[a] <= top.dims[a] as f64) {
            return None;
        }
        at[a] = (g[a] as usize).min(top.dims[a] - 1);
    }
    Some(top.index(at))
}

/// The finest level a brick of `edge` may take: [`MAX_LEVEL`], or for a source with its
/// own spacing the finest whose spacing is at least half of it.
fn finest_level(edge: f64, source_spacing: Option<f64>, interp: Interp) -> u8 {
    let Some(h) = source_spacing.filter(|h| h.is_finite() && *h > 0.0) else {
        return MAX_LEVEL;
    };
    let fraction = match interp {
        Interp::Trilinear => 0.5,
        Interp::Tricubic => 0.25,
    };
    (0..=MAX_LEVEL)
        .take_while(|&l| edge / cells_of(l) as f64 >= fraction * h * (1.0 - 1e-9))
        .last()
        .unwrap_or(0)
}

/// Bake the bricks `todo` (top-grid index, first level) in parallel, their bytes counted
/// from `used` on: once the count passes the cap no further brick starts and the bake is
/// a [`BakeError::SparseMemory`] (`active` the field's active bricks, for its message).
fn bake_within(
    source: &dyn IndexField,
    job: &BrickJob<'_>,
    todo: &[(usize, u8)],
    used: u64,
    active: usize,
    progress: Progress<'_>,
) -> Result<Vec<BakedBrick>, BakeError> {
    let cap = job.opts.max_memory;
    let used = AtomicU64::new(used);
    let over = AtomicBool::new(false);
    let done = AtomicU64::new(0);
    let total = todo.len() as u64;
    let baked = todo
        .par_iter()
        .map(|&(idx, level)| -> Result<BakedBrick, BakeError> {
            if over.load(Ordering::Relaxed) {
                return Err(BakeError::Option("stopped".into()));
            }
            let b = bake_brick(source, job, job.top.at(idx), idx, level)?;
            let bytes = baked_bytes(b.level, job.storage, b.apron);
            if used.fetch_add(bytes, Ordering::Relaxed) + bytes > cap {
                over.store(true, Ordering::Relaxed);
            }
            let d = done.fetch_add(1, Ordering::Relaxed) + 1;
            progress("bake bricks", d, total);
            Ok(b)
        })
        .collect::<Result<Vec<_>, _>>();
    if over.load(Ordering::Relaxed) {
        return Err(BakeError::SparseMemory {
            need: used.load(Ordering::Relaxed),
            cap,
            done: done.load(Ordering::Relaxed) as usize,
            active,
        });
    }
    baked
}

/// Bytes a brick at `level` with `apron` holds in memory (its voxels and its record).
fn baked_bytes(level: u8, storage: Storage, apron: u8) -> u64 {
    let voxels = (nodes_of(cells_of(level), apron) as u64).pow(3);
    voxels * storage.bytes_per_voxel() as u64 + std::mem::size_of::<Brick>() as u64
}

/// What every brick's bake shares: the top grid, the field's feature points, the finest
/// level a brick may take, whether the nodes' differences predict the error (not on a
/// source's lattice), the absolute |n| tolerance, the storage, the options and the count
/// of source evaluations.
struct BrickJob<'a> {
    top: &'a TopGrid,
    features: &'a [DVec3],
    level_max: u8,
    predict: bool,
    tolerance: f64,
    storage: Storage,
    opts: &'a SparseOptions,
    evals: &'a AtomicU64,
}

/// Bake brick `at` (top-grid index `idx`) at the coarsest level from `first_level` that
/// meets the tolerance.
fn bake_brick(
    source: &dyn IndexField,
    job: &BrickJob<'_>,
    at: [usize; 3],
    idx: usize,
    first_level: u8,
) -> Result<BakedBrick, BakeError> {
    let BrickJob {
        top,
        features,
        level_max,
        predict,
        tolerance,
        storage,
        opts,
        evals,
    } = *job;
    let bounds = source.bounds();
    let ambient = source.ambient_index();
    let (lo, hi) = top.brick_box(at);
    // Points to judge a level by: random inside the brick and the medium, and the
    // field's feature points in the brick.
    let mut rng = SplitMix64(opts.seed ^ (idx as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let mut points = Vec::with_capacity(ERROR_POINTS_PER_BRICK);
    let mut tries = 0;
    while points.len() < ERROR_POINTS_PER_BRICK && tries < 64 * ERROR_POINTS_PER_BRICK {
        tries += 1;
        let p = lo + (hi - lo) * DVec3::new(rng.next_f64(), rng.next_f64(), rng.next_f64());
        if bounds.contains(p) {
            points.push(p);
        }
    }
    points.extend(
        features
            .iter()
            .filter(|p| p.cmpge(lo).all() && p.cmple(hi).all())
            .copied(),
    );
    let reference: Vec<f64> = points.iter().map(|&p| source.n(p) - ambient).collect();
    evals.fetch_add(points.len() as u64, Ordering::Relaxed);
    let per_node = match opts.gradient {
        GradientMode::Exact => 1,
        GradientMode::CentralDifference => 7,
    };
    let apron = apron_of(opts.interp);
    let a = f64::from(apron);
    let mut level = first_level.min(level_max);
    loop {
        let cells = cells_of(level);
        let m = nodes_of(cells, apron);
        let h = top.edge / cells as f64;
        let shell = (GRID_MARGIN_TRILINEAR as f64 + a) * h;
        let h_cd = crate::bake::CD_STEP_VOXELS * h;
        let mut raw = crate::alloc::try_with_capacity(m * m * m, "a sparse brick")?;
        // Node (i, j, k) of the stored grid sits at lo + h (i - apron, j - apron, k - apron).
        let node = |i: usize, j: usize, k: usize| {
            lo + h * (DVec3::new(i as f64, j as f64, k as f64) - DVec3::splat(a))
        };
        for k in 0..m {
            for j in 0..m {
                for i in 0..m {
                    let p = node(i, j, k);
                    raw.push(sample_node(
                        source,
                        bounds,
                        ambient,
                        p,
                        opts.gradient,
                        h_cd,
                        shell,
                    )?);
                }
            }
        }
        evals.fetch_add((m * m * m * per_node) as u64, Ordering::Relaxed);
        // Curvature only where its stencil holds the field itself: beyond the shell
        // sample_node holds the shell's value, a kink no grid resolves (a brick across a
        // sphere's surface climbed to 256 cells on it).
        let inside = |i: usize, j: usize, k: usize| bounds.signed_distance(node(i, j, k)) <= 0.0;
        // What the nodes' differences predict the interpolation misses (not on a source's
        // lattice, where the nodes are the source's own data).
        let predicted = if predict {
            predicted_error(&raw, cells, opts.interp, inside)
        } else {
            0.0
        };
        let err = points
            .iter()
            .zip(&reference)
            .map(|(&p, &r)| (delta_at(&raw, cells, apron, (p - lo) / h) - r).abs())
            .fold(predicted, f64::max);
        let met = err <= tolerance;
        if met || level >= level_max {
            let (voxels, scale) = match storage {
                Storage::F32 => (BrickVoxels::F32(raw), [1.0, 1.0]),
                Storage::I16 => {
                    let (q, s) = quantize(&raw);
                    (BrickVoxels::I16(q), s)
                }
            };
            return Ok(BakedBrick {
                level,
                voxels,
                scale,
                limited: !met,
                apron,
            });
        }
        // Trilinear error goes as h^2, Catmull-Rom's as h^3: the next level is the first
        // whose cells the error predicts enough for (5% margin), at least one finer.
        let wanted = cells as f64 * order_root(opts.interp, err / tolerance) * 1.05;
        level = (level + 1..=level_max)
            .find(|&l| cells_of(l) as f64 >= wanted)
            .unwrap_or(level_max);
    }
}

/// The largest interpolation error a brick's raw nodes predict for themselves (with the
/// apron `interp` needs), taken at every node inside the medium. Random points alone miss
/// the one cell where a narrow peak's error is largest (64 points a brick left an
/// eight-plume bake at 1.9e-3 against a 1e-3 budget).
/// - Trilinear: inside a cell the error is sum_a t_a (1 - t_a) h^2 |f_aa| / 2 to leading
///   order, at most sum_a |second difference along a| / 8.
/// - Catmull-Rom: along an axis h^3 |f'''| t (1 - t) (1 - 2t) / 6 to leading order (zero for
///   quadratics), at most 0.016 h^3 |f'''| ~ |third difference| / 62; the sum over the axes
///   at every inner node, with a margin of 2 (the random points catch what this misses).
fn predicted_error(
    raw: &[[f32; 4]],
    cells: usize,
    interp: Interp,
    inside: impl Fn(usize, usize, usize) -> bool,
) -> f64 {
    let m = nodes_of(cells, apron_of(interp));
    let at = |i: usize, j: usize, k: usize| f64::from(raw[i + m * (j + m * k)][0]);
    match interp {
        Interp::Trilinear => {
            // On a face the difference is the one centred a node inwards (one-sided there).
            let inner = |a: usize| a.clamp(1, m - 2);
            let max = max_over_nodes(0..m, inside, |i, j, k| {
                let (ci, cj, ck) = (inner(i), inner(j), inner(k));
                (at(ci + 1, j, k) + at(ci - 1, j, k) - 2.0 * at(ci, j, k)).abs()
                    + (at(i, cj + 1, k) + at(i, cj - 1, k) - 2.0 * at(i, cj, k)).abs()
                    + (at(i, j, ck + 1) + at(i, j, ck - 1) - 2.0 * at(i, j, ck)).abs()
            });
            max / 8.0
        }
        Interp::Tricubic => {
            // A difference from node c - 1 to c + 2 (c within 1 ..= m - 3).
            let third = |f: &dyn Fn(usize) -> f64, c: usize| {
                let c = c.clamp(1, m - 3);
                (f(c + 2) - 3.0 * f(c + 1) + 3.0 * f(c) - f(c - 1)).abs()
            };
            let max = max_over_nodes(1..m - 1, inside, |i, j, k| {
                third(&|x| at(x, j, k), i) + third(&|y| at(i, y, k), j) + third(&|z| at(i, j, z), k)
            });
            max / 31.0
        }
    }
}

/// The largest `f` at the nodes (i, j, k), each in `range`, where `inside` holds.
fn max_over_nodes(
    range: std::ops::Range<usize>,
    inside: impl Fn(usize, usize, usize) -> bool,
    f: impl Fn(usize, usize, usize) -> f64,
) -> f64 {
    let mut max = 0.0f64;
    for k in range.clone() {
        for j in range.clone() {
            for i in range.clone() {
                if inside(i, j, k) {
                    max = max.max(f(i, j, k));
                }
            }
        }
    }
    max
}

/// How much finer a grid must be for its error to shrink by `ratio`: the square root
/// (trilinear, second order) or the cube root (Catmull-Rom, third order).
fn order_root(interp: Interp, ratio: f64) -> f64 {
    match interp {
        Interp::Trilinear => ratio.sqrt(),
        Interp::Tricubic => ratio.cbrt(),
    }
}

/// delta_n of a brick's raw nodes (with `apron` layers beyond its faces) at cell
/// coordinates `u`: trilinear, or Catmull-Rom where the brick has an apron.
fn delta_at(raw: &[[f32; 4]], cells: usize, apron: u8, u: DVec3) -> f64 {
    if apron == 0 {
        trilinear_delta(raw, cells, u)
    } else {
        let m = cells + 3;
        let (i, t) = super::cell_of(u, cells);
        let [wx, wy, wz] = t.map(|t| catmull_rom_weights(t as f32).map(f64::from));
        let mut out = 0.0;
        for (k, w_k) in wz.iter().enumerate() {
            for (j, w_j) in wy.iter().enumerate() {
                let row = i[0] + m * ((i[1] + j) + m * (i[2] + k));
                let line: f64 = (0..4).map(|x| wx[x] * f64::from(raw[row + x][0])).sum();
                out += line * w_k * w_j;
            }
        }
        out
    }
}

/// Trilinear delta_n of a brick's raw nodes at cell coordinates `u`.
fn trilinear_delta(raw: &[[f32; 4]], cells: usize, u: DVec3) -> f64 {
    let m = cells + 1;
    let (i, t) = super::cell_of(u, cells);
    let mut out = 0.0;
    for dz in 0..2 {
        for dy in 0..2 {
            for dx in 0..2 {
                let w = (if dx == 0 { 1.0 - t[0] } else { t[0] })
                    * (if dy == 0 { 1.0 - t[1] } else { t[1] })
                    * (if dz == 0 { 1.0 - t[2] } else { t[2] });
                out += w * f64::from(raw[(i[0] + dx) + m * ((i[1] + dy) + m * (i[2] + dz))][0]);
            }
        }
    }
    out
}

/// i16 voxels of one brick with its own scales (delta_n, and the gradient's).
fn quantize(raw: &[[f32; 4]]) -> (Vec<[i16; 4]>, [f32; 2]) {
    let (data, scale) = crate::baked::quantize_i16(raw);
    (data, [scale[0], scale[1]])
}

/// The final error points: most inside active bricks (and the medium), the rest anywhere
/// in the medium.
fn error_points(
    top: &TopGrid,
    active: &[usize],
    bounds: crate::bounds::Bounds,
    count: usize,
    seed: u64,
) -> Vec<DVec3> {
    let in_bricks = if active.is_empty() {
        0
    } else {
        (count as f64 * ERROR_POINTS_IN_BRICKS) as usize
    };
    let mut pts = random_points_inside(bounds, count - in_bricks, seed);
    let mut rng = SplitMix64(seed ^ 0x5A5A_A5A5);
    let mut tries = 0usize;
    while pts.len() < count && tries < 1000 * count {
        tries += 1;
        let idx = active[(rng.next_u64() % active.len() as u64) as usize];
        let at = top.at(idx);
        let (lo, hi) = top.brick_box(at);
        let p = lo + (hi - lo) * DVec3::new(rng.next_f64(), rng.next_f64(), rng.next_f64());
        if bounds.contains(p) {
            pts.push(p);
        }
    }
    pts
}

/// The field of `baked` (one per `active` brick, in order): the table, the brick records
/// and the voxels moved into one pool (each brick's freed as it is copied, so the bake's
/// peak is about one pool, not two).
fn assemble(
    top: &TopGrid,
    active: &[usize],
    baked: &mut [BakedBrick],
    storage: Storage,
    bounds: crate::bounds::Bounds,
    ambient: f64,
    source: &dyn IndexField,
) -> Result<SparseField, BakeError> {
    let voxel_total: usize = baked
        .iter()
        .map(|b| nodes_of(cells_of(b.level), b.apron).pow(3))
        .sum();
    let mut table =
        crate::alloc::try_filled(top.brick_count(), EMPTY, "a sparse field's brick table")?;
    let mut bricks = Vec::with_capacity(baked.len());
    let pool = match storage {
        Storage::F32 => {
            let mut pool = crate::alloc::try_with_capacity(voxel_total, "a sparse field's voxels")?;
            for b in baked.iter_mut() {
                if let BrickVoxels::F32(v) = &mut b.voxels {
                    pool.extend_from_slice(v);
                    *v = Vec::new();
                }
            }
            Pool::F32(pool)
        }
        Storage::I16 => {
            let mut pool = crate::alloc::try_with_capacity(voxel_total, "a sparse field's voxels")?;
            for b in baked.iter_mut() {
                if let BrickVoxels::I16(v) = &mut b.voxels {
                    pool.extend_from_slice(v);
                    *v = Vec::new();
                }
            }
            Pool::I16(pool)
        }
    };
    let mut offset = 0usize;
    for (i, (&idx, b)) in active.iter().zip(baked.iter()).enumerate() {
        table[idx] = i as u32;
        let at = top.at(idx);
        bricks.push(Brick {
            at: at.map(|a| a as u32),
            level: b.level,
            offset,
            scale: b.scale,
            apron: b.apron,
        });
        offset += nodes_of(cells_of(b.level), b.apron).pow(3);
    }
    SparseField::new(
        *top,
        table,
        bricks,
        pool,
        bounds,
        ambient,
        BakeProvenance {
            source: source.describe(),
            ..Default::default()
        },
    )
    .map_err(BakeError::Option)
}

/// Give each of `baked` its voxels back from `field`'s pool (to bake some again).
fn disassemble(field: SparseField, baked: &mut [BakedBrick]) {
    for (b, brick) in baked.iter_mut().zip(field.bricks()) {
        let span = brick.offset..brick.offset + brick.voxel_count();
        b.voxels = match field.pool() {
            Pool::F32(p) => BrickVoxels::F32(p[span].to_vec()),
            Pool::I16(p) => BrickVoxels::I16(p[span].to_vec()),
        };
    }
}

/// Bytes of a dense grid at `field`'s finest spacing over the box of its active bricks.
fn dense_equivalent_bytes(field: &SparseField) -> u64 {
    let bricks = field.bricks();
    if bricks.is_empty() {
        return 0;
    }
    let mut lo = [u32::MAX; 3];
    let mut hi = [0u32; 3];
    for b in bricks {
        for a in 0..3 {
            lo[a] = lo[a].min(b.at[a]);
            hi[a] = hi[a].max(b.at[a] + 1);
        }
    }
    let cells = (field.top().edge / field.finest_spacing()).round() as u64;
    (0..3).map(|a| u64::from(hi[a] - lo[a]) * cells + 1).fold(
        field.storage().bytes_per_voxel() as u64,
        u64::saturating_mul,
    )
}
