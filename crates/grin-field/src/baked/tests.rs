//! Unit tests of baked-field sampling: exactness on linear fields, the outside policy,
//! i16 storage, and the macro-cell grid.

use glam::DVec3;

use super::*;

/// A grid holding samples of `f` (delta_n, grad) at every node.
fn grid_of(
    dims: [usize; 3],
    origin: DVec3,
    h: f64,
    f: impl Fn(DVec3) -> [f64; 4],
) -> (GridGeometry, Vec<[f32; 4]>) {
    let g = GridGeometry {
        dims,
        origin,
        spacing: DVec3::splat(h),
    };
    let mut v = Vec::new();
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                v.push(f(g.node_world(i, j, k)).map(|x| x as f32));
            }
        }
    }
    (g, v)
}

fn unit_box() -> Bounds {
    Bounds::Box {
        min: DVec3::ZERO,
        max: DVec3::ONE,
    }
}

#[test]
fn trilinear_reproduces_a_linear_field() {
    let lin = |p: DVec3| [0.01 * p.x - 0.02 * p.y + 0.005 * p.z, 0.01, -0.02, 0.005];
    let (g, v) = grid_of([5, 6, 7], DVec3::ZERO, 0.25, lin);
    let f = BakedField::new(
        g,
        Voxels::F32(v),
        Interp::Trilinear,
        Outside::Clamp,
        unit_box(),
        1.0,
        BakeProvenance::default(),
    )
    .expect("valid grid");
    for p in [
        DVec3::new(0.13, 0.77, 0.5),
        DVec3::new(0.9, 0.1, 0.33),
        DVec3::new(1.0, 1.25, 1.5),
    ] {
        let s = f.sample(p);
        assert!((s.n - 1.0 - lin(p)[0]).abs() < 1e-8, "{p}");
        assert!((s.grad_n - DVec3::new(0.01, -0.02, 0.005)).length() < 1e-8);
    }
    // Clamp: beyond the nodes, the nearest node's value.
    let s = f.sample(DVec3::new(-1.0, 0.5, 0.5));
    assert!((s.n - 1.0 - lin(DVec3::new(0.0, 0.5, 0.5))[0]).abs() < 1e-8);
}

#[test]
fn tricubic_interpolates_the_nodes_and_is_ambient_outside_a_crop() {
    let bump = |p: DVec3| {
        let e = (-(p - DVec3::splat(0.5)).length_squared() / 0.05).exp();
        [0.02 * e, 0.0, 0.0, 0.0]
    };
    let (g, v) = grid_of([9, 9, 9], DVec3::ZERO, 0.125, bump);
    let f = BakedField::new(
        g,
        Voxels::F32(v.clone()),
        Interp::Tricubic,
        Outside::Ambient,
        unit_box(),
        1.0,
        BakeProvenance::default(),
    )
    .expect("valid grid");
    for (idx, (i, j, k)) in [(0, 0, 0), (4, 4, 4), (3, 7, 1), (8, 8, 8)]
        .into_iter()
        .enumerate()
    {
        let p = g.node_world(i, j, k);
        let s = f.sample(p);
        let want = f64::from(v[g.index(i, j, k)][0]);
        assert!(
            (s.n - 1.0 - want).abs() < 1e-7,
            "node {idx}: {} vs {want}",
            s.n - 1.0
        );
    }
    let out = f.sample(DVec3::new(1.2, 0.5, 0.5));
    assert_eq!(out.n, 1.0);
    assert_eq!(out.grad_n, DVec3::ZERO);
}

#[test]
fn i16_storage_rounds_within_half_a_step() {
    let wave = |p: DVec3| {
        [
            1e-4 * (6.0 * p.x).sin(),
            6e-4 * (6.0 * p.x).cos(),
            0.0,
            -2e-5,
        ]
    };
    let (_, v) = grid_of([17, 3, 3], DVec3::ZERO, 1.0 / 16.0, wave);
    let q = Voxels::quantize(&v);
    let scale = q.scale();
    assert_eq!(q.storage(), Storage::I16);
    for (i, x) in v.iter().enumerate() {
        let d = q.get(i);
        for c in 0..4 {
            assert!(
                (d[c] - x[c]).abs() <= 0.5001 * scale[c],
                "voxel {i} channel {c}"
            );
        }
    }
    // The delta_n scale spans exactly the largest |delta_n| (no wasted range).
    let max = v.iter().fold(0.0f32, |m, x| m.max(x[0].abs()));
    assert!(
        (scale[0] * 32767.0 - max).abs() <= max * 1e-6,
        "{} vs {max}",
        scale[0] * 32767.0
    );
}

