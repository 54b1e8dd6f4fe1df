//! [`Real`]: f32 or f64 with its glam vector type, so one integrator source serves the
//! f64 reference and the f32 path that mirrors the GPU.

use std::fmt::Debug;
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

use glam::{DVec3, Vec3};

use crate::field::{FieldSample, IndexField};

/// A 3-vector over the scalar `R` (glam's `Vec3` for f32, `DVec3` for f64).
pub trait Vec3Like<R>:
    Copy
    + Debug
    + PartialEq
    + Send
    + Sync
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<R, Output = Self>
    + Div<R, Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
{
    const ZERO: Self;
    fn new(x: R, y: R, z: R) -> Self;
    fn dot(self, other: Self) -> R;
    fn cross(self, other: Self) -> Self;
    fn length(self) -> R;
    fn length_squared(self) -> R;
    fn normalize(self) -> Self;
    fn x(self) -> R;
    fn y(self) -> R;
    fn z(self) -> R;
    fn to_dvec3(self) -> DVec3;
    fn from_dvec3(v: DVec3) -> Self;
}

macro_rules! impl_vec3like {
    ($v:ty, $r:ty) => {
        impl Vec3Like<$r> for $v {
            const ZERO: Self = <$v>::ZERO;
            #[inline]
            fn new(x: $r, y: $r, z: $r) -> Self {
                <$v>::new(x, y, z)
            }
            #[inline]
            fn dot(self, other: Self) -> $r {
                <$v>::dot(self, other)
            }
            #[inline]
            fn cross(self, other: Self) -> Self {
                <$v>::cross(self, other)
            }
            #[inline]
            fn length(self) -> $r {
                <$v>::length(self)
            }
            #[inline]
            fn length_squared(self) -> $r {
                <$v>::length_squared(self)
            }
            #[inline]
            fn normalize(self) -> Self {
                <$v>::normalize(self)
            }
            #[inline]
            fn x(self) -> $r {
                self.x
            }
            #[inline]
            fn y(self) -> $r {
                self.y
            }
            #[inline]
            fn z(self) -> $r {
                self.z
            }
            #[inline]
            fn to_dvec3(self) -> DVec3 {
                DVec3::new(self.x as f64, self.y as f64, self.z as f64)
            }
            #[inline]
            fn from_dvec3(v: DVec3) -> Self {
                <$v>::new(v.x as $r, v.y as $r, v.z as $r)
            }
        }
    };
}

impl_vec3like!(Vec3, f32);
impl_vec3like!(DVec3, f64);

/// f32 or f64: the scalar the integrators are generic over.
pub trait Real: num_traits::Float + Debug + Default + Send + Sync + 'static {
    type V3: Vec3Like<Self>;
    /// Unit roundoff, for tolerances that scale with precision.
    const EPS: Self;
    fn from_f64(x: f64) -> Self;
    fn to_f64(self) -> f64;
    /// Sample a field in this precision.
    fn sample_field(field: &dyn IndexField, p: Self::V3) -> FieldSample<Self>;
}

impl Real for f64 {
    type V3 = DVec3;
    const EPS: Self = f64::EPSILON;
    #[inline]
    fn from_f64(x: f64) -> Self {
        x
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline]
    fn sample_field(field: &dyn IndexField, p: DVec3) -> FieldSample<f64> {
        field.sample(p)
    }
}

impl Real for f32 {
    type V3 = Vec3;
    const EPS: Self = f32::EPSILON;
    #[inline]
    fn from_f64(x: f64) -> Self {
        x as f32
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self as f64
    }
    #[inline]
    fn sample_field(field: &dyn IndexField, p: Vec3) -> FieldSample<f32> {
        field.sample_f32(p)
    }
}
