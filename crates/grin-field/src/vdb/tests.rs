//! Unit tests of [`VdbField`](super::VdbField): interpolation, mapping checks, crop,
//! placement and the ambient index, on dense grids built here.

use glam::{DAffine3, DVec3};
use grin_scene::{NonFinitePolicy, UpAxis};
use vdb_sys::{DenseGrid, IndexBox, Transform};

use super::mapping::tests::gd_default;
use super::*;
use crate::bounds::Bounds;
use crate::field::IndexField;

fn params(mapping: Mapping, ambient: f64) -> VdbFieldParams {
    VdbFieldParams {
        mapping,
        units: 1.0,
        non_finite: NonFinitePolicy::Reject,
        bounds: Bounds::Sphere {
            center: DVec3::ZERO,
            radius: 10.0,
        },
        ambient: Some(ambient),
        max_bytes: DEFAULT_MAX_DENSE_BYTES,
        placement: IDENTITY,
    }
}

fn cube(values: impl Fn(i32, i32, i32) -> f32, n: i32, xf: Transform) -> DenseGrid<f32> {
    let bbox = IndexBox {
        min: [-n, -n + 1, -n + 2],
        max: [n, n + 1, n + 2],
    };
    let mut v = Vec::new();
    for k in bbox.min[2]..=bbox.max[2] {
        for j in bbox.min[1]..=bbox.max[1] {
            for i in bbox.min[0]..=bbox.max[0] {
                v.push(values(i, j, k));
            }
        }
    }
    DenseGrid {
        bbox,
        world_from_index: xf,
        values: v,
    }
}

#[test]
fn catmull_rom_is_exact_for_quadratics_and_honours_transform_and_units() {
    // delta_n = q(world) with q quadratic: Catmull-Rom reproduces it (and its gradient)
    // exactly away from the box edges, under a non-uniform, rotated, offset transform.
    let xf = Transform {
        world_from_index: [
            [0.04, 0.01, 0.0, -0.3],
            [0.0, 0.05, 0.0, 0.7],
            [0.005, 0.0, 0.06, -1.1],
        ],
    };
    let units = 2.0;
    let q = |p: DVec3| 1e-3 * (0.5 * p.x * p.x - 0.3 * p.y * p.z + 0.2 * p.z + 0.1);
    let grad_q = |p: DVec3| 1e-3 * DVec3::new(p.x, -0.3 * p.z, -0.3 * p.y + 0.2);
    let world = |i: i32, j: i32, k: i32| {
        DVec3::from_array(xf.index_to_world([f64::from(i), f64::from(j), f64::from(k)])) * units
    };
    let dense = cube(|i, j, k| q(world(i, j, k)) as f32, 6, xf);
    // Recompute with f32-rounded nodes: compare against the f64 polynomial with a
    // tolerance covering the f32 storage (values ~1e-3 -> ~1e-10).
    let mut p = params(Mapping::Index { delta: true }, 1.0);
    p.units = units;
    let f = VdbField::from_dense("quad".into(), &dense, 0.0, &p).expect("field");
    for &(i, j, k) in &[(0.3, 1.7, 2.2), (-1.5, 0.25, 3.9), (2.0, 2.0, 2.0)] {
        let w = f.world_from_index(DVec3::new(i, j, k));
        let s = f.sample(w);
        assert!(
            (s.n - 1.0 - q(w)).abs() < 1e-9,
            "n at {w}: {} vs {}",
            s.n - 1.0,
            q(w)
        );
        assert!(
            (s.grad_n - grad_q(w)).length() < 1e-7,
            "grad at {w}: {} vs {}",
            s.grad_n,
            grad_q(w)
        );
        // Index/world round trip, world in metres = units * VDB world.
        let back = f.index_from_world(w);
        assert!((back - DVec3::new(i, j, k)).length() < 1e-12);
    }
    let w = f.world_from_index(DVec3::new(1.0, 2.0, 3.0));
    let raw = xf.index_to_world([1.0, 2.0, 3.0]);
    assert!((w - DVec3::from_array(raw) * units).length() < 1e-12);
}