#[test]
fn bad_grids_are_rejected() {
    let (g, v) = grid_of([4, 4, 4], DVec3::ZERO, 0.25, |_| [0.0; 4]);
    let short = Voxels::F32(v[..10].to_vec());
    let e = BakedField::new(
        g,
        short,
        Interp::Trilinear,
        Outside::Clamp,
        unit_box(),
        1.0,
        BakeProvenance::default(),
    )
    .expect_err("too few voxels");
    assert!(e.to_string().contains("needs 64 voxels, got 10"), "{e}");
    let mut nan = v.clone();
    nan[5][0] = f32::NAN;
    let e = BakedField::new(
        g,
        Voxels::F32(nan),
        Interp::Trilinear,
        Outside::Clamp,
        unit_box(),
        1.0,
        BakeProvenance::default(),
    )
    .expect_err("NaN voxel");
    assert!(e.to_string().contains("voxel 5"), "{e}");
}

/// A blob in one corner of a 64^3 grid: the far cells are homogeneous and a ray there flies
/// straight to the first varying cell; inside the blob there is no straight flight.
#[test]
fn macro_cells_find_homogeneous_runs() {
    let c = DVec3::splat(0.2);
    let blob = |p: DVec3| {
        let r2 = (p - c).length_squared();
        if r2 > 0.01 {
            return [0.0; 4];
        }
        let w = (1.0 - r2 / 0.01).powi(3);
        let dw = -6.0 * (1.0 - r2 / 0.01).powi(2) / 0.01;
        let g = (p - c) * (0.01 * dw);
        [0.01 * w, g.x, g.y, g.z]
    };
    let h = 1.0 / 63.0;
    let (g, v) = grid_of([64, 64, 64], DVec3::ZERO, h, blob);
    for interp in [Interp::Trilinear, Interp::Tricubic] {
        let f = BakedField::new(
            g,
            Voxels::F32(v.clone()),
            interp,
            Outside::Clamp,
            unit_box(),
            1.0,
            BakeProvenance::default(),
        )
        .expect("valid grid");
        let mg = f.macro_grid();
        assert_eq!(mg.dims, [8, 8, 8]);
        // The prefiltered spline rings ~10 voxels out (pole 0.27^k) before it falls below the threshold.
        assert!(
            mg.homogeneous_fraction() > 0.85,
            "{interp:?}: {}",
            mg.homogeneous_fraction()
        );
        assert_eq!(
            f.homogeneous_span(c, DVec3::X),
            None,
            "{interp:?}: inside the blob"
        );
        // Along the diagonal from the far corner towards the blob: the run ends before the
        // blob's support (radius 0.1 around c) plus the interpolation reach.
        let start = DVec3::splat(0.95);
        let dir = (c - start).normalize();
        let span = f
            .homogeneous_span(start, dir)
            .expect("far corner is homogeneous");
        let blob_edge = (c - start).length() - 0.1;
        assert!(
            span <= blob_edge + 1e-9,
            "{interp:?}: span {span} reaches the blob at {blob_edge}"
        );
        assert!(
            span > blob_edge - 2.0 * 8.0 * h * 3f64.sqrt(),
            "{interp:?}: span {span} too short"
        );
        // Every point along the flight sees grad n ~ 0.
        for t in 0..50 {
            let p = start + dir * (span * t as f64 / 50.0);
            assert!(
                f.sample(p).grad_n.length() <= mg.threshold * 1.001,
                "{interp:?}: at {p}"
            );
        }
        // Towards the nearby +x face: the run stops at the grid's edge.
        let s = f
            .homogeneous_span(DVec3::new(0.9, 0.9, 0.9), DVec3::X)
            .expect("homogeneous");
        assert!((s - 0.1).abs() < 1e-9, "{interp:?}: {s}");
    }
}

