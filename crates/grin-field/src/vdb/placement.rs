//! Where a grid goes in the scene, as glam's [`DAffine3`]: [`IDENTITY`], the scene's
//! [`placement()`] of a grid, and [`affine_from_rows`] for a grid's own transform.

use glam::{DAffine3, DVec3};
use grin_scene::UpAxis;

/// The affine map that changes nothing.
pub const IDENTITY: DAffine3 = DAffine3::IDENTITY;

/// The scene's placement of a VDB grid (world = placement * grid metres): first the up
/// axis (a Z-up cache, as Blender writes, is turned so its +z is the scene's +y and its +y
/// the scene's -z), then the uniform `scale`, then rotations by `rotate_deg` about the
/// scene's x, then y, then z axes (right-handed, degrees), then `translate` (metres).
pub fn placement(up: UpAxis, scale: f64, rotate_deg: [f64; 3], translate: [f64; 3]) -> DAffine3 {
    let up_m = match up {
        UpAxis::Y => IDENTITY,
        // Columns: grid +x -> +x, grid +y -> -z, grid +z -> +y.
        UpAxis::Z => DAffine3::from_cols(DVec3::X, DVec3::NEG_Z, DVec3::Y, DVec3::ZERO),
    };
    let rotations = [
        DAffine3::from_rotation_x,
        DAffine3::from_rotation_y,
        DAffine3::from_rotation_z,
    ];
    let mut m = DAffine3::from_scale(DVec3::splat(scale)) * up_m;
    for (rotation, deg) in rotations.iter().zip(rotate_deg) {
        m = rotation(deg.to_radians()) * m;
    }
    m.translation += DVec3::from_array(translate);
    m
}

/// The affine map of a row-major 3x4 `[A | t]` (a grid's `world_from_index` as vdb-sys
/// reads it: world = A * ijk + t).
pub fn affine_from_rows(rows: &[[f64; 4]; 3]) -> DAffine3 {
    let column = |c: usize| DVec3::new(rows[0][c], rows[1][c], rows[2][c]);
    DAffine3::from_cols(column(0), column(1), column(2), column(3))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The affine map of a grid's rows places points as the grid's transform does, and
    /// its inverse undoes it.
    #[test]
    fn affine_from_rows_maps_as_the_grid_transform() {
        let xf = vdb_sys::Transform {
            world_from_index: [
                [0.04, 0.01, 0.0, -0.3],
                [0.0, 0.05, 0.0, 0.7],
                [0.005, 0.0, 0.06, -1.1],
            ],
        };
        let m = affine_from_rows(&xf.world_from_index);
        for ijk in [[0.0, 0.0, 0.0], [1.0, 2.0, 3.0], [-4.5, 0.25, 7.0]] {
            let w = m.transform_point3(DVec3::from_array(ijk));
            assert_eq!(w.to_array(), xf.index_to_world(ijk), "{ijk:?}");
            let back = m.inverse().transform_point3(w);
            assert!((back - DVec3::from_array(ijk)).length() < 1e-12, "{back}");
        }
    }
}
