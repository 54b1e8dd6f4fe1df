//! The [`IndexField`] trait: n and grad n at a point, the bounds, the n range.

use glam::{DVec3, Vec3};

use crate::bounds::Bounds;
use crate::real::Real;

/// n and grad n at one point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FieldSample<R: Real> {
    pub n: R,
    pub grad_n: R::V3,
}

impl<R: Real> FieldSample<R> {
    /// D = n grad n = grad(n^2 / 2), the right-hand side of r'' = D(r).
    #[inline]
    pub fn n_grad_n(&self) -> R::V3 {
        self.grad_n * self.n
    }
}

/// A refractive index field n(r) over a medium's bounds, in world coordinates.
///
/// `sample` may be called a little outside the bounds (Runge-Kutta stages of the step
/// that leaves the medium land there): fields return their formula's smooth extension
/// where it has one, and otherwise the value at the nearest point inside.
pub trait IndexField: Send + Sync + std::fmt::Debug {
    /// n and grad n at world point `p` (f64 reference).
    fn sample(&self, p: DVec3) -> FieldSample<f64>;

    /// The f32 path (what the GPU computes). Fields with native f32 storage override it;
    /// the default rounds the f64 sample, keeping delta_n = n - ambient accurate.
    fn sample_f32(&self, p: Vec3) -> FieldSample<f32> {
        let s = self.sample(p.as_dvec3());
        FieldSample {
            n: s.n as f32,
            grad_n: s.grad_n.as_vec3(),
        }
    }

    /// n and grad n at four points at once, as lanes: `p` holds the points' x, y and z,
    /// `out` receives n, dn/dx, dn/dy, dn/dz. The same values as [`Self::sample`] at each
    /// point, bit for bit; fields that compute several points faster together override it
    /// (an `expr` formula's compiled code works in two-lane vectors).
    fn sample4(&self, p: [[f64; 4]; 3], out: &mut [[f64; 4]; 4]) {
        sample4_each(self, p, out);
    }

    /// n alone (cheaper for fields that can skip the gradient).
    fn n(&self, p: DVec3) -> f64 {
        self.sample(p).n
    }

    /// The medium's bounds in world space.
    fn bounds(&self) -> Bounds;

    /// Index outside the bounds.
    fn ambient_index(&self) -> f64;

    /// (min n, max n) over the bounds (exact where known, else a sampled estimate).
    fn n_range(&self) -> (f64, f64);

    /// Largest |grad n| over the bounds (exact or sampled), used by the step heuristic.
    fn max_grad_n(&self) -> f64;

    /// A short human description, e.g. `luneburg R=1`.
    fn describe(&self) -> String;

    /// Macro-cell query (the paper's "infinite step"): if grad n is ~0 around `p`, the
    /// world length a ray from `p` along unit `dir` can fly straight before it may meet
    /// a varying region. `None` where the field varies here or the field has no
    /// macro-cell grid. Baked fields override it.
    fn homogeneous_span(&self, _p: DVec3, _dir: DVec3) -> Option<f64> {
        None
    }

    /// The shortest length over which the field can change by a large part of its range,
    /// where the field knows one: a plume's smallest width, the finest noise octave's half
    /// wavelength, twice a grid's spacing. Error-controlled steps stay below it, so no
    /// step can pass over a whole feature between samples. `None`: no scale below the
    /// bounds' own (analytic profiles, expressions).
    fn feature_size(&self) -> Option<f64> {
        None
    }

    /// What the field's construction found worth telling the user without refusing the
    /// field (a VDB grid whose data the bounds cut, an `expr` formula whose positivity
    /// is unproven between the check grid's nodes): the binary and the viewer show them,
    /// the library prints nothing.
    fn warnings(&self) -> Vec<String> {
        Vec::new()
    }

    /// The longest step from `p` that cannot pass over a feature unseen, where the field
    /// knows its features locally (an `expr` formula's interval map,
    /// crate::features), looking `reach` around `p`; infinite elsewhere.
    fn step_cap(&self, _p: DVec3, _reach: f64) -> f64 {
        f64::INFINITY
    }

    /// Whether [`Self::homogeneous_span`] or [`Self::step_cap`] can give anything but
    /// their defaults (`None`, infinity) anywhere: `false` lets a tracer skip asking them
    /// at every step. `true` unless the field knows it has neither.
    fn has_local_step_limits(&self) -> bool {
        true
    }

