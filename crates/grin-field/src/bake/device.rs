//! How a field is baked for the GPU marcher: f32 grids, trilinear or (where trilinear
//! misses the budget) tricubic, no finer than the error budget needs ([`bake_for_gpu_auto`]), with a warning where even the default
//! resolution under-resolves the field. The policy lives with the baker; grin-gpu only
//! uploads what it is given or what this chooses.

use super::{
    BUDGET_SAFETY, BakeError, BakeOptions, BakeReport, CANDIDATE_RESOLUTIONS, DEFAULT_ERROR_BUDGET,
    bake,
};
use crate::IndexField;
use crate::baked::{BakedField, Interp};

/// Grid resolution (nodes along the longest axis) used to bake an analytic field for the
/// GPU when the caller has no baked field: 128 keeps a unit sphere within ~1e-4 of the
/// analytic index for the paper's profiles (bake helper's DEFAULT_RESOLUTION).
pub const DEFAULT_GPU_BAKE_RESOLUTION: usize = super::DEFAULT_RESOLUTION;

/// Largest grid (bytes of f32 voxels) the automatic GPU bake goes to when the default
/// resolution, trilinear and tricubic, is over the error budget.
pub const GPU_BAKE_MAX_BYTES: u64 = 256 << 20;

/// Bake `field` on a grid for the GPU (trilinear, f32 voxels, fixed resolution).
///
/// A fixed resolution can under-resolve a thin layer (a 128-node grid along a long, flat
/// box): [`bake_for_gpu_with_report`] returns the bake's report too, and
/// [`bake_warning`] says so when its measured error is over [`DEFAULT_ERROR_BUDGET`]
/// (this crate prints nothing: the caller shows the warning).
pub fn bake_for_gpu(field: &dyn IndexField, resolution: usize) -> Result<BakedField, BakeError> {
    bake_for_gpu_with_report(field, resolution).map(|(baked, _)| baked)
}

/// [`bake_for_gpu`] with the baker's report (measured max error relative to the field's
/// delta_n range).
pub fn bake_for_gpu_with_report(
    field: &dyn IndexField,
    resolution: usize,
) -> Result<(BakedField, BakeReport), BakeError> {
    bake_for_gpu_interp(field, resolution, Interp::Trilinear)
}

/// [`bake_for_gpu_with_report`] with the given interpolation (f32 voxels).
pub fn bake_for_gpu_interp(
    field: &dyn IndexField,
    resolution: usize,
    interp: Interp,
) -> Result<(BakedField, BakeReport), BakeError> {
    let opts = BakeOptions {
        resolution: Some(resolution),
        interp,
        storage: Some(crate::baked::Storage::F32),
        ..BakeOptions::default()
    };
    bake(field, &opts, &|_, _, _| {})
}

