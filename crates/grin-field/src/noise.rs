//! Procedural noise media (Perlin / fBm / turbulence from the `noise` crate) evaluated at
//! every sample: the paper's baseline, and a source for baking.
//!
//! delta_n(p) = amplitude * envelope(p) * N(frequency * (p - drift * t))
//!
//! - `perlin`: N = perlin(q) (the crate's improved Perlin noise, range about [-1, 1]).
//! - `fbm`: N = sum_i persistence^i perlin_i(lacunarity^i q) / sum_i persistence^i, each
//!   octave with its own seed (`seed + i`), so the peak stays about 1.
//! - `turbulence`: N = 2 * sum_i w_i sabs(perlin_i(..)) / sum_i w_i - 1 with
//!   sabs(x) = sqrt(x^2 + TURBULENCE_SOFTNESS^2): Perlin's |noise| with the kink at the
//!   zero crossings rounded, because a kinked n makes grad n jump (docs/physics.md,
//!   failure mode 4).
//!
//! The envelope fades delta_n to 0 (n to ambient) over the outer `envelope` fraction of
//! the bounds' radius with a C2 quintic smoothstep, so the field has no jump at the surface.
//!
//! Fade curve: `noise` 0.9's `perlin_3d` interpolates with the quintic 6t^5 - 15t^4 + 10t^3
//! (`map_quintic`), so grad n is continuous across lattice planes (a test checks it); the
//! classic cubic fade would make grad n kinked there.
//!
//! Clamp: the crate's `perlin_3d` ends with `clamp(-1, 1)`, and 3D Perlin noise does
//! exceed 1 a little, so the crate's output has flat plateaus with kinked edges (grad n
//! jumps; baked errors there fall at first order only). [`perlin3`] is the same noise (the
//! crate's permutation table, gradient set and quintic fade) without that clamp.
//!
//! The crate has no analytic gradient: grad n is the central difference of delta_n at
//! `GRADIENT_STEP_PER_WAVELENGTH` of the finest octave's wavelength (6 extra evaluations,
//! exactly what the paper pays at every Runge-Kutta stage).

use glam::DVec3;
use grin_scene::{NoiseSpec, NoiseType};
use noise::permutationtable::{NoiseHasher, PermutationTable};

use crate::bounds::Bounds;
use crate::field::{FieldError, FieldSample, IndexField};

/// Central-difference step as a fraction of the finest octave's wavelength: truncation
/// error (2 pi * 1e-3)^2 / 6 ~ 7e-6 relative, round-off far below it.
pub const GRADIENT_STEP_PER_WAVELENGTH: f64 = 1e-3;

/// Rounding of |x| in turbulence (in noise units): keeps grad n continuous at zero crossings.
pub const TURBULENCE_SOFTNESS: f64 = 0.05;

/// Octave cap: beyond this the finest wavelength is far below any bake resolution.
pub const MAX_OCTAVES: u32 = 12;

/// Points per axis of the grid that estimates max |grad n| at construction.
const GRAD_ESTIMATE_POINTS: usize = 20;

/// A procedural noise medium (implements [`IndexField`]).
#[derive(Debug, Clone)]
pub struct NoiseField {
    spec: NoiseSpec,
    bounds: Bounds,
    ambient: f64,
    octaves: Vec<PermutationTable>,
    /// 1 / sum of octave weights.
    norm: f64,
    /// Central-difference step (world units).
    grad_step: f64,
    max_grad: f64,
}

