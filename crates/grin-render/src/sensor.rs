//! The sensor of a measurement camera: photon shot noise, read noise, saturation and
//! quantisation applied to a linear image whose value 1 is the full well. Deterministic:
//! each value's noise comes from its index, the image's `stream` and the seed.

use grin_scene::Sensor;

use crate::rng::{Rng, pcg_hash};

/// A standard normal number from two uniforms (Box-Muller).
fn normal(rng: &mut Rng) -> f64 {
    let u1 = f64::from(rng.next_f32()).max(1e-12);
    let u2 = f64::from(rng.next_f32());
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// A Poisson number of mean `lambda`: exact (Knuth's product of uniforms) below 30,
/// the normal approximation rounded above it (its skew is then below 0.2).
fn poisson(lambda: f64, rng: &mut Rng) -> f64 {
    if lambda <= 0.0 {
        return 0.0;
    }
    if lambda < 30.0 {
        let limit = (-lambda).exp();
        let mut k = 0.0;
        let mut p = f64::from(rng.next_f32());
        while p > limit {
            k += 1.0;
            p *= f64::from(rng.next_f32());
        }
        return k;
    }
    (lambda + lambda.sqrt() * normal(rng)).round().max(0.0)
}

/// `value` as the sensor records it: electrons (Poisson of value x full well, plus
/// Gaussian read noise) back in units of the full well, clipped to [0, 1] (saturation,
/// no negative signal) and rounded to `bits`. A sensor with everything off returns
/// `value` unchanged.
pub fn record(sensor: &Sensor, value: f64, index: u32, stream: u32) -> f64 {
    let quantise = sensor.bits > 0;
    if sensor.full_well <= 0.0 && !quantise {
        return value;
    }
    let mut v = value;
    if sensor.full_well > 0.0 {
        let seed = pcg_hash(sensor.seed as u32 ^ pcg_hash((sensor.seed >> 32) as u32));
        let mut rng = Rng::for_pixel(index, stream, seed);
        let electrons = poisson(value.max(0.0) * sensor.full_well, &mut rng)
            + sensor.read_noise * normal(&mut rng);
        v = electrons / sensor.full_well;
    }
    v = v.clamp(0.0, 1.0);
    if quantise {
        let levels = f64::from((1u32 << sensor.bits) - 1);
        v = (v * levels).round() / levels;
    }
    v
}

/// Apply [`record`] to every value of `values` (interleaved channels count as values),
/// as image `stream` (two images of one exposure pair get different streams).
pub fn record_all(sensor: &Sensor, values: &mut [f64], stream: u32) {
    for (i, v) in values.iter_mut().enumerate() {
        if v.is_finite() {
            *v = record(sensor, *v, i as u32, stream);
        }
    }
}

/// Apply [`record`] to a frame's RGB (stream 0; the AOVs stay as traced).
pub fn record_frame(sensor: &Sensor, frame: &mut crate::image::Frame) {
    for (i, p) in frame.pixels.iter_mut().enumerate() {
        for (c, v) in p.rgb.iter_mut().enumerate() {
            if v.is_finite() {
                *v = record(sensor, f64::from(*v), (i * 3 + c) as u32, 0) as f32;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stats(v: &[f64]) -> (f64, f64) {
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
        (mean, var.sqrt())
    }

    #[test]
    fn shot_and_read_noise_have_their_variance() {
        // Mean 0.25 of a 1000 e- well: 250 e- shot noise (sd 15.8) and 3 e- read noise:
        // sd sqrt(250 + 9) / 1000 = 0.01609; 12 bits add 1/4095/sqrt(12) = 7e-5.
        let s = Sensor {
            full_well: 1000.0,
            read_noise: 3.0,
            bits: 12,
            seed: 9,
        };
        let mut v = vec![0.25; 40_000];
        record_all(&s, &mut v, 0);
        let (mean, sd) = stats(&v);
        assert!((mean - 0.25).abs() < 5e-4, "{mean}");
        assert!((sd / 0.01609 - 1.0).abs() < 0.03, "{sd}");
        assert!(
            v.iter()
                .all(|x| (x * 4095.0 - (x * 4095.0).round()).abs() < 1e-9)
        );
        // Small counts take the exact Poisson: mean 2 e- has variance 2 e-^2.
        let s = Sensor {
            full_well: 100.0,
            read_noise: 0.0,
            bits: 0,
            seed: 3,
        };
        let mut v = vec![0.02; 40_000];
        record_all(&s, &mut v, 1);
        let (mean, sd) = stats(&v);
        assert!((mean - 0.02).abs() < 4e-4, "{mean}");
        assert!(((sd * 100.0).powi(2) / 2.0 - 1.0).abs() < 0.04, "{sd}");
        assert!(
            v.iter()
                .all(|x| (x * 100.0 - (x * 100.0).round()).abs() < 1e-9)
        );
    }

    #[test]
    fn saturation_quantisation_and_off() {
        let bits8 = Sensor {
            bits: 8,
            ..Sensor::default()
        };
        assert_eq!(record(&bits8, 2.0, 0, 0), 1.0);
        assert_eq!(record(&bits8, -0.5, 0, 0), 0.0);
        assert_eq!(record(&bits8, 0.5, 0, 0), 128.0 / 255.0);
        assert_eq!(record(&Sensor::default(), 7.25, 0, 0), 7.25);
        // Same seed, same noise; another stream, another draw.
        let s = Sensor {
            full_well: 500.0,
            ..Sensor::default()
        };
        assert_eq!(record(&s, 0.3, 5, 0), record(&s, 0.3, 5, 0));
        assert_ne!(record(&s, 0.3, 5, 0), record(&s, 0.3, 5, 1));
    }
}