/// Bake `field` for the GPU with no more nodes than it needs: first trilinear at
/// [`DEFAULT_GPU_BAKE_RESOLUTION`]; over the budget, tricubic on the same grid, then a
/// finer grid of the better one within [`GPU_BAKE_MAX_BYTES`]. If the first meets the default error budget
/// ([`DEFAULT_ERROR_BUDGET`], with the bake's [`BUDGET_SAFETY`] margin), trilinear error
/// falling as h^2 predicts the coarsest candidate resolution that still meets it, which
/// is baked and kept if its measured error confirms it. Over budget at the full
/// resolution, that bake is used and [`bake_warning`] of the report says so. Two bakes
/// at most (the automatic search of `grin bake` would try every coarser candidate first).
///
/// A source with its own sample spacing (a VDB grid) is baked by `grin bake`'s automatic
/// search instead ([`bake_grid_source_for_gpu`]): from coarse grids up to its voxel size,
/// then tricubic at it and 2x and 4x finer, so a blob a dozen voxels wide is not baked on
/// 128 nodes, and a cache whose budget needs 4x its voxels gets them.
pub fn bake_for_gpu_auto(field: &dyn IndexField) -> Result<(BakedField, BakeReport), BakeError> {
    if field.source_spacing().is_some()
        && let Some(baked) = bake_grid_source_for_gpu(field)?
    {
        return Ok(baked);
    }
    let full = bake_for_gpu_with_report(field, DEFAULT_GPU_BAKE_RESOLUTION)?;
    let goal = DEFAULT_ERROR_BUDGET * BUDGET_SAFETY;
    let rel = full.1.relative_error;
    if rel > goal {
        // Trilinear is 2nd order. The prefiltered tricubic B-spline of the same grid is
        // 4th order in the same memory (it reads 64 texels a sample instead of 8): the
        // better of the two is kept, and warned about if still over the budget.
        let cubic = bake_for_gpu_interp(field, DEFAULT_GPU_BAKE_RESOLUTION, Interp::Tricubic)?;
        let best = if cubic.1.relative_error < rel {
            cubic
        } else {
            full
        };
        let rel = best.1.relative_error;
        if rel <= goal {
            return Ok(best);
        }
        // Still over: a finer grid, as fine as the error's order predicts (h^2 or h^4,
        // 10% margin), within GPU_BAKE_MAX_BYTES.
        let order = match best.1.interp {
            Interp::Trilinear => 2.0,
            Interp::Tricubic => 4.0,
        };
        let res = DEFAULT_GPU_BAKE_RESOLUTION as f64;
        let wanted = res * (rel / goal).powf(1.0 / order) * 1.1;
        let fits = res * (GPU_BAKE_MAX_BYTES as f64 / best.1.bytes.max(1) as f64).cbrt();
        // No finer than a grid source's own spacing (a VDB's voxels): past it the bake
        // resolves the source's interpolation, not its data.
        let spacing = grid_spacing(&best.1);
        let at_source = field
            .source_spacing()
            .map_or(f64::INFINITY, |h| (res * spacing / h).ceil());
        let finer = wanted.min(fits).min(at_source).floor() as usize;
        let mut chosen = if finer <= DEFAULT_GPU_BAKE_RESOLUTION + 8 {
            best
        } else {
            let fine = bake_for_gpu_interp(field, finer, best.1.interp)?;
            if fine.1.relative_error < rel {
                fine
            } else {
                best
            }
        };
        chosen.1.source_limited = chosen.1.relative_error > DEFAULT_ERROR_BUDGET
            && field
                .source_spacing()
                .is_some_and(|h| grid_spacing(&chosen.1) <= h * 1.0001);
        return Ok(chosen);
    }
    let predicted = if rel > 0.0 {
        DEFAULT_GPU_BAKE_RESOLUTION as f64 * (rel / goal).sqrt()
    } else {
        0.0
    };
    let Some(&coarse) = CANDIDATE_RESOLUTIONS
        .iter()
        .find(|&&r| r as f64 >= predicted && r < DEFAULT_GPU_BAKE_RESOLUTION)
    else {
        return Ok(full);
    };
    let small = bake_for_gpu_with_report(field, coarse)?;
    Ok(if small.1.relative_error <= goal {
        small
    } else {
        full
    })
}

/// The GPU bake of a source with its own spacing: `grin bake`'s automatic search with f32
/// voxels and the GPU's memory cap ([`GPU_BAKE_MAX_BYTES`]). `None` when the search ends
/// at the memory cap before the source's voxel size without meeting the budget (the
/// caller bakes as for any field, with its warning).
fn bake_grid_source_for_gpu(
    field: &dyn IndexField,
) -> Result<Option<(BakedField, BakeReport)>, BakeError> {
    let opts = BakeOptions {
        storage: Some(crate::baked::Storage::F32),
        max_memory: GPU_BAKE_MAX_BYTES,
        cubic_past_source: true,
        ..BakeOptions::default()
    };
    match bake(field, &opts, &|_, _, _| {}) {
        Ok(baked) => Ok(Some(baked)),
        Err(BakeError::BudgetNotMet { .. }) => Ok(None),
        Err(e) => Err(e),
    }
}

/// A one-line warning when a GPU bake's measured error is over the default budget
/// ([`DEFAULT_ERROR_BUDGET`] of the delta_n range), naming the grid, its spacing and the
/// error; `None` when the bake meets the budget.
pub fn bake_warning(report: &BakeReport) -> Option<String> {
    if report.relative_error <= DEFAULT_ERROR_BUDGET {
        return None;
    }
    let [nx, ny, nz] = report.dims;
    let spacing = grid_spacing(report);
    let interp = report.interp.name();
    if report.source_limited {
        return Some(format!(
            "the GPU field bake ({nx}x{ny}x{nz} nodes {interp}, spacing {spacing:.3}) is at the source grid's own voxel size; its max |n error| {:.3e} = {:.2}% of the delta_n range is {interp} against grin's Catmull-Rom between the same voxels, not missing data: GPU and CPU images differ by that much at sharp edges of the data",
            report.errors.max_err_n,
            report.relative_error * 100.0,
        ));
    }
    Some(format!(
        "the GPU field bake ({nx}x{ny}x{nz} nodes {interp}, spacing {spacing:.3}) has max |n error| {:.3e} = {:.2}% of the delta_n range {:.3e} ({:.0}x the budget of {}%): the field is under-resolved and the GPU image will differ from the CPU's; shrink the medium's bounds to where the field matters, or bake a finer grid (`grin bake SCENE --resolution N -o field.grinf`) and use it (`field = {{ kind = \"baked\", path = \"field.grinf\" }}`)",
        report.errors.max_err_n,
        report.relative_error * 100.0,
        report.delta_n_range,
        report.relative_error / DEFAULT_ERROR_BUDGET,
        DEFAULT_ERROR_BUDGET * 100.0,
    ))
}