#[test]
fn gradient_matches_finite_difference_of_n() {
    // The gradient is the derivative of the interpolant itself (a conservative field).
    let xf = Transform::uniform(0.1, [0.2, -0.1, 0.0]);
    let dense = cube(
        |i, j, k| (0.01 * ((i * 7 + j * 3 - k * 5) % 11) as f32).sin(),
        4,
        xf,
    );
    let f = VdbField::from_dense(
        "bumpy".into(),
        &dense,
        0.0,
        &params(Mapping::Linear { k: 0.01 }, 1.2),
    )
    .expect("field");
    let e = 1e-6;
    for p in [DVec3::new(0.23, 0.05, 0.31), DVec3::new(-0.12, 0.27, 0.13)] {
        let g = f.sample(p).grad_n;
        let fd = DVec3::new(
            f.n(p + DVec3::X * e) - f.n(p - DVec3::X * e),
            f.n(p + DVec3::Y * e) - f.n(p - DVec3::Y * e),
            f.n(p + DVec3::Z * e) - f.n(p - DVec3::Z * e),
        ) / (2.0 * e);
        assert!((g - fd).length() < 1e-7 * (1.0 + g.length()), "{g} vs {fd}");
    }
}

#[test]
fn non_finite_voxels_are_rejected_or_replaced_with_a_count() {
    let xf = Transform::uniform(0.1, [0.0; 3]);
    let dense = cube(
        |i, j, k| match (i, j, k) {
            (0, 1, 2) => f32::NAN,
            (1, 1, 2) => f32::INFINITY,
            _ => 0.5,
        },
        2,
        xf,
    );
    let gd = Mapping::GladstoneDale(gd_default());
    let ambient = gd.n(0.0, 1.0).expect("ambient");
    let mut p = params(gd, ambient);
    let e = VdbField::from_dense("nf".into(), &dense, 0.0, &p).expect_err("rejected");
    assert!(e.to_string().contains("2 NaN/Inf voxel(s)"), "{e}");
    p.non_finite = NonFinitePolicy::Ambient;
    let f = VdbField::from_dense("nf".into(), &dense, 0.0, &p).expect("replaced");
    assert_eq!(f.non_finite_replaced(), 2);
    let at = f.sample(f.world_from_index(DVec3::new(0.0, 1.0, 2.0)));
    assert!(
        (at.n - ambient).abs() < 1e-15,
        "replaced voxel holds ambient"
    );
    assert!(f.describe().contains("2 NaN/Inf voxels replaced"));
}

#[test]
fn background_must_map_to_the_ambient_index() {
    let xf = Transform::uniform(0.1, [0.0; 3]);
    let dense = cube(|_, _, _| 0.1, 2, xf);
    let e = VdbField::from_dense(
        "gd".into(),
        &dense,
        0.0,
        &params(Mapping::GladstoneDale(gd_default()), 1.0),
    )
    .expect_err("mismatch");
    assert!(e.to_string().contains("ambient_index = 1.000272"), "{e}");
}

/// Max |n error| and max |grad n error| of a Gaussian (width s) sampled at voxel size
/// s / per_s, over points of the inner ball.
fn gaussian_errors(per_s: f64) -> (f64, f64) {
    let (a, s) = (1e-3, 0.2);
    let h = s / per_s;
    let half = (2.5 * per_s).ceil() as i32;
    let xf = Transform::uniform(h, [0.0; 3]);
    let f = |p: DVec3| a * (-p.length_squared() / (s * s)).exp();
    let bbox = IndexBox {
        min: [-half; 3],
        max: [half; 3],
    };
    let mut values = Vec::new();
    for k in -half..=half {
        for j in -half..=half {
            for i in -half..=half {
                let p = DVec3::new(f64::from(i), f64::from(j), f64::from(k)) * h;
                values.push(f(p) as f32);
            }
        }
    }
    let dense = DenseGrid {
        bbox,
        world_from_index: xf,
        values,
    };
    let field = VdbField::from_dense(
        "gauss".into(),
        &dense,
        0.0,
        &params(Mapping::Index { delta: true }, 1.0),
    )
    .expect("field");
    let (mut en, mut eg) = (0.0f64, 0.0f64);
    for i in 0..4000 {
        // A deterministic spiral of points within 1.5 s of the centre.
        let t = f64::from(i) * 0.618_033_988_75;
        let r = 1.5 * s * (f64::from(i) / 4000.0).cbrt();
        let z = 1.0 - 2.0 * (f64::from(i) + 0.5) / 4000.0;
        let q = (1.0 - z * z).sqrt();
        let p = DVec3::new(
            q * (t * std::f64::consts::TAU).cos(),
            q * (t * std::f64::consts::TAU).sin(),
            z,
        ) * r;
        let smp = field.sample(p);
        let g = p * (-2.0 * f(p) / (s * s));
        en = en.max((smp.n - 1.0 - f(p)).abs());
        eg = eg.max((smp.grad_n - g).length());
    }
    (en / a, eg / (a / s))
}

