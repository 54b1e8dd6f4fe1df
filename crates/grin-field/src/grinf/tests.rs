//! Round trip and corruption tests of the .grinf format.

use glam::DVec3;

use super::*;
use crate::bake::{BakeOptions, bake, random_points_inside};
use crate::field::{FieldSample, IndexField};

#[derive(Debug)]
struct Wave;

impl IndexField for Wave {
    fn sample(&self, p: DVec3) -> FieldSample<f64> {
        let n = 1.0 + 3e-4 * (4.0 * p.x).sin() * (3.0 * p.y).cos();
        let g = DVec3::new(
            1.2e-3 * (4.0 * p.x).cos() * (3.0 * p.y).cos(),
            -9e-4 * (4.0 * p.x).sin() * (3.0 * p.y).sin(),
            0.0,
        );
        FieldSample { n, grad_n: g }
    }
    fn bounds(&self) -> Bounds {
        Bounds::Box {
            min: DVec3::new(-1.0, -0.5, -0.25),
            max: DVec3::new(1.0, 0.5, 0.25),
        }
    }
    fn ambient_index(&self) -> f64 {
        1.0
    }
    fn n_range(&self) -> (f64, f64) {
        (1.0 - 3e-4, 1.0 + 3e-4)
    }
    fn max_grad_n(&self) -> f64 {
        1.5e-3
    }
    fn describe(&self) -> String {
        "test wave".into()
    }
}

fn baked(storage: Storage, interp: Interp) -> BakedField {
    let opts = BakeOptions {
        resolution: Some(20),
        storage: Some(storage),
        interp,
        error_points: 500,
        ..Default::default()
    };
    bake(&Wave, &opts, &|_: &str, _: u64, _: u64| {})
        .expect("bake")
        .0
}

#[test]
fn round_trip_gives_bit_identical_samples() {
    let dir = tempfile::tempdir().expect("tempdir");
    for storage in [Storage::F32, Storage::I16] {
        for interp in [Interp::Trilinear, Interp::Tricubic] {
            let f = baked(storage, interp);
            let path = dir.path().join("w.grinf");
            save(&f, &path).expect("save");
            let g = load(&path).expect("load");
            assert_eq!(g.voxels(), f.voxels());
            assert_eq!(g.geometry(), f.geometry());
            assert_eq!(g.provenance(), f.provenance());
            assert_eq!(
                (g.storage(), g.interp(), g.outside()),
                (storage, interp, f.outside())
            );
            assert_eq!(g.bounds(), Wave.bounds());
            for p in random_points_inside(Wave.bounds(), 300, 5) {
                let (a, b) = (f.sample(p), g.sample(p));
                assert_eq!(a.n.to_bits(), b.n.to_bits());
                assert_eq!(
                    a.grad_n.to_array().map(f64::to_bits),
                    b.grad_n.to_array().map(f64::to_bits)
                );
            }
            let h = read_header(&path).expect("header");
            assert_eq!(
                h.file_bytes,
                std::fs::metadata(&path).expect("metadata").len()
            );
            assert_eq!(h.provenance.source, "test wave");
            // No temporary file is left behind.
            let names: Vec<_> = std::fs::read_dir(dir.path()).expect("dir").collect();
            assert_eq!(names.len(), 1);
        }
    }
}

#[test]
fn corrupt_files_are_clear_errors() {
    let f = baked(Storage::I16, Interp::Trilinear);
    let good = to_bytes(&f);
    let p = "x.grinf";
    let err = |b: &[u8]| from_bytes(b, p).expect_err("corrupt").to_string();

    let mut b = good.clone();
    b[0] = b'X';
    assert!(err(&b).contains("not a .grinf file"), "{}", err(&b));

    let mut b = good.clone();
    b[8] = 9;
    assert!(
        err(&b).contains("unsupported .grinf version 9"),
        "{}",
        err(&b)
    );

    let mut b = good.clone();
    let mid = b.len() / 2;
    b[mid] ^= 0x40;
    assert!(err(&b).contains("checksum mismatch"), "{}", err(&b));

    let b = &good[..good.len() - 100];
    assert!(err(b).contains("truncated"), "{}", err(b));
    let b = &good[..20];
    assert!(err(b).contains("truncated"), "{}", err(b));

    // Absurd dims in the header: a size error, not an allocation.
    let mut b = good.clone();
    b[16..20].copy_from_slice(&u32::MAX.to_le_bytes());
    b[20..24].copy_from_slice(&u32::MAX.to_le_bytes());
    let e = err(&b);
    assert!(e.contains("truncated") || e.contains("too large"), "{e}");

    assert!(from_bytes(&good, p).is_ok());
}

#[test]
fn layout_matches_the_documentation() {
    let f = baked(Storage::F32, Interp::Trilinear);
    let b = to_bytes(&f);
    let u32_at = |o: usize| u32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]);
    let f32_at = |o: usize| f32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]);
    let f64_at = |o: usize| f64::from_le_bytes(std::array::from_fn(|i| b[o + i]));
    assert_eq!(&b[0..8], b"GRINF\0\0\0");
    let data = u32_at(12) as usize;
    assert_eq!(data % 16, 0);
    let dims = [u32_at(16), u32_at(20), u32_at(24)].map(|d| d as usize);
    assert_eq!(dims, f.dims());
    assert_eq!(f64_at(40), 1.0);
    let origin = DVec3::new(f64_at(48), f64_at(56), f64_at(64));
    let h = f64_at(72);
    // Voxel (i, j, k) channel c at data + 16 * (i + nx (j + ny k)) + 4 c.
    let (i, j, k) = (3, 4, 2);
    let off = data + 16 * (i + dims[0] * (j + dims[1] * k));
    let p = origin + DVec3::new(i as f64, j as f64, k as f64) * h;
    let want = Wave.sample(p);
    assert!((f64::from(f32_at(off)) - (want.n - 1.0)).abs() < 1e-9);
    assert!((f64::from(f32_at(off + 4)) - want.grad_n.x).abs() < 1e-8);
    assert_eq!(u32_at(b.len() - 4), crc32fast::hash(&b[..b.len() - 4]));
}