impl NoiseField {
    /// Build from the scene's noise spec; checks the parameters.
    pub fn new(spec: &NoiseSpec, bounds: Bounds, ambient: f64) -> Result<Self, FieldError> {
        let param = |name: &str, message: String| FieldError::Param {
            field: "noise".into(),
            param: name.into(),
            message,
        };
        if spec.octaves == 0 || spec.octaves > MAX_OCTAVES {
            return Err(param(
                "octaves",
                format!("{} is not in 1..={MAX_OCTAVES}", spec.octaves),
            ));
        }
        if !(spec.frequency.is_finite() && spec.frequency > 0.0) {
            return Err(param(
                "frequency",
                format!("{} must be positive", spec.frequency),
            ));
        }
        if !spec.amplitude.is_finite() || spec.amplitude.abs() >= ambient {
            return Err(param(
                "amplitude",
                format!(
                    "{} must be finite and smaller than the ambient index {ambient}",
                    spec.amplitude
                ),
            ));
        }
        if !(spec.lacunarity.is_finite() && spec.lacunarity >= 1.0) {
            return Err(param(
                "lacunarity",
                format!("{} must be >= 1", spec.lacunarity),
            ));
        }
        if !(spec.persistence.is_finite() && spec.persistence > 0.0) {
            return Err(param(
                "persistence",
                format!("{} must be positive", spec.persistence),
            ));
        }
        if !(spec.envelope.is_finite() && (0.0..=1.0).contains(&spec.envelope)) {
            return Err(param(
                "envelope",
                format!("{} is not in [0, 1]", spec.envelope),
            ));
        }
        let count = match spec.noise {
            NoiseType::Perlin => 1,
            NoiseType::Fbm | NoiseType::Turbulence => spec.octaves,
        };
        let octaves: Vec<PermutationTable> = (0..count)
            .map(|i| PermutationTable::new(spec.seed.wrapping_add(i)))
            .collect();
        let weight_sum: f64 = (0..count).map(|i| spec.persistence.powi(i as i32)).sum();
        let finest_frequency = spec.frequency * spec.lacunarity.powi(count as i32 - 1);
        let mut field = NoiseField {
            spec: spec.clone(),
            bounds,
            ambient,
            octaves,
            norm: 1.0 / weight_sum,
            grad_step: GRADIENT_STEP_PER_WAVELENGTH / finest_frequency,
            max_grad: 0.0,
        };
        field.max_grad = field.estimate_max_grad();
        Ok(field)
    }

    /// The same medium at time `t` (seconds): the pattern drifts by `drift * t`.
    pub fn at_time(&self, t: f64) -> Self {
        let mut f = self.clone();
        f.spec.t = t;
        f
    }

    /// The noise spec this field evaluates.
    pub fn spec(&self) -> &NoiseSpec {
        &self.spec
    }

    /// The unit-amplitude noise N(q) at noise-space point q.
    fn noise(&self, q: DVec3) -> f64 {
        let lac = self.spec.lacunarity;
        let pers = self.spec.persistence;
        match self.spec.noise {
            NoiseType::Perlin => perlin3(&self.octaves[0], q),
            NoiseType::Fbm => {
                let (mut sum, mut f, mut w) = (0.0, 1.0, 1.0);
                for o in &self.octaves {
                    sum += w * perlin3(o, q * f);
                    f *= lac;
                    w *= pers;
                }
                sum * self.norm
            }
            NoiseType::Turbulence => {
                let (mut sum, mut f, mut w) = (0.0, 1.0, 1.0);
                let soft2 = TURBULENCE_SOFTNESS * TURBULENCE_SOFTNESS;
                for o in &self.octaves {
                    let v = perlin3(o, q * f);
                    sum += w * (v * v + soft2).sqrt();
                    f *= lac;
                    w *= pers;
                }
                2.0 * sum * self.norm - 1.0
            }
        }
    }

    /// Envelope in [0, 1]: 1 deep inside, 0 at and outside the bounds, C2 in between.
    fn envelope(&self, p: DVec3) -> f64 {
        let width = self.spec.envelope * self.bounds.radius();
        let fade = |depth: f64| {
            if width <= 0.0 {
                return if depth >= 0.0 { 1.0 } else { 0.0 };
            }
            smootherstep((depth / width).clamp(0.0, 1.0))
        };
        match self.bounds {
            Bounds::Sphere { center, radius } => fade(radius - (p - center).length()),
            Bounds::Box { min, max } => {
                let d = (p - min).min(max - p);
                fade(d.x) * fade(d.y) * fade(d.z)
            }
        }
    }

