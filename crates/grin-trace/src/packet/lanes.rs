//! Lane vectors: one f64 ([`L`]) or one 3-vector ([`V`]) per lane, with glam's scalar
//! arithmetic lane by lane (the compiler turns it into SIMD), a lane mask for blends, and
//! the lanes' field samples, signed distances and normals of the bounds.

use std::array;
use std::ops::{Add, Div, Mul, Neg, Sub};

use glam::DVec3;
use grin_field::{Bounds, IndexField};

use super::LANES;

/// One f64 per lane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct L(pub(super) [f64; LANES]);

impl L {
    #[inline]
    pub(super) fn splat(v: f64) -> L {
        L([v; LANES])
    }
    #[inline]
    pub(super) fn map(self, f: impl Fn(f64) -> f64) -> L {
        L(array::from_fn(|i| f(self.0[i])))
    }
    #[inline]
    pub(super) fn zip(self, o: L, f: impl Fn(f64, f64) -> f64) -> L {
        L(array::from_fn(|i| f(self.0[i], o.0[i])))
    }
    #[inline]
    pub(super) fn sqrt(self) -> L {
        self.map(f64::sqrt)
    }
}

macro_rules! lane_op {
    ($tr:ident, $m:ident, $op:tt) => {
        impl $tr for L {
            type Output = L;
            #[inline]
            fn $m(self, o: L) -> L {
                L(array::from_fn(|i| self.0[i] $op o.0[i]))
            }
        }
    };
}
lane_op!(Add, add, +);
lane_op!(Sub, sub, -);
lane_op!(Mul, mul, *);
lane_op!(Div, div, /);

impl Neg for L {
    type Output = L;
    #[inline]
    fn neg(self) -> L {
        self.map(|v| -v)
    }
}

/// A 3-vector per lane, with glam's DVec3 arithmetic (the same operations in the same
/// order, so every lane rounds as the scalar tracer does).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct V {
    pub(super) x: L,
    pub(super) y: L,
    pub(super) z: L,
}

impl V {
    #[inline]
    pub(super) fn zero() -> V {
        V {
            x: L::splat(0.0),
            y: L::splat(0.0),
            z: L::splat(0.0),
        }
    }
    #[inline]
    pub(super) fn lane(&self, i: usize) -> DVec3 {
        DVec3::new(self.x.0[i], self.y.0[i], self.z.0[i])
    }
    #[inline]
    pub(super) fn set(&mut self, i: usize, v: DVec3) {
        self.x.0[i] = v.x;
        self.y.0[i] = v.y;
        self.z.0[i] = v.z;
    }
    #[inline]
    pub(super) fn scale(self, s: L) -> V {
        V {
            x: self.x * s,
            y: self.y * s,
            z: self.z * s,
        }
    }
    #[inline]
    pub(super) fn over(self, s: L) -> V {
        V {
            x: self.x / s,
            y: self.y / s,
            z: self.z / s,
        }
    }
    #[inline]
    pub(super) fn dot(self, o: V) -> L {
        (self.x * o.x) + (self.y * o.y) + (self.z * o.z)
    }
    #[inline]
    pub(super) fn length(self) -> L {
        self.dot(self).sqrt()
    }
    /// glam's `normalize_or_zero`: times 1/length where that is finite and positive.
    #[inline]
    pub(super) fn normalize_or_zero(self) -> V {
        let rcp = L::splat(1.0) / self.length();
        let n = self.scale(rcp);
        let keep = |i: usize| rcp.0[i].is_finite() && rcp.0[i] > 0.0;
        V {
            x: L(array::from_fn(|i| if keep(i) { n.x.0[i] } else { 0.0 })),
            y: L(array::from_fn(|i| if keep(i) { n.y.0[i] } else { 0.0 })),
            z: L(array::from_fn(|i| if keep(i) { n.z.0[i] } else { 0.0 })),
        }
    }
    #[inline]
    pub(super) fn finite(&self, i: usize) -> bool {
        self.x.0[i].is_finite() && self.y.0[i].is_finite() && self.z.0[i].is_finite()
    }
}

impl Add for V {
    type Output = V;
    #[inline]
    fn add(self, o: V) -> V {
        V {
            x: self.x + o.x,
            y: self.y + o.y,
            z: self.z + o.z,
        }
    }
}

impl Sub for V {
    type Output = V;
    #[inline]
    fn sub(self, o: V) -> V {
        V {
            x: self.x - o.x,
            y: self.y - o.y,
            z: self.z - o.z,
        }
    }
}

/// Knuth's TwoSum per component (crate::integrate::add_compensated, lane by lane).
#[inline]
pub(super) fn two_sum(a: V, b: V) -> (V, V) {
    let sum = a + b;
    let b_virtual = sum - a;
    let lost = (a - (sum - b_virtual)) + (b - b_virtual);
    (sum, lost)
}

