//! The scene's `map`: a scalar grid value -> n ([`Mapping`]), with air's index by
//! Gladstone-Dale ([`GladstoneDale`]).

use grin_scene::VdbMap;

use crate::field::FieldError;

/// Air's index by Gladstone-Dale for the scene's `gladstone-dale` parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GladstoneDale {
    pub ambient_temperature_k: f64,
    pub scale_k: f64,
    pub pressure_pa: f64,
    pub k_gd: f64,
    pub r_specific: f64,
}

impl GladstoneDale {
    /// n of air at absolute temperature `t_k` (ideal gas at constant pressure).
    pub fn n_at_temperature(&self, t_k: f64) -> f64 {
        let rho = self.pressure_pa / (self.r_specific * t_k);
        1.0 + self.k_gd * rho
    }

    /// T_K for a (unitless) simulation temperature.
    pub fn temperature_k(&self, value: f64) -> f64 {
        self.ambient_temperature_k + self.scale_k * value
    }
}

/// A scalar grid value -> n mapping (the scene's `map`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Mapping {
    Index { delta: bool },
    Linear { k: f64 },
    GladstoneDale(GladstoneDale),
}

impl Mapping {
    pub fn from_spec(map: &VdbMap) -> Self {
        match *map {
            VdbMap::Index { delta } => Mapping::Index { delta },
            VdbMap::Linear { k } => Mapping::Linear { k },
            VdbMap::GladstoneDale {
                ambient_temperature_k,
                scale_k,
                pressure_pa,
                k_gd,
                r_specific,
            } => Mapping::GladstoneDale(GladstoneDale {
                ambient_temperature_k,
                scale_k,
                pressure_pa,
                k_gd,
                r_specific,
            }),
        }
    }

    /// True where n is an offset from the ambient index (`index` with `delta`, `linear`).
    pub fn is_relative(&self) -> bool {
        matches!(
            self,
            Mapping::Index { delta: true } | Mapping::Linear { .. }
        )
    }

    /// n for one grid value; `Err(T_K)` for a non-positive absolute temperature.
    pub fn n(&self, value: f64, ambient: f64) -> Result<f64, f64> {
        match *self {
            Mapping::Index { delta: false } => Ok(value),
            Mapping::Index { delta: true } => Ok(ambient + value),
            Mapping::Linear { k } => Ok(ambient + k * value),
            Mapping::GladstoneDale(gd) => {
                let t = gd.temperature_k(value);
                if t > 0.0 {
                    Ok(gd.n_at_temperature(t))
                } else {
                    Err(t)
                }
            }
        }
    }

    pub(super) fn describe(&self) -> String {
        match *self {
            Mapping::Index { delta } => format!("index (delta={delta})"),
            Mapping::Linear { k } => format!("linear k={k}"),
            Mapping::GladstoneDale(gd) => format!(
                "gladstone-dale T={}K+{}K*v",
                gd.ambient_temperature_k, gd.scale_k
            ),
        }
    }

    pub(super) fn check(&self, field: &str) -> Result<(), FieldError> {
        let bad = |param: &str, message: &str| {
            Err(FieldError::Param {
                field: field.to_owned(),
                param: param.to_owned(),
                message: message.to_owned(),
            })
        };
        match *self {
            Mapping::Index { .. } => Ok(()),
            Mapping::Linear { k } if !k.is_finite() => bad("k", "must be finite"),
            Mapping::Linear { .. } => Ok(()),
            Mapping::GladstoneDale(gd) => {
                if !(gd.ambient_temperature_k > 0.0 && gd.ambient_temperature_k.is_finite()) {
                    bad(
                        "ambient_temperature_k",
                        "must be a positive temperature in kelvin",
                    )
                } else if !gd.scale_k.is_finite() {
                    bad("scale_k", "must be finite")
                } else if !(gd.pressure_pa > 0.0 && gd.pressure_pa.is_finite()) {
                    bad("pressure_pa", "must be positive")
                } else if !(gd.k_gd >= 0.0 && gd.k_gd.is_finite()) {
                    bad("k_gd", "must be non-negative")
                } else if !(gd.r_specific > 0.0 && gd.r_specific.is_finite()) {
                    bad("r_specific", "must be positive")
                } else {
                    Ok(())
                }
            }
        }
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// Air at 293.15 K and 101325 Pa, 300 K per unit of the grid.
    pub(in crate::vdb) fn gd_default() -> GladstoneDale {
        GladstoneDale {
            ambient_temperature_k: 293.15,
            scale_k: 300.0,
            pressure_pa: 101_325.0,
            k_gd: 2.26e-4,
            r_specific: 287.05,
        }
    }

    /// docs/physics.md, Air: n - 1 at 101325 Pa = 2.92e-4 (0 C), 2.77e-4 (15 C),
    /// 2.72e-4 (20 C), 0.80e-4 (1000 K), 0.53e-4 (1500 K), quoted to 3 significant digits.
    #[test]
    fn gladstone_dale_reproduces_reference_table() {
        let gd = gd_default();
        for (t_k, expected) in [
            (273.15, 2.92e-4),
            (288.15, 2.77e-4),
            (293.15, 2.72e-4),
            (1000.0, 0.80e-4),
            (1500.0, 0.53e-4),
        ] {
            let got = gd.n_at_temperature(t_k) - 1.0;
            assert!(
                (got - expected).abs() <= 0.005e-4,
                "T = {t_k} K: n - 1 = {got:e}, table {expected:e}"
            );
        }
        // The map: value 0 is ambient temperature; value v is T_amb + scale * v.
        let m = Mapping::GladstoneDale(gd);
        let v = (1000.0 - 293.15) / 300.0;
        let n = m.n(v, 1.0).expect("positive T");
        assert!((n - 1.0 - 0.80e-4).abs() < 0.005e-4, "{n}");
        assert!(m.n(-2.0, 1.0).is_err(), "T = 293.15 - 600 K is negative");
    }
}