    /// delta_n = n - ambient at world point p.
    pub fn delta_n(&self, p: DVec3) -> f64 {
        let env = self.envelope(p);
        if env == 0.0 {
            return 0.0;
        }
        let drift = DVec3::from_array(self.spec.drift) * self.spec.t;
        self.spec.amplitude * env * self.noise((p - drift) * self.spec.frequency)
    }

    fn estimate_max_grad(&self) -> f64 {
        let (lo, hi) = self.bounds.aabb();
        let m = GRAD_ESTIMATE_POINTS;
        let mut g: f64 = 0.0;
        for k in 0..m {
            for j in 0..m {
                for i in 0..m {
                    let f = (DVec3::new(i as f64, j as f64, k as f64) + 0.5) / m as f64;
                    g = g.max(self.sample(lo + (hi - lo) * f).grad_n.length());
                }
            }
        }
        // Sampled maximum: allow for peaks between the sample points.
        g * 1.5
    }
}

/// Improved Perlin noise at q: `noise` 0.9's `perlin_3d` (same hash, gradients, quintic
/// fade and scale) without its final clamp to [-1, 1], which would kink the field.
pub fn perlin3(table: &PermutationTable, q: DVec3) -> f64 {
    /// The crate's normalisation, 2 / sqrt(3).
    const SCALE_FACTOR: f64 = 1.154_700_538_379_251_5;
    let corner = q.floor();
    let d = q - corner;
    let c = [corner.x as isize, corner.y as isize, corner.z as isize];
    let grad = |ox: isize, oy: isize, oz: isize| {
        let p = d - DVec3::new(ox as f64, oy as f64, oz as f64);
        match table.hash(&[c[0] + ox, c[1] + oy, c[2] + oz]) & 0b1111 {
            0 | 12 => p.x + p.y,
            1 | 13 => -p.x + p.y,
            2 => p.x - p.y,
            3 => -p.x - p.y,
            4 => p.x + p.z,
            5 => -p.x + p.z,
            6 => p.x - p.z,
            7 => -p.x - p.z,
            8 => p.y + p.z,
            9 | 14 => -p.y + p.z,
            10 => p.y - p.z,
            _ => -p.y - p.z,
        }
    };
    let s = DVec3::new(smootherstep(d.x), smootherstep(d.y), smootherstep(d.z));
    let lerp = |a: f64, b: f64, t: f64| a + t * (b - a);
    let x00 = lerp(grad(0, 0, 0), grad(1, 0, 0), s.x);
    let x10 = lerp(grad(0, 1, 0), grad(1, 1, 0), s.x);
    let x01 = lerp(grad(0, 0, 1), grad(1, 0, 1), s.x);
    let x11 = lerp(grad(0, 1, 1), grad(1, 1, 1), s.x);
    lerp(lerp(x00, x10, s.y), lerp(x01, x11, s.y), s.z) * SCALE_FACTOR
}

/// C2 quintic smoothstep 6x^5 - 15x^4 + 10x^3 on [0, 1].
fn smootherstep(x: f64) -> f64 {
    x * x * x * (x * (x * 6.0 - 15.0) + 10.0)
}

impl IndexField for NoiseField {
    fn sample(&self, p: DVec3) -> FieldSample<f64> {
        let h = self.grad_step;
        let d = |e: DVec3| (self.delta_n(p + e * h) - self.delta_n(p - e * h)) / (2.0 * h);
        FieldSample {
            n: self.ambient + self.delta_n(p),
            grad_n: DVec3::new(d(DVec3::X), d(DVec3::Y), d(DVec3::Z)),
        }
    }

    fn n(&self, p: DVec3) -> f64 {
        self.ambient + self.delta_n(p)
    }

    fn bounds(&self) -> Bounds {
        self.bounds
    }

    fn ambient_index(&self) -> f64 {
        self.ambient
    }

    fn n_range(&self) -> (f64, f64) {
        let a = self.spec.amplitude.abs();
        (self.ambient - a, self.ambient + a)
    }