/// `may_fly` is false exactly where `homogeneous_span` can never give a flight: a field
/// varying in every macro cell of a grid that covers its bounds.
#[test]
fn may_fly_only_where_a_flight_exists() {
    let h = 1.0 / 31.0;
    let wavy = |p: DVec3| {
        let (s, c) = (10.0 * p.x).sin_cos();
        [1e-3 * s + 1e-3 * p.y, 1e-2 * c, 1e-3, 0.0]
    };
    let bake = |bounds: Bounds, outside: Outside, f: &dyn Fn(DVec3) -> [f64; 4]| {
        let (g, v) = grid_of([32, 32, 32], DVec3::ZERO, h, f);
        BakedField::new(
            g,
            Voxels::F32(v),
            Interp::Trilinear,
            outside,
            bounds,
            1.0,
            BakeProvenance::default(),
        )
        .expect("valid grid")
    };
    let varying = bake(unit_box(), Outside::Ambient, &wavy);
    assert_eq!(varying.macro_grid().homogeneous_fraction(), 0.0);
    assert!(!varying.may_fly());
    // Everywhere along a few rays there is no flight either.
    for i in 0..20 {
        let p = DVec3::new(0.05 * i as f64, 0.5, 0.3);
        assert_eq!(varying.homogeneous_span(p, DVec3::Y), None, "at {p}");
    }
    // The same grid cropped inside larger bounds: beyond it the field is ambient and a
    // ray flies to the grid.
    let larger = Bounds::Box {
        min: DVec3::splat(-0.5),
        max: DVec3::splat(1.5),
    };
    let cropped = bake(larger, Outside::Ambient, &wavy);
    assert!(cropped.may_fly());
    let s = cropped
        .homogeneous_span(DVec3::new(-0.25, 0.5, 0.5), DVec3::X)
        .expect("flight to the grid");
    assert!((s - 0.25).abs() < 1e-9, "{s}");
    // Clamped beyond the grid: no flight there.
    assert!(!bake(larger, Outside::Clamp, &wavy).may_fly());
    // A constant field: every cell is homogeneous.
    assert!(bake(unit_box(), Outside::Ambient, &|_| [0.0; 4]).may_fly());

    // A field varying throughout a ball and ambient outside it, on a 64-node grid (8
    // macro cells per axis): the grid's corner cells are homogeneous but lie outside the
    // ball, so a ball-bounded medium has no flight, a box-bounded one has.
    let centre = DVec3::splat(0.5);
    let ball_field = move |p: DVec3| {
        if (p - centre).length() > 0.52 {
            [0.0; 4]
        } else {
            wavy(p)
        }
    };
    let h64 = 1.0 / 63.0;
    let (g, v) = grid_of([64, 64, 64], DVec3::ZERO, h64, ball_field);
    let with = |bounds: Bounds| {
        BakedField::new(
            g,
            Voxels::F32(v.clone()),
            Interp::Trilinear,
            Outside::Ambient,
            bounds,
            1.0,
            BakeProvenance::default(),
        )
        .expect("valid grid")
    };
    let ball = with(Bounds::Sphere {
        center: centre,
        radius: 0.5,
    });
    assert!(ball.macro_grid().homogeneous_fraction() > 0.0);
    assert!(!ball.may_fly());
    assert!(with(unit_box()).may_fly());
}

#[test]
fn to_interp_builds_the_field_with_interp_builds() {
    let bump = |p: DVec3| {
        let e = (-(p - DVec3::splat(0.4)).length_squared() / 0.05).exp();
        [0.02 * e, 0.3 * e, -0.1 * e, 0.05 * e]
    };
    let (g, v) = grid_of([11, 9, 10], DVec3::ZERO, 0.11, bump);
    let f = BakedField::new(
        g,
        Voxels::F32(v),
        Interp::Tricubic,
        Outside::Ambient,
        unit_box(),
        1.0,
        BakeProvenance::default(),
    )
    .expect("valid grid");
    for interp in [Interp::Trilinear, Interp::Tricubic] {
        let a = f.to_interp(interp);
        let b = f.clone().with_interp(interp);
        assert_eq!(a.interp(), interp);
        assert_eq!(a.spline_coefficients(), b.spline_coefficients());
        assert_eq!(a.macro_grid().max_grad, b.macro_grid().max_grad);
        for p in [DVec3::new(0.31, 0.52, 0.47), DVec3::new(0.05, 0.9, 0.2)] {
            let (sa, sb) = (a.sample(p), b.sample(p));
            assert_eq!((sa.n, sa.grad_n), (sb.n, sb.grad_n), "{interp:?} at {p}");
        }
    }
}
