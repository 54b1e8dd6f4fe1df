//! Where a grid's data is: [`DataBox`] (the voxels that change the index), found over a
//! file's grid by [`locate_data`] and checked against the medium's bounds.

use glam::{DAffine3, DVec3};
use vdb_sys::{IndexBox, VdbFile};

use super::bricks::Bricks;
use crate::bounds::Bounds;
use crate::field::FieldError;

/// Voxels whose change from the background is at most this fraction of the largest change
/// count as background when framing the data (faint residue is not what a user frames).
pub const DATA_FRACTION: f64 = 1e-3;

/// Where scalar grid `grid` of `file` has its data ([`DataBox`]: the voxels whose change
/// from the background is above [`DATA_FRACTION`] of the largest), read a brick at a
/// time over the box OpenVDB gives for its non-background values (else its active box),
/// keeping only the bricks that change anything: `Ok(None)` where no value leaves the
/// background. `max_bytes` caps the bricks kept and the box at one voxel a byte.
pub fn locate_data(
    file: &VdbFile,
    grid: &vdb_sys::GridInfo,
    max_bytes: u64,
) -> Result<Option<DataBox>, String> {
    let Some(bbox) = grid.data_bbox.or(grid.active_bbox) else {
        return Ok(None);
    };
    if bbox.voxel_count() > u128::from(max_bytes) {
        return Err(format!(
            "its data box {:?}..={:?} is {} voxels, more than the {max_bytes} read here",
            bbox.min,
            bbox.max,
            bbox.voxel_count()
        ));
    }
    let mut read = |part: IndexBox, out: &mut Vec<f32>| -> Result<(), String> {
        *out = file
            .read_scalar(&grid.name, part, max_bytes)
            .map_err(|e| e.to_string())?
            .values;
        Ok(())
    };
    let change = Bricks::read(
        bbox,
        grid.background,
        max_bytes,
        &mut read,
        |_, v| {
            let d = (f64::from(v) - grid.background).abs();
            Ok(if d.is_finite() { d } else { 0.0 })
        },
        || format!("its non-background voxels need more than the {max_bytes} bytes read here"),
    )?;
    Ok(change.data_box(DATA_FRACTION))
}

/// The index box of a grid's data: the voxels whose change from the background is above
/// [`DATA_FRACTION`] of the largest change.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DataBox {
    /// Inclusive index bounds (the grid's own index space).
    pub min: [i64; 3],
    pub max: [i64; 3],
}

impl DataBox {
    /// The data box of `change` (|value - background| per voxel, x fastest over `dims`,
    /// starting at index `min_index`); `None` when no voxel changes anything.
    pub fn find(change: &[f64], dims: [usize; 3], min_index: [i32; 3]) -> Option<DataBox> {
        Self::find_above(change, dims, min_index, DATA_FRACTION)
    }

    /// The box of the voxels whose change is above `fraction` of the largest (0: every
    /// voxel that changes anything).
    pub fn find_above(
        change: &[f64],
        dims: [usize; 3],
        min_index: [i32; 3],
        fraction: f64,
    ) -> Option<DataBox> {
        let peak = change
            .iter()
            .filter(|d| d.is_finite())
            .fold(0.0f64, |a, d| a.max(d.abs()));
        if peak == 0.0 {
            return None;
        }
        let mut lo = [usize::MAX; 3];
        let mut hi = [0usize; 3];
        for (off, &d) in change.iter().enumerate() {
            // NaN compares false: not data.
            if d.abs().partial_cmp(&(fraction * peak)) != Some(std::cmp::Ordering::Greater) {
                continue;
            }
            let ijk = [
                off % dims[0],
                (off / dims[0]) % dims[1],
                off / (dims[0] * dims[1]),
            ];
            for a in 0..3 {
                lo[a] = lo[a].min(ijk[a]);
                hi[a] = hi[a].max(ijk[a]);
            }
        }
        (lo[0] != usize::MAX).then(|| DataBox {
            min: std::array::from_fn(|a| lo[a] as i64 + i64::from(min_index[a])),
            max: std::array::from_fn(|a| hi[a] as i64 + i64::from(min_index[a])),
        })
    }

    /// World box of the box's voxel centres widened by `pad` voxels, through the affine
    /// `world_from_index`.
    pub fn world(&self, world_from_index: &DAffine3, pad: f64) -> (DVec3, DVec3) {
        let (mut lo, mut hi) = (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN));
        for c in 0..8 {
            let ijk: [f64; 3] = std::array::from_fn(|a| {
                if c >> a & 1 == 0 {
                    self.min[a] as f64 - pad
                } else {
                    self.max[a] as f64 + pad
                }
            });
            let w = world_from_index.transform_point3(DVec3::from_array(ijk));
            lo = lo.min(w);
            hi = hi.max(w);
        }
        (lo, hi)
    }

    /// The `bounds` line of a scene that holds the data (half a voxel past the centres).
    pub fn bounds_line(&self, world_from_index: &DAffine3) -> String {
        let (lo, hi) = self.world(world_from_index, 0.5);
        format!(
            "bounds = {{ box = {{ min = {}, max = {} }} }}",
            fmt3(lo),
            fmt3(hi)
        )
    }
}

fn fmt3(v: DVec3) -> String {
    format!("[{:.4}, {:.4}, {:.4}]", v.x, v.y, v.z)
}

/// Where the grid's data ([`DataBox`]) lies against the medium's bounds: bounds that miss
/// it are an error, bounds that cut it and data that changes nothing are warnings,
/// returned. Each names the data's world box and a `bounds` line that holds it.
pub(super) fn check_data_placement(
    label: &str,
    data: Option<DataBox>,
    world_from_index: &DAffine3,
    bounds: &Bounds,
) -> Result<Vec<String>, FieldError> {
    let Some(data) = data else {
        return Ok(vec![format!(
            "{label}: every voxel maps to the background's index (a constant grid, or a mapping that changes nothing): the medium bends no ray"
        )]);
    };
    // The data's world box through its voxel centres (what the bounds must hold), and
    // half a voxel out (what the suggested bounds give).
    let (lo, hi) = data.world(world_from_index, 0.0);
    let (plo, phi) = data.world(world_from_index, 0.5);
    let fix = data.bounds_line(world_from_index);
    if !bounds.meets_box(lo, hi, 0.0) {
        return Err(FieldError::Param {
            field: label.to_owned(),
            param: "bounds".into(),
            message: format!(
                "the [medium] bounds miss the grid's data, which lies in world box {} .. {}; to hold it: {fix}",
                fmt3(plo),
                fmt3(phi)
            ),
        });
    }
    let corners_inside = (0..8).all(|c: u32| {
        let p = DVec3::new(
            if c & 1 == 0 { lo.x } else { hi.x },
            if c & 2 == 0 { lo.y } else { hi.y },
            if c & 4 == 0 { lo.z } else { hi.z },
        );
        bounds.signed_distance(p) <= 1e-9 * (1.0 + p.length())
    });
    Ok(if corners_inside {
        Vec::new()
    } else {
        vec![format!(
            "{label}: the [medium] bounds cut the grid's data (world box {} .. {}): rays see only the part inside; to hold it all: {fix}",
            fmt3(plo),
            fmt3(phi)
        )]
    })
}