    /// Half the wavelength of the finest octave: 1 / (2 frequency lacunarity^(octaves-1)).
    fn feature_size(&self) -> Option<f64> {
        let octaves = self.octaves.len().max(1) as i32;
        let finest = self.spec.frequency.abs() * self.spec.lacunarity.abs().powi(octaves - 1);
        (finest > 0.0 && finest.is_finite()).then(|| 0.5 / finest)
    }
    fn max_grad_n(&self) -> f64 {
        self.max_grad
    }

    fn describe(&self) -> String {
        let s = &self.spec;
        format!(
            "noise {:?} octaves={} frequency={} amplitude={} seed={} t={}",
            s.noise, s.octaves, s.frequency, s.amplitude, s.seed, s.t
        )
        .to_lowercase()
    }
    fn has_local_step_limits(&self) -> bool {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(noise: NoiseType) -> NoiseSpec {
        NoiseSpec {
            noise,
            octaves: 4,
            frequency: 3.0,
            amplitude: 0.02,
            seed: 7,
            lacunarity: 2.0,
            persistence: 0.5,
            envelope: 0.25,
            drift: [0.3, 0.0, 0.0],
            t: 0.0,
        }
    }

    fn ball() -> Bounds {
        Bounds::Sphere {
            center: DVec3::ZERO,
            radius: 1.0,
        }
    }

    #[test]
    fn envelope_fades_to_ambient_at_the_surface() {
        for kind in [NoiseType::Perlin, NoiseType::Fbm, NoiseType::Turbulence] {
            let f = NoiseField::new(&spec(kind), ball(), 1.0).expect("valid spec");
            for dir in [DVec3::X, DVec3::Y, DVec3::new(1.0, 1.0, 1.0).normalize()] {
                assert_eq!(f.n(dir * 1.0), 1.0);
                assert_eq!(f.n(dir * 1.2), 1.0);
                // Inside the fade, |delta_n| is bounded by amplitude * envelope.
                let p = dir * 0.9;
                assert!((f.n(p) - 1.0).abs() <= 0.02 * smootherstep(0.4) + 1e-12);
            }
            let (lo, hi) = f.n_range();
            let mut any = false;
            for i in 0..200 {
                let p = DVec3::new(
                    (i as f64 * 0.37).sin(),
                    (i as f64 * 0.71).cos(),
                    (i as f64 * 0.13).sin(),
                ) * 0.7;
                let n = f.n(p);
                assert!(n >= lo && n <= hi, "{kind:?}: n = {n} outside [{lo}, {hi}]");
                any |= (n - 1.0).abs() > 1e-3;
            }
            assert!(any, "{kind:?}: the noise should vary inside the ball");
        }
    }

    #[test]
    fn gradient_matches_finite_differences_of_n() {
        let f = NoiseField::new(&spec(NoiseType::Fbm), ball(), 1.0).expect("valid spec");
        let h = 1e-5;
        for i in 0..50 {
            let p = DVec3::new(
                (i as f64 * 1.3).sin(),
                (i as f64 * 0.7).cos(),
                (i as f64 * 2.1).sin(),
            ) * 0.5;
            let g = f.sample(p).grad_n;
            let fd = DVec3::new(
                (f.n(p + DVec3::X * h) - f.n(p - DVec3::X * h)) / (2.0 * h),
                (f.n(p + DVec3::Y * h) - f.n(p - DVec3::Y * h)) / (2.0 * h),
                (f.n(p + DVec3::Z * h) - f.n(p - DVec3::Z * h)) / (2.0 * h),
            );
            assert!((g - fd).length() <= 1e-4 * f.max_grad_n(), "{g} vs {fd}");
        }
    }

    /// The crate's fade is quintic: d2n/dx2 has no jump across a lattice plane. The classic
    /// cubic fade (s'' = 6 at t = 0, -6 at t = 1) would make it jump by ~12 x the corner
    /// gradient terms, i.e. grad n kinked (docs/physics.md, failure mode 4).
    #[test]
    fn gradient_is_smooth_across_lattice_planes() {
        let mut s = spec(NoiseType::Perlin);
        s.frequency = 1.0;
        s.envelope = 0.0;
        let big = Bounds::Sphere {
            center: DVec3::ZERO,
            radius: 100.0,
        };
        let f = NoiseField::new(&s, big, 1.0).expect("valid spec");
        let eps = 1e-4;
        let d2 = |p: DVec3| {
            (f.n(p + DVec3::X * eps) - 2.0 * f.n(p) + f.n(p - DVec3::X * eps)) / (eps * eps)
        };
        let (mut worst_jump, mut typical): (f64, f64) = (0.0, 0.0);
        for i in 0..40 {
            // The plane x = 2 of the noise lattice, at assorted y, z; stencils stay on one side.
            let y = 0.1 + 0.173 * i as f64;
            let z = 0.3 + 0.291 * i as f64;
            let left = d2(DVec3::new(2.0 - 3e-4, y, z));
            let right = d2(DVec3::new(2.0 + 3e-4, y, z));
            worst_jump = worst_jump.max((left - right).abs());
            // Mid-cell curvature sets the scale (at the plane itself a quintic fade has s'' = 0).
            typical = typical.max(d2(DVec3::new(2.5, y, z)).abs());
        }
        assert!(typical > 1e-3, "the test must see curvature ({typical})");
        assert!(
            worst_jump < 0.05 * typical,
            "d2n/dx2 jumps by {worst_jump} (max {typical})"
        );
    }

    /// perlin3 is the crate's Perlin noise wherever the crate does not clamp, and smooth
    /// where it does.
    #[test]
    fn perlin3_matches_the_crate_without_its_clamp() {
        use noise::NoiseFn;
        let crate_noise = noise::Perlin::new(4);
        let table = PermutationTable::new(4);
        let mut clamped = 0;
        for i in 0..20_000 {
            let q = DVec3::new(
                (i as f64 * 0.0137).sin() * 7.0,
                (i as f64 * 0.0291).cos() * 5.0 - 2.0,
                i as f64 * 3.1e-4,
            );
            let (ours, theirs) = (perlin3(&table, q), crate_noise.get(q.to_array()));
            if theirs.abs() < 1.0 {
                assert!((ours - theirs).abs() < 1e-12, "at {q}: {ours} vs {theirs}");
            } else {
                clamped += 1;
                assert!(ours.abs() >= 1.0);
            }
        }
        // The line the bake found: the crate clamps at q2.x ~ -0.042; perlin3 stays smooth.
        let q = |x: f64| DVec3::new(x, 0.5017926347636392, 1.4929993569728819);
        let h = 1e-3;
        let d2 = |x: f64| {
            (perlin3(&table, q(x + h)) - 2.0 * perlin3(&table, q(x)) + perlin3(&table, q(x - h)))
                / (h * h)
        };
        assert!(crate_noise.get(q(-0.03).to_array()) == -1.0 && perlin3(&table, q(-0.03)) < -1.0);
        let kink = (d2(-0.0425) - d2(-0.0415)).abs();
        assert!(
            kink < 0.05 * d2(-0.0425).abs().max(1.0),
            "perlin3 kinked: {kink}"
        );
        eprintln!("{clamped} of 20000 crate samples clamped");
    }

    #[test]
    fn drift_translates_the_pattern() {
        let f0 = NoiseField::new(&spec(NoiseType::Fbm), ball(), 1.0).expect("valid spec");
        let f1 = f0.at_time(0.5);
        let shift = DVec3::new(0.15, 0.0, 0.0);
        let p = DVec3::new(0.1, 0.2, -0.1);
        // Deep inside (envelope 1) the field at t moves with the drift.
        assert!((f1.n(p + shift) - f0.n(p)).abs() < 1e-15);
        assert!((f1.n(p) - f0.n(p)).abs() > 1e-6);
    }

    #[test]
    fn bad_parameters_are_named() {
        let mut s = spec(NoiseType::Fbm);
        s.octaves = 0;
        let e = NoiseField::new(&s, ball(), 1.0).expect_err("octaves 0");
        assert!(e.to_string().contains("octaves"), "{e}");
        let mut s = spec(NoiseType::Fbm);
        s.frequency = -1.0;
        let e = NoiseField::new(&s, ball(), 1.0).expect_err("negative frequency");
        assert!(e.to_string().contains("frequency"), "{e}");
    }
}