/// The signed distance to the bounds, per lane (Bounds::signed_distance's arithmetic).
#[inline(always)]
pub(super) fn signed_distance(bounds: &Bounds, p: V) -> L {
    match *bounds {
        Bounds::Sphere { center, radius } => {
            let c = V {
                x: L::splat(center.x),
                y: L::splat(center.y),
                z: L::splat(center.z),
            };
            (p - c).length() - L::splat(radius)
        }
        Bounds::Box { min, max } => {
            let c = (min + max) * 0.5;
            let h = (max - min) * 0.5;
            let q = |p: L, c: f64, h: f64| (p - L::splat(c)).map(f64::abs) - L::splat(h);
            let (qx, qy, qz) = (q(p.x, c.x, h.x), q(p.y, c.y, h.y), q(p.z, c.z, h.z));
            let pos = |v: L| v.map(|a| a.max(0.0));
            let outside = V {
                x: pos(qx),
                y: pos(qy),
                z: pos(qz),
            }
            .length();
            let inside = qx.zip(qy, f64::max).zip(qz, f64::max).map(|a| a.min(0.0));
            outside + inside
        }
    }
}

/// Sample the field at the lanes' points (`IndexField::sample4`; the values of lanes
/// that take no step are not used).
#[inline]
pub(super) fn sample(field: &dyn IndexField, p: V) -> (L, V) {
    let mut out = [[0.0; LANES]; 4];
    field.sample4([p.x.0, p.y.0, p.z.0], &mut out);
    let lanes = |k: usize| L(read_halves(&out[k]));
    (
        lanes(0),
        V {
            x: lanes(1),
            y: lanes(2),
            z: lanes(3),
        },
    )
}

/// Four lanes read as two halves. A compiled expression (crate grin_field's JIT) stores
/// its results two lanes at a time, and a four-lane read of two stores cannot take its
/// value from them until both have retired (a store-forwarding stall after every field
/// sample); each half read alone is forwarded from its store.
#[inline(always)]
#[allow(unsafe_code)]
fn read_halves(v: &[f64; 4]) -> [f64; 4] {
    let half = (v as *const [f64; 4]).cast::<[f64; 2]>();
    // SAFETY: `half` and `half.add(1)` are the two aligned, initialised halves of the
    // borrowed `v` ([f64; 4] is laid out as [[f64; 2]; 2]). Volatile only so that the
    // compiler keeps them two reads rather than merging them into one.
    let (lo, hi) = unsafe { (half.read_volatile(), half.add(1).read_volatile()) };
    [lo[0], lo[1], hi[0], hi[1]]
}

/// The outward unit normal of the bounds nearest each lane's point (Bounds::normal's
/// arithmetic).
#[inline(always)]
pub(super) fn normal(bounds: &Bounds, p: V) -> V {
    match *bounds {
        Bounds::Sphere { center, .. } => {
            let d = p - V {
                x: L::splat(center.x),
                y: L::splat(center.y),
                z: L::splat(center.z),
            };
            d.scale(L::splat(1.0) / d.length())
        }
        Bounds::Box { min, max } => {
            let c = (min + max) * 0.5;
            let h = (max - min) * 0.5;
            let (dx, dy, dz) = (
                p.x - L::splat(c.x),
                p.y - L::splat(c.y),
                p.z - L::splat(c.z),
            );
            let (qx, qy, qz) = (
                dx.map(f64::abs) - L::splat(h.x),
                dy.map(f64::abs) - L::splat(h.y),
                dz.map(f64::abs) - L::splat(h.z),
            );
            let mut n = V::zero();
            for i in 0..LANES {
                let (x, y, z) = (qx.0[i], qy.0[i], qz.0[i]);
                if x >= y && x >= z {
                    n.x.0[i] = dx.0[i].signum();
                } else if y >= z {
                    n.y.0[i] = dy.0[i].signum();
                } else {
                    n.z.0[i] = dz.0[i].signum();
                }
            }
            n
        }
    }
}

/// A lane mask: all bits set in the chosen lanes (a blend, where a branch per lane
/// would keep the lane vectors out of registers).
#[derive(Debug, Clone, Copy)]
pub(super) struct Mask(pub(super) [u64; LANES]);

impl Mask {
    #[inline(always)]
    pub(super) fn of(lanes: [bool; LANES]) -> Mask {
        Mask(array::from_fn(|i| u64::from(lanes[i]).wrapping_neg()))
    }

    /// `a` in the chosen lanes, `b` in the others.
    #[inline(always)]
    pub(super) fn select(self, a: L, b: L) -> L {
        L(array::from_fn(|i| {
            let m = self.0[i];
            f64::from_bits((a.0[i].to_bits() & m) | (b.0[i].to_bits() & !m))
        }))
    }

    #[inline(always)]
    pub(super) fn select_v(self, a: V, b: V) -> V {
        V {
            x: self.select(a.x, b.x),
            y: self.select(a.y, b.y),
            z: self.select(a.z, b.z),
        }
    }
}
