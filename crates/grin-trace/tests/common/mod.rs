//! Analytic test fields with known ray solutions, written here (independently of
//! grin-field's profiles) so the tracer's tests check the tracer alone.

#![allow(dead_code)]

use glam::DVec3;
use grin_field::{Bounds, FieldSample, IndexField};

/// n(r) and grad n(r) formulas, valid (smoothly extended) a little outside the bounds.
#[derive(Debug, Clone, Copy)]
pub enum Profile {
    /// n^2 = 2 - |r - c|^2 / R^2.
    Luneburg { c: DVec3, radius: f64 },
    /// n = n0 / (1 + |r|^2 / a^2), centred at the origin.
    FishEye { n0: f64, a: f64 },
    /// n^2 = n0^2 (1 - a^2 (x^2 + y^2)), axis z.
    GrinRod { n0: f64, a: f64 },
    /// n^2 = n0^2 + k y.
    LinearN2 { n0: f64, k: f64 },
    /// n constant.
    Uniform { n: f64 },
    /// n = 1 + amp exp(-|r - c|^2 / s^2).
    Blob { c: DVec3, amp: f64, s: f64 },
    /// n = 1 + e exp(-y / h).
    Stratified { e: f64, h: f64 },
}

impl Profile {
    pub fn eval(&self, p: DVec3) -> (f64, DVec3) {
        match *self {
            Profile::Luneburg { c, radius } => {
                let d = p - c;
                let n = (2.0 - d.length_squared() / (radius * radius)).sqrt();
                (n, -d / (radius * radius * n))
            }
            Profile::FishEye { n0, a } => {
                let q = 1.0 + p.length_squared() / (a * a);
                (n0 / q, -p * (2.0 * n0 / (a * a * q * q)))
            }
            Profile::GrinRod { n0, a } => {
                let rho2 = p.x * p.x + p.y * p.y;
                let n = n0 * (1.0 - a * a * rho2).sqrt();
                let k = -n0 * n0 * a * a / n;
                (n, DVec3::new(p.x * k, p.y * k, 0.0))
            }
            Profile::LinearN2 { n0, k } => {
                let n = (n0 * n0 + k * p.y).sqrt();
                (n, DVec3::new(0.0, k / (2.0 * n), 0.0))
            }
            Profile::Uniform { n } => (n, DVec3::ZERO),
            Profile::Blob { c, amp, s } => {
                let d = p - c;
                let g = amp * (-d.length_squared() / (s * s)).exp();
                (1.0 + g, d * (-2.0 * g / (s * s)))
            }
            Profile::Stratified { e, h } => {
                let g = e * (-p.y / h).exp();
                (1.0 + g, DVec3::new(0.0, -g / h, 0.0))
            }
        }
    }
}

/// A test medium: a profile inside `bounds`, `ambient` outside; optionally reports whole
/// bounds as homogeneous when the profile is uniform (to exercise macro cells).
#[derive(Debug, Clone)]
pub struct TestField {
    pub profile: Profile,
    pub bounds: Bounds,
    pub ambient: f64,
    pub macro_uniform: bool,
    n_range: (f64, f64),
    max_grad: f64,
}

impl TestField {
    pub fn new(profile: Profile, bounds: Bounds, ambient: f64) -> Self {
        // Sampled extremes over a grid inside the bounds.
        const SAMPLES: usize = 24;
        let (lo, hi) = bounds.aabb();
        let (mut nmin, mut nmax, mut gmax) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
        for i in 0..=SAMPLES {
            for j in 0..=SAMPLES {
                for k in 0..=SAMPLES {
                    let f = DVec3::new(i as f64, j as f64, k as f64) / SAMPLES as f64;
                    let p = lo + (hi - lo) * f;
                    if bounds.contains(p) {
                        let (n, g) = profile.eval(p);
                        nmin = nmin.min(n);
                        nmax = nmax.max(n);
                        gmax = gmax.max(g.length());
                    }
                }
            }
        }
        TestField {
            profile,
            bounds,
            ambient,
            macro_uniform: false,
            n_range: (nmin, nmax),
            max_grad: gmax,
        }
    }

    pub fn sphere(profile: Profile, center: DVec3, radius: f64, ambient: f64) -> Self {
        Self::new(profile, Bounds::Sphere { center, radius }, ambient)
    }

    pub fn cuboid(profile: Profile, min: DVec3, max: DVec3, ambient: f64) -> Self {
        Self::new(profile, Bounds::Box { min, max }, ambient)
    }
}

impl IndexField for TestField {
    fn sample(&self, p: DVec3) -> FieldSample<f64> {
        let (n, grad_n) = self.profile.eval(p);
        FieldSample { n, grad_n }
    }
    fn bounds(&self) -> Bounds {
        self.bounds
    }
    fn ambient_index(&self) -> f64 {
        self.ambient
    }
    fn n_range(&self) -> (f64, f64) {
        self.n_range
    }
    fn max_grad_n(&self) -> f64 {
        self.max_grad
    }
    fn describe(&self) -> String {
        format!("{:?}", self.profile)
    }
    fn homogeneous_span(&self, p: DVec3, dir: DVec3) -> Option<f64> {
        if !self.macro_uniform {
            return None;
        }
        self.bounds.intersect(p, dir).map(|(_, s_out)| s_out)
    }
}

/// Minimise `f` over [a, b] by golden-section search (unimodal f).
pub fn golden_min(mut a: f64, mut b: f64, f: impl Fn(f64) -> f64) -> (f64, f64) {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let mut x1 = b - g * (b - a);
    let mut x2 = a + g * (b - a);
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..200 {
        if f1 < f2 {
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - g * (b - a);
            f1 = f(x1);
        } else {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + g * (b - a);
            f2 = f(x2);
        }
        if (b - a).abs() < 1e-15 {
            break;
        }
    }
    let x = 0.5 * (a + b);
    (x, f(x))
}

/// Least-squares slope of log(err) against log(h).
pub fn log_slope(hs: &[f64], errs: &[f64]) -> f64 {
    let xs: Vec<f64> = hs.iter().map(|h| h.ln()).collect();
    let ys: Vec<f64> = errs.iter().map(|e| e.ln()).collect();
    let n = xs.len() as f64;
    let mx = xs.iter().sum::<f64>() / n;
    let my = ys.iter().sum::<f64>() / n;
    let sxy: f64 = xs.iter().zip(&ys).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = xs.iter().map(|x| (x - mx) * (x - mx)).sum();
    sxy / sxx
}