/// The node spacing of a bake's grid (cubic cells).
fn grid_spacing(report: &BakeReport) -> f64 {
    (report.grid_max.x - report.grid_min.x) / (report.dims[0].max(2) - 1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Bounds;
    use crate::analytic::ExponentialAtmosphere;
    use glam::DVec3;
    use grin_scene::Axis;

    /// An exponential hot layer (scale height `h`) over a box `len` long and 1.6 tall.
    fn layer(len: f64, h: f64) -> ExponentialAtmosphere {
        let bounds = Bounds::Box {
            min: DVec3::new(-len / 2.0, -0.1, 0.0),
            max: DVec3::new(len / 2.0, 1.5, len),
        };
        ExponentialAtmosphere::new(bounds, 1.0, -6e-4, h, 0.0, Axis::Y).expect("valid layer")
    }

    #[test]
    fn thin_layer_in_long_box_is_reported_under_resolved() {
        // The old mirage scene: a 120-unit box at 128 nodes (spacing ~0.95) against a
        // 0.15 scale height; its n error is hundreds of times the budget.
        let (_, report) =
            bake_for_gpu_with_report(&layer(120.0, 0.15), DEFAULT_GPU_BAKE_RESOLUTION)
                .expect("bake");
        assert!(
            report.relative_error > 100.0 * DEFAULT_ERROR_BUDGET,
            "{report:?}"
        );
        let w = bake_warning(&report).expect("a warning");
        assert!(
            w.contains("under-resolved") && w.contains("spacing 0.94"),
            "{w}"
        );
    }

    #[test]
    fn resolved_layer_has_no_warning() {
        // 11.5 nodes per scale height: trilinear error (h/H)^2/8 ~ 1e-3 of the range.
        let (_, report) =
            bake_for_gpu_with_report(&layer(1.5, 0.15), DEFAULT_GPU_BAKE_RESOLUTION).expect("bake");
        assert!(report.relative_error <= DEFAULT_ERROR_BUDGET, "{report:?}");
        assert_eq!(bake_warning(&report), None);
    }

    /// The GPU bakes no more than the field needs: a smooth lens meets the budget on a
    /// coarser grid than 128 nodes (and the coarse grid's measured error says so); a
    /// field no grid up to 128 resolves keeps 128 nodes and its warning.
    #[test]
    fn automatic_gpu_bake_is_as_coarse_as_the_budget_allows() {
        let lens = crate::analytic::Luneburg::new(
            Bounds::Sphere {
                center: DVec3::ZERO,
                radius: 1.0,
            },
            1.0,
            None,
        )
        .expect("lens");
        let (_, full) = bake_for_gpu_with_report(&lens, DEFAULT_GPU_BAKE_RESOLUTION).expect("bake");
        let (_, auto) = bake_for_gpu_auto(&lens).expect("bake");
        assert!(auto.resolution < DEFAULT_GPU_BAKE_RESOLUTION, "{auto:?}");
        assert!(auto.relative_error <= DEFAULT_ERROR_BUDGET * BUDGET_SAFETY);
        assert!(
            auto.bytes * 2 < full.bytes,
            "{} vs {}",
            auto.bytes,
            full.bytes
        );

        // Over the budget at every grid within the memory cap: the finest it reached,
        // within the cap, and the warning.
        let (_, thin) = bake_for_gpu_auto(&layer(120.0, 0.15)).expect("bake");
        assert!(thin.resolution > DEFAULT_GPU_BAKE_RESOLUTION, "{thin:?}");
        assert!(thin.bytes <= GPU_BAKE_MAX_BYTES, "{}", thin.bytes);
        assert!(bake_warning(&thin).is_some());
    }
}
