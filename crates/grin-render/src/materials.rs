//! Surface optics shared by materials and the medium boundary: reflection, Snell
//! refraction, exact dielectric Fresnel, Schlick's metal Fresnel, the checker pattern.
//! Keep in sync with shaders' `reflect_dir` / `refract_dir` / `fresnel_dielectric`.

use glam::DVec3;

/// Mirror reflection of `d` about the unit normal `n`.
#[inline]
pub fn reflect_dir(d: DVec3, n: DVec3) -> DVec3 {
    d - n * (2.0 * d.dot(n))
}

/// Snell refraction of unit `d` through a surface with unit normal `n` facing against
/// `d` (n . d <= 0), from index `n1` into `n2`. `None` on total internal reflection.
pub fn refract_dir(d: DVec3, n: DVec3, n1: f64, n2: f64) -> Option<DVec3> {
    let eta = n1 / n2;
    let cos_i = -d.dot(n);
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if sin2_t > 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some((d * eta + n * (eta * cos_i - cos_t)).normalize())
}

/// Unpolarised Fresnel reflectance at a dielectric interface for a ray arriving with
/// cosine `cos_i` (> 0) to the normal, from `n1` into `n2`; 1 on total internal reflection.
pub fn fresnel_dielectric(cos_i: f64, n1: f64, n2: f64) -> f64 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin2_t = (n1 / n2).powi(2) * (1.0 - cos_i * cos_i);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t);
    let rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i);
    0.5 * (rs * rs + rp * rp)
}

/// Schlick's approximation with a coloured normal-incidence reflectance `f0` (metals).
pub fn fresnel_schlick(cos_i: f64, f0: DVec3) -> DVec3 {
    let m = (1.0 - cos_i.clamp(0.0, 1.0)).powi(5);
    f0 + (DVec3::ONE - f0) * m
}

/// Checkerboard with squares of side `scale` in the two world axes across the surface's
/// dominant normal axis (x/z on a floor, x/y on a wall facing z): true on `color_a`.
/// Keying on the normal keeps a plane lying at a coordinate of 0 from flickering.
pub fn checker_is_a(p: DVec3, normal: DVec3, scale: f64) -> bool {
    let a = normal.abs();
    let (u, v) = if a.y >= a.x && a.y >= a.z {
        (p.x, p.z)
    } else if a.z >= a.x {
        (p.x, p.y)
    } else {
        (p.y, p.z)
    };
    let iu = (u / scale).floor() as i64;
    let iv = (v / scale).floor() as i64;
    (iu + iv).rem_euclid(2) == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snell_law_holds() {
        let d = DVec3::new(0.5, -(0.75f64).sqrt(), 0.0); // 30 degrees from the normal
        let t = refract_dir(d, DVec3::Y, 1.0, 1.5).expect("refracts");
        // n1 sin(i) = n2 sin(t)
        assert!((1.0 * 0.5 - 1.5 * t.x).abs() < 1e-12);
        assert!((t.length() - 1.0).abs() < 1e-12);
        // Going out at beyond the critical angle (41.8 deg for 1.5): TIR.
        let d = DVec3::new(0.8, -0.6, 0.0);
        assert!(refract_dir(d, DVec3::Y, 1.5, 1.0).is_none());
        assert_eq!(fresnel_dielectric(0.6, 1.5, 1.0), 1.0);
    }

    #[test]
    fn fresnel_normal_incidence_and_symmetry() {
        // ((n1 - n2)/(n1 + n2))^2 = 0.04 for glass at normal incidence.
        assert!((fresnel_dielectric(1.0, 1.0, 1.5) - 0.04).abs() < 1e-12);
        // Equal indices: no reflection at any angle.
        assert!(fresnel_dielectric(0.3, 1.2, 1.2) < 1e-30);
        // Grazing incidence reflects everything.
        assert!((fresnel_dielectric(1e-9, 1.0, 1.5) - 1.0).abs() < 1e-6);
        assert!((fresnel_schlick(1.0, DVec3::splat(0.5)) - DVec3::splat(0.5)).length() < 1e-12);
    }

    #[test]
    fn checker_alternates() {
        let up = DVec3::Y;
        assert!(checker_is_a(DVec3::new(0.5, 0.0, 0.5), up, 1.0));
        assert!(!checker_is_a(DVec3::new(1.5, 0.0, 0.5), up, 1.0));
        assert!(!checker_is_a(DVec3::new(-0.5, 0.0, 0.5), up, 1.0));
        // A floor at y = 0 does not flicker with the sign of y's rounding error.
        assert_eq!(
            checker_is_a(DVec3::new(0.5, 1e-17, 0.5), up, 1.0),
            checker_is_a(DVec3::new(0.5, -1e-17, 0.5), up, 1.0)
        );
        // A wall facing -z alternates in x and y.
        assert!(!checker_is_a(DVec3::new(0.5, 1.5, 3.0), -DVec3::Z, 1.0));
        assert!(checker_is_a(DVec3::new(1.5, 1.5, 3.0), -DVec3::Z, 1.0));
        assert!(reflect_dir(DVec3::new(1.0, -1.0, 0.0), DVec3::Y) == DVec3::new(1.0, 1.0, 0.0));
    }
}