/// Files with a valid checksum whose numbers cannot be a medium: each a clear error.
#[test]
fn crafted_files_with_valid_checksums_are_refused() {
    let f = baked(Storage::F32, Interp::Trilinear);
    let good = to_bytes(&f);
    let data = u32::from_le_bytes([good[12], good[13], good[14], good[15]]) as usize;
    let resealed = |edit: &dyn Fn(&mut Vec<u8>)| {
        let mut b = good.clone();
        edit(&mut b);
        let n = b.len() - 4;
        let crc = crc32fast::hash(&b[..n]);
        b[n..].copy_from_slice(&crc.to_le_bytes());
        from_bytes(&b, "crafted.grinf")
            .expect_err("crafted")
            .to_string()
    };
    // Origin at 1e300.
    let e = resealed(&|b| b[48..56].copy_from_slice(&1e300f64.to_le_bytes()));
    assert!(e.starts_with("crafted.grinf: "), "{e}");
    assert!(e.contains("reaches beyond ±1e7 world units"), "{e}");
    // A voxel delta_n of 3e38 (finite in f32, but n and its gradient are not a medium).
    let e = resealed(&|b| b[data..data + 4].copy_from_slice(&3e38f32.to_le_bytes()));
    assert!(e.contains("baked voxel 0 has n = "), "{e}");
    // A voxel with n <= 0 (delta_n = -2 around ambient 1).
    let e = resealed(&|b| b[data + 16..data + 20].copy_from_slice(&(-2.0f32).to_le_bytes()));
    assert!(e.contains("baked voxel 1 has n = -1"), "{e}");
    // A gradient whose square overflows f32.
    let e = resealed(&|b| b[data + 4..data + 8].copy_from_slice(&3e30f32.to_le_bytes()));
    assert!(
        e.contains("baked voxel 0 has a gradient too large for f32"),
        "{e}"
    );
    assert!(from_bytes(&good, "good.grinf").is_ok());

    // The whole file: numbers that fit the payload's size but not its content.
    let f64s = |b: &mut Vec<u8>, at: usize, v: [f64; 3]| {
        for (k, x) in v.iter().enumerate() {
            b[at + 8 * k..at + 8 * k + 8].copy_from_slice(&x.to_le_bytes());
        }
    };
    let g = *f.geometry();
    let sp = g.spacing.to_array();
    // The ratio the message reports: the stored gradient over the index's differences
    // (a 20-node bake's central differences read ~3 % low on their own).
    let ratio = |e: &str, axis: &str| -> f64 {
        let at = e.find(&format!("along {axis} is ")).expect(e) + 11;
        e[at..at + 5].parse().expect(e)
    };
    // A spacing twice the grid's: the stored gradient is twice the index's differences.
    let e = resealed(&|b| f64s(b, 72, sp.map(|h| 2.0 * h)));
    assert!(e.contains("spacing or dims do not match the data"), "{e}");
    assert!((1.95..2.15).contains(&ratio(&e, "x")), "{e}");
    // Only y's spacing off by 1.5.
    let e = resealed(&|b| f64s(b, 72, [sp[0], 1.5 * sp[1], sp[2]]));
    assert!((1.45..1.6).contains(&ratio(&e, "y")), "{e}");
    // Dims permuted over the same payload.
    let e = resealed(&|b| {
        let [nx, ny, nz] = g.dims.map(|d| (d as u32).to_le_bytes());
        b[16..20].copy_from_slice(&nz);
        b[24..28].copy_from_slice(&nx);
        let _ = ny;
    });
    assert!(e.starts_with("crafted.grinf: bad header: "), "{e}");
    // A clamped grid moved off its bounds.
    assert_eq!(
        f.outside(),
        Outside::Clamp,
        "the wave fills its box: not cropped"
    );
    let o = g.origin.to_array();
    let e = resealed(&|b| f64s(b, 48, [o[0] + 0.5, o[1], o[2]]));
    assert!(e.contains("does not cover the bounds"), "{e}");
}

/// i16 voxels are -32767..32767 times their scale: a file's -32768 (grin writes none) reads
/// as -32767, as a GPU's rgba16snorm texel does, so both backends read the same integers.
#[test]
fn an_i16_voxel_of_minus_32768_reads_as_minus_32767() {
    let f = baked(Storage::I16, Interp::Trilinear);
    let mut b = to_bytes(&f);
    let data = u32::from_le_bytes([b[12], b[13], b[14], b[15]]) as usize;
    // Voxel 0's dn/dx.
    b[data + 2..data + 4].copy_from_slice(&i16::MIN.to_le_bytes());
    let n = b.len() - 4;
    let crc = crc32fast::hash(&b[..n]);
    b[n..].copy_from_slice(&crc.to_le_bytes());
    let g = from_bytes(&b, "min.grinf").expect("an i16 file with -32768");
    match g.voxels() {
        Voxels::I16 { data, .. } => assert_eq!(data[0][1], -i16::MAX),
        other => panic!("storage {:?}", other.storage()),
    }
}
