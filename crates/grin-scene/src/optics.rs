//! `[optics]`: what `grin render` writes instead of a beauty image: pictures of the
//! deflection as measurements and compositing see it (docs/optics.md has the physics and
//! the formulas of each mode).

use serde::{Deserialize, Serialize};

/// An image-space output of the scene's medium.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct OpticsSpec {
    pub mode: OpticsMode,
    /// The background plane that displacement, ST maps and BOS dots are measured on;
    /// left out: at infinity (displacements are then angles). BOS needs a plane.
    #[serde(default)]
    pub plane: Option<PlaneSpec>,
    #[serde(default)]
    pub knife: Knife,
    /// Wavelength of the interferogram, nanometres.
    #[serde(default = "default_wavelength")]
    pub wavelength_nm: f64,
    #[serde(default)]
    pub fringes: Fringes,
    #[serde(default)]
    pub dots: Dots,
    #[serde(default)]
    pub screen: Screen,
    /// The accuracy `step = { auto }` targets for this output, in the output's own unit:
    /// the landing point in pixels (displacement, ST map, BOS; for the shadowgraph, in
    /// the screen's bins), the optical path difference in waves (interferogram). Left
    /// out: [`DEFAULT_OUTPUT_ACCURACY`]. Schlieren's is the exit direction in radians,
    /// by default [`SCHLIEREN_ACCURACY_FRACTION`] of the knife's `source_size_rad` (the
    /// deflection that spans the signal's range).
    #[serde(default)]
    pub accuracy: Option<f64>,
}

/// The default accuracy of a pixel or wave output: a hundredth of a pixel, of a wave.
pub const DEFAULT_OUTPUT_ACCURACY: f64 = 0.01;

/// Schlieren's default accuracy, as a fraction of the knife's `source_size_rad`: a
/// hundredth of the signal's range (a deflection error that small moves the knife-edge
/// intensity by at most 1 % of its span).
pub const SCHLIEREN_ACCURACY_FRACTION: f64 = 0.01;

/// What unit an output's accuracy is asked in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, strum::IntoStaticStr)]
#[strum(serialize_all = "lowercase")]
pub enum AccuracyUnit {
    /// The exit direction, radians (the knob's own).
    #[strum(serialize = "rad")]
    Radians,
    /// Where the ray lands, in image pixels.
    #[strum(serialize = "px")]
    Pixels,
    /// The optical path difference, in waves.
    Waves,
}

impl AccuracyUnit {
    pub fn name(self) -> &'static str {
        self.into()
    }
}

impl OpticsSpec {
    /// The unit this output's accuracy is asked in.
    pub fn accuracy_unit(&self) -> AccuracyUnit {
        match self.mode {
            OpticsMode::Displacement | OpticsMode::Bos | OpticsMode::Shadowgraph => {
                AccuracyUnit::Pixels
            }
            OpticsMode::Interferogram => AccuracyUnit::Waves,
            OpticsMode::Schlieren => AccuracyUnit::Radians,
        }
    }

    /// The accuracy asked in [`OpticsSpec::accuracy_unit`].
    pub fn output_accuracy(&self) -> Option<f64> {
        Some(match self.accuracy_unit() {
            AccuracyUnit::Radians => self
                .accuracy
                .unwrap_or(SCHLIEREN_ACCURACY_FRACTION * self.knife.source_size_rad),
            _ => self.accuracy.unwrap_or(DEFAULT_OUTPUT_ACCURACY),
        })
    }
}

/// Which picture.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize, strum::IntoStaticStr)]
#[serde(rename_all = "kebab-case")]
#[strum(serialize_all = "kebab-case")]
pub enum OpticsMode {
    /// Where each pixel's ray lands on the plane with the medium minus without, in pixels
    /// and in plane units, and the ST map a compositor applies to a plate.
    Displacement,
    /// Knife-edge schlieren.
    Schlieren,
    /// Ray density on a screen behind the medium, collimated light.
    Shadowgraph,
    /// Fringes of the optical path difference.
    Interferogram,
    /// Background-oriented schlieren: a random-dot background seen without and with the
    /// medium, and the true displacement.
    Bos,
}

/// A plane through `point` with normal `normal`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PlaneSpec {
    pub point: [f64; 3],
    pub normal: [f64; 3],
}

/// The knife edge of a schlieren system, in the focal plane of its second mirror.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Knife {
    /// Direction in the image (degrees from +x towards +y up) of the deflections the
    /// knife sees: 0 = a vertical edge, sensitive to horizontal deflection.
    pub angle_deg: f64,
    /// Fraction of the light source's image the edge blocks with no medium (0..1).
    pub cutoff: f64,
    /// Half-size of the light source's image, as a deflection angle (radians): the
    /// deflection that moves the image by its own half-size. Sets the sensitivity and
    /// the range before the signal saturates.
    pub source_size_rad: f64,
}

impl Default for Knife {
    fn default() -> Self {
        Knife {
            angle_deg: 0.0,
            cutoff: 0.5,
            source_size_rad: 1e-4,
        }
    }
}

/// Fringes of an interferogram: `spacing_px` 0 is infinite-fringe (the phase itself),
/// else a carrier of that spacing in pixels, its wave vector at `angle_deg`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Fringes {
    pub spacing_px: f64,
    pub angle_deg: f64,
}

/// The random-dot background of BOS on the plane: dots of `diameter` (plane units, the
/// 1/e^2 width of a Gaussian) covering `density` of the area, placed by `seed`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Dots {
    pub diameter: f64,
    pub density: f64,
    pub seed: u32,
}

impl Default for Dots {
    fn default() -> Self {
        Dots {
            diameter: 0.01,
            density: 0.3,
            seed: 1,
        }
    }
}

/// The shadowgraph screen: perpendicular to the camera's view, `distance` past the
/// medium's centre, `size` (width, height) in world units (default: the medium's
/// bounding box across the view), binned at the render's width x height; the beam is
/// collimated along the view, `rays_per_pixel` (a square number) per bin of the
/// undisturbed beam.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Screen {
    pub distance: f64,
    pub size: Option<[f64; 2]>,
    pub rays_per_pixel: u32,
}

impl Default for Screen {
    fn default() -> Self {
        Screen {
            distance: 1.0,
            size: None,
            rays_per_pixel: 16,
        }
    }
}

fn default_wavelength() -> f64 {
    532.0
}