/// A step-edged block (hot: delta_n = -1e-3 inside, 0 outside): Catmull-Rom alone
/// rings past both ends; the field never leaves [ambient - 1e-3, ambient], is exactly
/// ambient one voxel outside the block, and a bake of it keeps that range.
#[test]
fn interpolant_stays_in_the_mapped_range() {
    let xf = Transform {
        world_from_index: [
            [0.1, 0.0, 0.0, 0.0],
            [0.0, 0.1, 0.0, 0.0],
            [0.0, 0.0, 0.1, 0.0],
        ],
    };
    let inside = |i: i32, j: i32, k: i32| i.abs() <= 3 && (j - 1).abs() <= 3 && (k - 2).abs() <= 3;
    let dense = cube(|i, j, k| if inside(i, j, k) { -1e-3 } else { 0.0 }, 8, xf);
    let field = VdbField::from_dense(
        "block".into(),
        &dense,
        0.0,
        &params(Mapping::Index { delta: true }, 1.0),
    )
    .expect("field");
    let (mut lo, mut hi) = (f64::MAX, f64::MIN);
    let mut rung = 0;
    for i in 0..=120 {
        for j in 0..=40 {
            let p = DVec3::new(-0.6 + 0.01 * f64::from(i), -0.3 + 0.03 * f64::from(j), 0.2);
            let smp = field.sample(p);
            lo = lo.min(smp.n);
            hi = hi.max(smp.n);
            let (raw, _) = field.catmull_rom({
                let idx = field.index_from_world(p);
                [
                    idx.x - f64::from(field.bbox.min[0]),
                    idx.y - f64::from(field.bbox.min[1]),
                    idx.z - f64::from(field.bbox.min[2]),
                ]
            });
            if !(-1e-3..=0.0).contains(&raw) {
                rung += 1;
            }
        }
    }
    assert!(rung > 0, "Catmull-Rom alone rings at the edge");
    let floor = 1.0 + f64::from(-1e-3f32);
    assert!(lo >= floor && hi <= 1.0, "n in [{lo}, {hi}]");
    // One voxel and a half outside the block's face (x = 0.3): exactly ambient.
    let out = field.sample(DVec3::new(0.45, 0.1, 0.2));
    assert_eq!(out.n, 1.0);
    assert_eq!(out.grad_n, DVec3::ZERO);
    // The bake of it stays in range too.
    let opts = crate::bake::BakeOptions {
        resolution: Some(32),
        ..Default::default()
    };
    let (baked, report) = crate::bake::bake(&field, &opts, &|_, _, _| {}).expect("bake");
    let (blo, bhi) = crate::field::IndexField::n_range(&baked);
    assert!(
        blo >= floor - 1e-9 && bhi <= 1.0 + 1e-9,
        "baked [{blo}, {bhi}], {report:?}"
    );
}

