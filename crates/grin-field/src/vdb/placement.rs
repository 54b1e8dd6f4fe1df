//! The affine maths of a grid's placement: [`IDENTITY`], the scene's [`placement()`] of a
//! grid, [`compose`] and `apply` of the 3x4 maps.

use grin_scene::UpAxis;

/// The affine map that changes nothing.
pub const IDENTITY: [[f64; 4]; 3] = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
];

/// The scene's placement of a VDB grid (world = placement * grid metres): first the up
/// axis (a Z-up cache, as Blender writes, is turned so its +z is the scene's +y and its +y
/// the scene's -z), then the uniform `scale`, then rotations by `rotate_deg` about the
/// scene's x, then y, then z axes (right-handed, degrees), then `translate` (metres).
pub fn placement(
    up: UpAxis,
    scale: f64,
    rotate_deg: [f64; 3],
    translate: [f64; 3],
) -> [[f64; 4]; 3] {
    let up_m = match up {
        UpAxis::Y => IDENTITY,
        UpAxis::Z => [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0, 0.0],
        ],
    };
    let scaled = IDENTITY.map(|row| row.map(|v| v * scale));
    let rot = |axis: usize, deg: f64| {
        let (s, c) = deg.to_radians().sin_cos();
        let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
        let mut m = IDENTITY;
        m[a][a] = c;
        m[a][b] = -s;
        m[b][a] = s;
        m[b][b] = c;
        m
    };
    let mut m = compose(&scaled, &up_m);
    for (axis, &deg) in rotate_deg.iter().enumerate() {
        m = compose(&rot(axis, deg), &m);
    }
    for (row, t) in m.iter_mut().zip(translate) {
        row[3] += t;
    }
    m
}

/// The affine map `a` after `b` (a * b).
pub fn compose(a: &[[f64; 4]; 3], b: &[[f64; 4]; 3]) -> [[f64; 4]; 3] {
    std::array::from_fn(|r| {
        std::array::from_fn(|c| {
            let lin: f64 = (0..3).map(|k| a[r][k] * b[k][c]).sum();
            if c == 3 { lin + a[r][3] } else { lin }
        })
    })
}

/// `m` applied to the point `p`.
pub(super) fn apply(m: &[[f64; 4]; 3], p: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2] + m[r][3])
}