    /// Points where the field has its finest features (crate::features), for a bake's
    /// error search: random points can miss a feature 1/100 of the bounds wide.
    fn feature_points(&self) -> Vec<DVec3> {
        Vec::new()
    }

    /// The spacing (scene metres) of the samples this field interpolates, where it is a
    /// grid of data (a VDB's voxel size, a baked grid's spacing): a bake finer than it
    /// resolves the interpolation, not the data. `None` for fields given by a formula.
    fn source_spacing(&self) -> Option<f64> {
        None
    }

    /// Where this field's data sit on an axis-aligned cubic lattice (a VDB grid without
    /// rotation or shear): the world point of lattice node (0, 0, 0) and the spacing, so
    /// that a Catmull-Rom bake with its nodes on the same lattice interpolates exactly
    /// what this field interpolates. `None` elsewhere.
    fn source_lattice(&self) -> Option<(DVec3, f64)> {
        None
    }

    /// How far n may be from what this field stands for (a bake's measured max |n
    /// error| against its source; 0 for fields that are their own definition). A
    /// refraction at the bounds amplifies it by tan of the refracted angle: the tracer
    /// adds that to a ray's error estimate (grazing rays through a bake of a lens).
    fn n_uncertainty(&self) -> f64 {
        0.0
    }

    /// Relative roundoff of this field's samples: f64's for a formula, f32's for a baked
    /// grid, which holds and interpolates f32 whatever the trace's precision. Error
    /// control holds no step below it: the samples' roundoff enters a step's error
    /// estimate in proportion to the step, so a tolerance per unit length under it is
    /// never met at any step size (dopri at `auto 1e-8` on a baked fish-eye shrank its
    /// steps to 1e-12 R and ended 31 of 32 rays at `max_steps` after 10^6 steps each).
    fn sample_eps(&self) -> f64 {
        f64::EPSILON
    }

    /// The grid itself when this field is a baked one (a `.grinf` file): the GPU
    /// uploads it as it is instead of baking the field again.
    fn as_baked(&self) -> Option<&crate::baked::BakedField> {
        None
    }

    /// The sparse grid itself when this field is a sparse bake (a version-2 `.grinf`):
    /// what the GPU backend must not bake again as one dense box.
    fn as_sparse(&self) -> Option<&crate::sparse::SparseField> {
        None
    }

    /// An upper bound on |n - ambient| over the world box [`lo`, `hi`], where the field
    /// can prove one (a sum of Gaussians bounded by each one's value at the box's nearest
    /// point); `None` where it cannot, and a sparse bake then probes the box instead.
    fn delta_bound(&self, _lo: DVec3, _hi: DVec3) -> Option<f64> {
        None
    }
}

/// [`IndexField::sample4`] one point at a time with [`IndexField::sample`] (the default,
/// and what a field that overrides it falls back to).
pub fn sample4_each<F: IndexField + ?Sized>(field: &F, p: [[f64; 4]; 3], out: &mut [[f64; 4]; 4]) {
    for i in 0..4 {
        let s = field.sample(DVec3::new(p[0][i], p[1][i], p[2][i]));
        out[0][i] = s.n;
        out[1][i] = s.grad_n.x;
        out[2][i] = s.grad_n.y;
        out[3][i] = s.grad_n.z;
    }
}

/// Why a field could not be built or evaluated.
#[derive(Debug, thiserror::Error)]
pub enum FieldError {
    /// n <= 0 (or non-finite) somewhere inside the medium.
    #[error("{field}: n = {n} <= 0 at ({x}, {y}, {z}) inside the medium; n must be positive")]
    NonPositive {
        field: String,
        n: f64,
        x: f64,
        y: f64,
        z: f64,
    },
    #[error("{field}: n is not finite ({n}) at ({x}, {y}, {z})")]
    NonFinite {
        field: String,
        n: f64,
        x: f64,
        y: f64,
        z: f64,
    },
    #[error("expression `{expr}`: {message}")]
    Expr { expr: String, message: String },
    #[error("{field}: invalid parameter `{param}`: {message}")]
    Param {
        field: String,
        param: String,
        message: String,
    },
    #[error("{path}: {message}")]
    File { path: String, message: String },
    /// Reading an OpenVDB file failed (names the file and grid).
    #[error(transparent)]
    Vdb(#[from] vdb_sys::VdbError),
    #[error("{0}")]
    Other(String),
}