/// Bounds that miss the data are refused with the data's world box and a bounds line
/// that holds it; bounds that cut it load (with a warning).
#[test]
fn bounds_that_miss_the_data_are_refused_with_where_it_is() {
    let xf = Transform {
        world_from_index: [
            [0.1, 0.0, 0.0, 5.0],
            [0.0, 0.1, 0.0, 0.0],
            [0.0, 0.0, 0.1, 0.0],
        ],
    };
    let dense = cube(|i, _, _| if i.abs() <= 2 { -1e-3 } else { 0.0 }, 4, xf);
    let mut far = params(Mapping::Index { delta: true }, 1.0);
    far.bounds = Bounds::Sphere {
        center: DVec3::ZERO,
        radius: 1.0,
    };
    let msg = match VdbField::from_dense("blob".into(), &dense, 0.0, &far) {
        Ok(_) => panic!("the bounds are far from x = 5"),
        Err(e) => e.to_string(),
    };
    assert!(
        msg.contains("miss the grid's data") && msg.contains("bounds = { box = { min = [4.7500"),
        "{msg}"
    );
    let mut cut = params(Mapping::Index { delta: true }, 1.0);
    cut.bounds = Bounds::Box {
        min: DVec3::new(4.9, -1.0, -1.0),
        max: DVec3::new(6.0, 1.0, 1.0),
    };
    let cut_field = VdbField::from_dense("blob".into(), &dense, 0.0, &cut).expect("loads");
    let warnings = cut_field.warnings();
    assert!(
        warnings.len() == 1
            && warnings[0].starts_with("blob: the [medium] bounds cut the grid's data")
            && warnings[0].contains("to hold it all: bounds = { box = { min = [4.7500"),
        "{warnings:?}"
    );
    // Bounds that hold it all: nothing to say.
    let held = VdbField::from_dense(
        "blob".into(),
        &dense,
        0.0,
        &params(Mapping::Index { delta: true }, 1.0),
    )
    .expect("loads");
    assert!(held.warnings().is_empty(), "{:?}", held.warnings());
}

/// The stated interpolation error: O(h^3) in n and O(h^2) in grad n (Catmull-Rom).
#[test]
fn catmull_rom_converges_at_third_order_in_n_and_second_in_grad() {
    let (n1, g1) = gaussian_errors(4.0);
    let (n2, g2) = gaussian_errors(8.0);
    let (n3, g3) = gaussian_errors(16.0);
    let order = |e1: f64, e2: f64| (e1 / e2).log2();
    let (on, og) = (order(n2, n3), order(g2, g3));
    eprintln!(
        "Catmull-Rom on a Gaussian, s/h = 4, 8, 16: n error {n1:.2e} {n2:.2e} {n3:.2e} \
         (order {on:.2}), grad error {g1:.2e} {g2:.2e} {g3:.2e} (order {og:.2})"
    );
    assert!(on > 2.6, "n order {on} ({n1:.2e}, {n2:.2e}, {n3:.2e})");
    assert!(og > 1.8, "grad order {og} ({g1:.2e}, {g2:.2e}, {g3:.2e})");
    // 10 voxels per width: the level tests/vdb.rs relies on.
    let (n10, g10) = gaussian_errors(10.0);
    assert!(
        n10 < 5e-4 && g10 < 2e-2,
        "s/h = 10: n {n10:.2e}, grad {g10:.2e}"
    );
}

/// The placement: a Z-up point turns to +y, a 90 degree turn about +y takes +x to -z
/// (right-handed), scale and translate come after; composed on the grid's transform.
#[test]
fn placement_turns_scales_rotates_then_translates() {
    let at = |m: &DAffine3, p: [f64; 3]| m.transform_point3(DVec3::from_array(p));
    let close = |a: DVec3, b: DVec3| (a - b).length() < 1e-12;
    let up = placement(UpAxis::Z, 1.0, [0.0; 3], [0.0; 3]);
    assert!(close(at(&up, [0.0, 0.0, 1.0]), DVec3::Y));
    assert!(close(at(&up, [0.0, 1.0, 0.0]), -DVec3::Z));
    assert!(close(at(&up, [1.0, 0.0, 0.0]), DVec3::X));
    let m = placement(UpAxis::Y, 2.0, [0.0, 90.0, 0.0], [1.0, 2.0, 3.0]);
    assert!(close(at(&m, [1.0, 0.0, 0.0]), DVec3::new(1.0, 2.0, 1.0)));
    assert!(close(at(&m, [0.0, 1.0, 0.0]), DVec3::new(1.0, 4.0, 3.0)));
    let rz = placement(UpAxis::Y, 1.0, [0.0, 0.0, 90.0], [0.0; 3]);
    assert!(close(at(&rz, [1.0, 0.0, 0.0]), DVec3::Y));
    let rx = placement(UpAxis::Y, 1.0, [90.0, 0.0, 0.0], [0.0; 3]);
    assert!(close(at(&rx, [0.0, 1.0, 0.0]), DVec3::Z));
    // x first, then y: (0, 1, 0) -> (0, 0, 1) -> (1, 0, 0).
    let rxy = placement(UpAxis::Y, 1.0, [90.0, 90.0, 0.0], [0.0; 3]);
    assert!(close(at(&rxy, [0.0, 1.0, 0.0]), DVec3::X));

    // Through a field: the voxel at index 0 of a unit grid, placed, lands there.
    let xf = Transform::uniform(1.0, [0.0; 3]);
    let dense = cube(
        |i, j, k| if (i, j, k) == (0, 0, 0) { 1e-3 } else { 0.0 },
        3,
        xf,
    );
    let mut prm = params(Mapping::Index { delta: true }, 1.0);
    prm.placement = placement(UpAxis::Z, 0.5, [0.0, 0.0, 0.0], [10.0, 0.0, 0.0]);
    prm.bounds = Bounds::Sphere {
        center: DVec3::new(10.0, 0.0, 0.0),
        radius: 5.0,
    };
    let field = VdbField::from_dense("placed".into(), &dense, 0.0, &prm).expect("field");
    assert!((field.n(DVec3::new(10.0, 0.0, 0.0)) - (1.0 + 1e-3)).abs() < 1e-9);
    assert!(close(
        field.world_from_index(DVec3::new(0.0, 0.0, 2.0)),
        DVec3::new(10.0, 1.0, 0.0)
    ));
}

/// "auto" takes the background's index; an explicit ambient within the tolerance is
/// taken as the background (the data moves by the difference): outside the data the
/// field is the ambient exactly, and the dense copy keeps only the voxels that change
/// the index (plus padding), not the cache's whole active box.
#[test]
fn ambient_auto_and_near_ambient_leave_the_background_exactly_ambient() {
    let xf = Transform {
        world_from_index: [
            [0.1, 0.0, 0.0, 0.0],
            [0.0, 0.1, 0.0, 0.0],
            [0.0, 0.0, 0.1, 0.0],
        ],
    };
    // A hot core in a big box of background (0 = ambient temperature).
    let dense = cube(
        |i, j, k| {
            if i.abs() <= 1 && (j - 1).abs() <= 1 && (k - 2).abs() <= 1 {
                1.0
            } else {
                0.0
            }
        },
        12,
        xf,
    );
    let gd = Mapping::GladstoneDale(gd_default());
    let n_bg = gd.n(0.0, 1.0).expect("n");
    let mut auto = params(gd, 1.0);
    auto.ambient = None;
    let field = VdbField::from_dense("auto".into(), &dense, 0.0, &auto).expect("field");
    assert_eq!(field.ambient_index(), n_bg);
    let far = DVec3::new(0.9, 0.9, 0.9);
    assert_eq!(field.n(far), n_bg);
    let b = field.index_box();
    assert_eq!(
        (b.min, b.max),
        ([-3, -2, -1], [3, 4, 5]),
        "cropped to the core + 2"
    );
    assert_eq!(field.dims, [7, 7, 7]);
    let core = field.n(DVec3::new(0.0, 0.1, 0.2));
    assert!((core - gd.n(1.0, 1.0).expect("n")).abs() < 1e-12, "{core}");

    // 5e-7 off the background's index: accepted, and taken as that index.
    let near = params(gd, n_bg + 5e-7);
    let field = VdbField::from_dense("near".into(), &dense, 0.0, &near).expect("field");
    assert_eq!(field.n(far), n_bg + 5e-7);
    assert_eq!(field.sample(DVec3::new(0.6, 0.1, 0.2)).grad_n, DVec3::ZERO);
    let core = field.n(DVec3::new(0.0, 0.1, 0.2));
    assert!((core - (gd.n(1.0, 1.0).expect("n") + 5e-7)).abs() < 1e-12);
    // 2e-6 off: refused, naming the value to use.
    let e = VdbField::from_dense("far".into(), &dense, 0.0, &params(gd, n_bg + 2e-6))
        .expect_err("refused");
    assert!(e.to_string().contains("ambient_index = 1.000272"), "{e}");

    // A relative mapping: "auto" is 1.0.
    let mut rel = params(Mapping::Linear { k: 1e-4 }, 1.0);
    rel.ambient = None;
    let field = VdbField::from_dense("rel".into(), &dense, 0.0, &rel).expect("field");
    assert_eq!(field.ambient_index(), 1.0);
}
