//! The scene types, one struct per TOML table. Field names are the TOML keys.
//! Vectors are `[f64; 3]` in world space; lengths are world units (metres where a
//! scene says so).
//!
//! One concept, one file: a type per TOML table, the scene contract in one place.

use serde::{Deserialize, Serialize};

use crate::ambient::AmbientIndex;

/// A whole scene file.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    pub camera: Camera,
    #[serde(default, rename = "object")]
    pub objects: Vec<Object>,
    pub medium: Option<MediumSpec>,
    #[serde(default, rename = "light")]
    pub lights: Vec<Light>,
    #[serde(default)]
    pub sky: Sky,
    #[serde(default)]
    pub render: RenderSettings,
    /// A frame range and rate: the medium's path may hold a frame token (`####`,
    /// `%04d`, `$F4`), and noise / `expr` time follows the frame (`t + frame / fps`).
    #[serde(default)]
    pub animation: Option<Animation>,
    /// An image-space output instead of the beauty render (`grin render` writes it).
    #[serde(default)]
    pub optics: Option<crate::optics::OpticsSpec>,
    /// Sensor noise and bit depth applied to the written images.
    #[serde(default)]
    pub sensor: Option<Sensor>,
}

/// `[animation]`: `frames = [first, last]` (inclusive) at `fps` frames per second.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Animation {
    pub frames: [i64; 2],
    #[serde(default = "default_fps")]
    pub fps: f64,
}

/// `fn name() -> T { value }` for each `name: T = value;`: the functions serde's
/// `default = "name"` calls.
macro_rules! defaults {
    ($($(#[$doc:meta])* $name:ident: $t:ty = $v:expr;)*) => {
        $($(#[$doc])* fn $name() -> $t { $v })*
    };
}

defaults! {
    default_fps: f64 = 24.0;
}

/// The camera: a pinhole with a vertical field of view, or a lens described as a
/// measurement would (focal length and sensor height in mm, or the pixel pitch; loading
/// turns them into `fov_y_deg`), with a thin-lens aperture (`f_number`: defocus blur
/// away from `focus_distance`, world units taken as metres for the aperture's size).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    pub position: [f64; 3],
    pub look_at: [f64; 3],
    #[serde(default = "default_up")]
    pub up: [f64; 3],
    #[serde(default = "default_fov")]
    pub fov_y_deg: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focal_length_mm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_height_mm: Option<f64>,
    /// With `focal_length_mm`: the sensor height is the pitch times `[render] height`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pixel_pitch_um: Option<f64>,
    /// Aperture diameter = focal length / f_number (needs `focal_length_mm`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub f_number: Option<f64>,
    /// Distance in focus along the view (default: from `position` to `look_at`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focus_distance: Option<f64>,
}

impl Camera {
    /// A pinhole camera.
    pub fn pinhole(position: [f64; 3], look_at: [f64; 3], up: [f64; 3], fov_y_deg: f64) -> Self {
        Camera {
            position,
            look_at,
            up,
            fov_y_deg,
            focal_length_mm: None,
            sensor_height_mm: None,
            pixel_pitch_um: None,
            f_number: None,
            focus_distance: None,
        }
    }

    /// The thin lens's aperture diameter in world units (metres) and the distance in
    /// focus; `None` for a pinhole.
    pub fn aperture(&self) -> Option<(f64, f64)> {
        let (f, n) = (self.focal_length_mm?, self.f_number?);
        let focus = self.focus_distance.unwrap_or_else(|| {
            (0..3)
                .map(|i| (self.look_at[i] - self.position[i]).powi(2))
                .sum::<f64>()
                .sqrt()
        });
        Some((f / 1000.0 / n, focus))
    }
}

/// `[sensor]`: what a camera's sensor does to the linear image (values in [0, 1] of its
/// full well): photon shot noise (Poisson, `full_well` electrons at 1), Gaussian read
/// noise (`read_noise` electrons rms), saturation at 1, and quantisation to `bits`.
/// 0 turns each off. Applied to the beauty image and the `[optics]` intensity images.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Sensor {
    pub full_well: f64,
    pub read_noise: f64,
    pub bits: u32,
    pub seed: u64,
}

impl Default for Sensor {
    fn default() -> Self {
        Sensor {
            full_well: 0.0,
            read_noise: 0.0,
            bits: 0,
            seed: 1,
        }
    }
}

defaults! {
    default_up: [f64; 3] = [0.0, 1.0, 0.0];
    default_fov: f64 = 40.0;
}

/// A scene object: a shape and its material.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Object {
    pub shape: Shape,
    #[serde(default)]
    pub material: Material,
}

/// Geometric primitives. TOML: `shape = { sphere = { center = [..], radius = .. } }`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum Shape {
    Sphere {
        center: [f64; 3],
        radius: f64,
    },
    /// Infinite plane through `point` with unit `normal` (normalised on load).
    Plane {
        #[serde(default)]
        point: [f64; 3],
        #[serde(default = "default_up")]
        normal: [f64; 3],
    },
    Box {
        min: [f64; 3],
        max: [f64; 3],
    },
}

/// Surface materials. TOML: either a bare name (`material = "glass"`, defaults for all
/// parameters) or a table (`material = { glass = { ior = 1.5 } }`).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Material {
    Diffuse {
        color: [f64; 3],
    },
    /// Two-colour checkerboard with square size `scale`, in the two world axes across the
    /// surface's dominant normal axis (x/z on a floor, x/y on a wall facing z).
    Checker {
        color_a: [f64; 3],
        color_b: [f64; 3],
        scale: f64,
    },
    /// Perfect mirror with a tint.
    Mirror {
        color: [f64; 3],
    },
    /// Metal: mirror with Schlick Fresnel from `color` (the normal-incidence reflectance).
    Metal {
        color: [f64; 3],
    },
    /// Dielectric with Fresnel reflection and total internal reflection.
    Glass {
        ior: f64,
        color: [f64; 3],
    },
    /// An image on a plane or a box (PNG: sRGB, decoded to linear; EXR or HDR: linear;
    /// `path` relative to the scene file), times `color`. On a plane it is `size`
    /// (width, height) world units centred on `center` (default: the plane's point),
    /// along the plane's axes (grin_render::surface::face_axes); on a box it spans each
    /// face. Outside the image: `border`, or the image again with `repeat`. `emissive`:
    /// the surface shows the image as it is, unlit (a backlit plate); else the image is
    /// the diffuse albedo.
    Texture {
        path: String,
        #[serde(skip_serializing_if = "Option::is_none")]
        size: Option<[f64; 2]>,
        #[serde(skip_serializing_if = "Option::is_none")]
        center: Option<[f64; 3]>,
        repeat: bool,
        border: [f64; 3],
        color: [f64; 3],
        emissive: bool,
    },
    /// The random-dot background of BOS experiments on a plane or a box: Gaussian dots
    /// of 1/e^2 `diameter` (world units) covering `density` of the area, placed by
    /// `seed`, in `color` over `background`; plane coordinates from `center` (default:
    /// the plane's point or the box face's centre) along the face's axes. The same
    /// pattern as `[optics] mode = "bos"` with the same dots on the same plane.
    Dots {
        diameter: f64,
        density: f64,
        seed: u32,
        color: [f64; 3],
        background: [f64; 3],
        #[serde(skip_serializing_if = "Option::is_none")]
        center: Option<[f64; 3]>,
        emissive: bool,
    },
}

impl Default for Material {
    fn default() -> Self {
        Material::Diffuse {
            color: [0.8, 0.8, 0.8],
        }
    }
}

/// The medium: a region of space (the bounds) where n varies, set in ambient space of
/// index `ambient_index` (a number or `"auto"`; see [`AmbientIndex`]).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MediumSpec {
    pub bounds: BoundsSpec,
    #[serde(default, skip_serializing_if = "AmbientIndex::is_unset")]
    pub ambient_index: AmbientIndex,
    pub field: FieldSpec,
}

/// Medium bounds. TOML: `{ sphere = { center, radius } }` or `{ box = { min, max } }`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum BoundsSpec {
    Sphere { center: [f64; 3], radius: f64 },
    Box { min: [f64; 3], max: [f64; 3] },
}

/// The refractive index field of the medium, selected by `kind`. The parameters of each
/// profile, their defaults and formulas are documented in grin-field's `analytic`
/// module; coordinates are relative to the bounds' centre unless a field says otherwise.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum FieldSpec {
    /// n = `n` everywhere inside the bounds (a constant-index ball or box).
    Uniform { n: f64 },
    /// n^2 = n0^2 + k * (coordinate along `axis` relative to the bounds' centre).
    LinearN2 {
        n0: f64,
        k: f64,
        #[serde(default = "default_axis_y")]
        axis: Axis,
    },
    /// GRIN rod (SELFOC) along `axis`: n^2 = n0^2 (1 - a^2 rho^2), rho the distance from
    /// the axis through the bounds' centre.
    GrinRod {
        n0: f64,
        a: f64,
        #[serde(default = "default_axis_z")]
        axis: Axis,
    },
    /// Luneburg lens: n^2 = 2 - (r/R)^2, R the bounds' radius (or `radius`).
    Luneburg {
        #[serde(default)]
        radius: Option<f64>,
    },
    /// Maxwell fish-eye: n = n0 / (1 + (r/a)^2).
    MaxwellFishEye { n0: f64, a: f64 },
    /// Eaton lens: n^2 = 2R/r - 1 with the core r < core * R replaced by its value at the core.
    Eaton {
        #[serde(default)]
        radius: Option<f64>,
        #[serde(default = "default_eaton_core")]
        core: f64,
    },
    /// Stratified exponential atmosphere: n = 1 + e * exp(-h / scale_height), h the height
    /// along `axis` above `base` (world coordinate).
    ExponentialAtmosphere {
        e: f64,
        scale_height: f64,
        #[serde(default)]
        base: f64,
        #[serde(default = "default_axis_y")]
        axis: Axis,
    },
    /// Gaussian hot-air plumes: n = n_amb - sum a_i exp(-|r - c_i|^2 / s_i^2) (world coordinates).
    Plume { plumes: Vec<PlumeBlob> },
    /// A user formula in x, y, z (world coordinates) and t (time, seconds).
    Expr {
        n: String,
        #[serde(default)]
        t: f64,
    },
    /// Perlin / fBm / turbulence noise in index units (grin-field `noise` module).
    Noise(NoiseSpec),
    /// An OpenVDB grid mapped to n (grin-field `vdb` module).
    Vdb(VdbSpec),
    /// A baked `.grinf` file (path relative to the scene file). `interpolation` overrides
    /// the one stored in the file's header (chosen at bake time with `grin bake --interp`).
    Baked {
        path: String,
        #[serde(default)]
        interpolation: Option<Interpolation>,
    },
}

impl FieldSpec {
    /// The file the field reads (a VDB or a baked `.grinf`, as the scene file writes it:
    /// relative to its directory, perhaps with a frame token), if any.
    pub fn file(&self) -> Option<&str> {
        match self {
            FieldSpec::Vdb(v) => Some(&v.path),
            FieldSpec::Baked { path, .. } => Some(path),
            _ => None,
        }
    }
}

defaults! {
    default_axis_y: Axis = Axis::Y;
    default_axis_z: Axis = Axis::Z;
    default_eaton_core: f64 = 0.02;
}

/// A coordinate axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize, strum::IntoStaticStr)]
#[serde(rename_all = "lowercase")]
#[strum(serialize_all = "lowercase")]
pub enum Axis {
    X,
    Y,
    Z,
}

/// One Gaussian plume: amplitude `a` (index units, positive = hotter = lower n),
/// centre `center` (world), width `s` (world).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PlumeBlob {
    pub a: f64,
    pub center: [f64; 3],
    pub s: f64,
}

/// Procedural noise medium. delta_n = amplitude * noise(frequency * p + drift * t) * envelope.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseSpec {
    #[serde(default = "default_noise_type")]
    pub noise: NoiseType,
    #[serde(default = "default_octaves")]
    pub octaves: u32,
    #[serde(default = "default_frequency")]
    pub frequency: f64,
    /// Peak delta_n in index units.
    pub amplitude: f64,
    #[serde(default)]
    pub seed: u32,
    #[serde(default = "default_lacunarity")]
    pub lacunarity: f64,
    #[serde(default = "default_persistence")]
    pub persistence: f64,
    /// Fraction of the bounds' half-size over which the field fades to ambient.
    #[serde(default = "default_envelope")]
    pub envelope: f64,
    /// Drift velocity of the noise pattern (world units per second) for animation.
    #[serde(default)]
    pub drift: [f64; 3],
    /// Time (seconds) at which the field is evaluated.
    #[serde(default)]
    pub t: f64,
}

defaults! {
    default_noise_type: NoiseType = NoiseType::Fbm;
    default_octaves: u32 = 4;
    default_frequency: f64 = 3.0;
    default_lacunarity: f64 = 2.0;
    default_persistence: f64 = 0.5;
    default_envelope: f64 = 0.25;
}

/// Which noise.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum NoiseType {
    Perlin,
    Fbm,
    Turbulence,
}

/// An OpenVDB grid as the index source.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct VdbSpec {
    pub path: String,
    pub grid: String,
    pub map: VdbMap,
    /// Metres per VDB world unit.
    #[serde(default = "default_units")]
    pub units: f64,
    /// What to do with NaN/Inf voxels.
    #[serde(default)]
    pub non_finite: NonFinitePolicy,
    /// The cache's up axis: `"y"` (grin, Houdini) or `"z"` (Blender), turned to the
    /// scene's +y.
    #[serde(default)]
    pub up: UpAxis,
    /// Uniform scale about the scene origin, after `units` and `up`.
    #[serde(default = "default_units")]
    pub scale: f64,
    /// Rotations in degrees about the scene's x, then y, then z axes, after `scale`.
    #[serde(default)]
    pub rotate_deg: [f64; 3],
    /// Translation in scene metres, last.
    #[serde(default)]
    pub translate: [f64; 3],
}

/// Which axis of a VDB cache points up.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum UpAxis {
    #[default]
    Y,
    Z,
}

defaults! {
    default_units: f64 = 1.0;
}

/// How a VDB grid value becomes n.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum VdbMap {
    /// The grid is n itself (`delta = false`) or n - n_ambient (`delta = true`).
    Index {
        #[serde(default)]
        delta: bool,
    },
    /// n = n_amb + k * value.
    Linear { k: f64 },
    /// Air by Gladstone-Dale: T_K = ambient_temperature_k + scale_k * value,
    /// rho = pressure_pa / (r_specific * T_K), n = 1 + k_gd * rho.
    GladstoneDale {
        #[serde(default = "default_t_amb")]
        ambient_temperature_k: f64,
        #[serde(default = "default_scale_k")]
        scale_k: f64,
        #[serde(default = "default_pressure")]
        pressure_pa: f64,
        #[serde(default = "default_k_gd")]
        k_gd: f64,
        #[serde(default = "default_r_specific")]
        r_specific: f64,
    },
}

defaults! {
    default_t_amb: f64 = 293.15;
    default_scale_k: f64 = 300.0;
    /// Standard atmosphere, Pa (docs/physics.md, Air).
    default_pressure: f64 = 101_325.0;
    /// Gladstone-Dale constant of air in the visible, m^3/kg (docs/physics.md, Air).
    default_k_gd: f64 = 2.26e-4;
    /// Specific gas constant of dry air, J/(kg K).
    default_r_specific: f64 = 287.05;
}

/// Policy for NaN/Inf voxels in imported grids.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum NonFinitePolicy {
    #[default]
    Reject,
    Ambient,
}

/// Lights. TOML: `point = { position, intensity }` or `directional = { direction, intensity }`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum Light {
    Point {
        position: [f64; 3],
        intensity: [f64; 3],
    },
    /// `direction` is the direction the light travels.
    Directional {
        direction: [f64; 3],
        intensity: [f64; 3],
    },
}

/// Background seen by rays that leave the scene.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum Sky {
    /// A vertical gradient from `horizon` to `zenith`, `ground` below the horizon.
    Gradient {
        horizon: [f64; 3],
        zenith: [f64; 3],
        ground: [f64; 3],
    },
    /// An equirectangular EXR or HDR environment map (path relative to the scene file).
    Map {
        path: String,
        #[serde(default = "default_one")]
        intensity: f64,
    },
    /// A background plate (PNG, EXR or HDR, path relative to the scene file) at
    /// infinity, filling the scene camera's view: without a medium, pixel (i, j) of the
    /// render shows the plate at the same place (scaled when the sizes differ); through
    /// the medium it is distorted. Directions behind the camera see black, beyond the
    /// frame the plate's edge. Diffuse surfaces are lit by its mean colour.
    Plate {
        path: String,
        #[serde(default = "default_one")]
        intensity: f64,
    },
}

defaults! {
    default_one: f64 = 1.0;
}

impl Default for Sky {
    fn default() -> Self {
        Sky::Gradient {
            horizon: [0.9, 0.9, 0.95],
            zenith: [0.35, 0.55, 0.9],
            ground: [0.3, 0.28, 0.25],
        }
    }
}

/// The ray integrators (t-parameter form r'' = n grad n).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
#[derive(strum::IntoStaticStr, strum::EnumString, strum::VariantNames)]
#[strum(serialize_all = "kebab-case")]
pub enum IntegratorKind {
    Euler,
    SymplecticEuler,
    Verlet,
    Sharma,
    Rk4,
    /// Embedded Dormand-Prince 5(4) pair with error control.
    Adaptive,
}

impl IntegratorKind {
    pub const ALL: [IntegratorKind; 6] = [
        IntegratorKind::Euler,
        IntegratorKind::SymplecticEuler,
        IntegratorKind::Verlet,
        IntegratorKind::Sharma,
        IntegratorKind::Rk4,
        IntegratorKind::Adaptive,
    ];

    /// The TOML / command-line name.
    pub fn name(self) -> &'static str {
        self.into()
    }

    /// Parse a command-line name.
    pub fn from_name(s: &str) -> Option<Self> {
        s.parse().ok()
    }
}

/// How long each step is. Lengths are world lengths ds (the integrator converts to the
/// t parameter by dt = ds / n at the step's start).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum StepSpec {
    Fixed(f64),
    /// The paper's heuristic: lerp(max, min, |dir . grad n| / amplitude); amplitude
    /// defaults to the field's max |grad n|.
    Heuristic {
        min: f64,
        max: f64,
        #[serde(default)]
        amplitude: Option<f64>,
    },
    /// Error-controlled: local error per step <= tolerance (world length units).
    Adaptive {
        tolerance: f64,
        #[serde(default)]
        initial: Option<f64>,
    },
    /// The accuracy knob: error control for a worst exit-direction error of about this
    /// many radians. `step = { auto = 1e-4 }`. Steps are held to an error (the tracer's
    /// norm: position, or direction error times the medium's radius) of at most
    /// [`AUTO_TOL_PER_RAD`] x accuracy per unit of path length, so the errors of a path
    /// of length L add up to at most that times L whatever the integrator's order
    /// (`grin bench accuracy` measures what each delivers; docs/accuracy.md).
    Auto(f64),
}

/// Error per unit path length per radian of asked exit-direction error: a ray crossing
/// the medium's diameter (2 radii) accumulates at most the asked error.
pub const AUTO_TOL_PER_RAD: f64 = 0.5;

/// The default step: `auto` at this exit-direction error (rad), about a thirtieth of a
/// pixel of a 60 degree, 640-pixel-wide view.
pub const DEFAULT_AUTO_ACCURACY: f64 = 1e-4;

/// Pilot rays a render or a ray table traces to resolve `auto` (`[render] pilot_rays`).
pub const DEFAULT_PILOT_RAYS: u32 = 64;

/// The integrator a scene runs when it names none and the pilots do not choose: the
/// Dormand-Prince pair for `auto` (its error control is the cheapest per length,
/// docs/accuracy.md), else Sharma's (the paper's).
pub fn default_integrator(step: &StepSpec) -> IntegratorKind {
    match step {
        StepSpec::Auto(_) => IntegratorKind::Adaptive,
        _ => IntegratorKind::Sharma,
    }
}

impl RenderSettings {
    /// The exit-direction error (rad) a ray is asked for, above which its own error
    /// estimate makes it `degraded`: what the pilots resolved, else the `auto` value,
    /// else (a step the scene fixed) [`DEFAULT_AUTO_ACCURACY`].
    pub fn accuracy(&self) -> f64 {
        self.resolved_accuracy.unwrap_or(match self.step {
            StepSpec::Auto(a) => a,
            _ => DEFAULT_AUTO_ACCURACY,
        })
    }

    /// The integration error estimate (rad) above which a ray is `degraded`: what the
    /// pilots vouched for, else [`Self::accuracy`].
    pub fn estimate_limit(&self) -> f64 {
        self.resolved_estimate_limit
            .unwrap_or_else(|| self.accuracy())
    }

    /// The integrator the scene names, or [`default_integrator`] of its step.
    pub fn integrator(&self) -> IntegratorKind {
        self.integrator
            .unwrap_or_else(|| default_integrator(&self.step))
    }
}

/// How the exit point on the bounds is found on the step that leaves the medium.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
#[derive(strum::IntoStaticStr)]
#[strum(serialize_all = "kebab-case")]
pub enum ExitMethod {
    /// Bisection on the step length (the paper's method).
    Bisection,
    /// Root of the step's cubic Hermite dense output, then a re-step to it.
    #[default]
    Hermite,
}

/// Render and tracing settings (`[render]`).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RenderSettings {
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub max_depth: u32,
    /// `None` (the key left out): with `step = { auto = ... }` the pilot rays choose the
    /// integrator too; with any other step, sharma.
    pub integrator: Option<IntegratorKind>,
    pub step: StepSpec,
    /// Rays traced before the render to resolve `step = { auto = ... }`
    /// (`grin_trace::auto`); 0: no pilots, error control per length on every ray.
    pub pilot_rays: u32,
    /// Per-ray cap on integration steps; a ray that hits it ends as `max_steps`.
    pub max_steps: u32,
    pub exit: ExitMethod,
    /// Fly straight through macro cells where |grad n| is ~0 (baked fields).
    pub macro_cells: bool,
    /// Jitter each pixel ray's first step by a random fraction (turns banding into noise).
    pub jitter: bool,
    /// Bend shadow rays through the medium (false: straight, as in the paper).
    pub bend_shadow_rays: bool,
    /// Seed for jitter and sampling.
    pub seed: u64,
    /// The exit-direction error (rad) rays are held to when the pilots resolved `auto`
    /// (or an output's accuracy) into another step: not a key of its own, see
    /// [`RenderSettings::accuracy`].
    #[serde(skip)]
    pub resolved_accuracy: Option<f64>,
    /// ... and the integration error estimate the pilots vouch for
    /// ([`RenderSettings::estimate_limit`]).
    #[serde(skip)]
    pub resolved_estimate_limit: Option<f64>,
}

/// Sampling of baked grids: trilinear (C0, 2nd order) or the prefiltered tricubic
/// B-spline (C2, 4th order).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Interpolation {
    #[default]
    Trilinear,
    Tricubic,
}

/// Default per-ray step cap: 2^16 steps covers a 0.5-voxel march through a 1024^3 grid
/// dozens of times over, while bounding a ray that orbits forever.
pub const DEFAULT_MAX_STEPS: u32 = 65_536;

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            width: 640,
            height: 360,
            spp: 1,
            max_depth: 6,
            integrator: None,
            step: StepSpec::Auto(DEFAULT_AUTO_ACCURACY),
            pilot_rays: DEFAULT_PILOT_RAYS,
            max_steps: DEFAULT_MAX_STEPS,
            exit: ExitMethod::Hermite,
            macro_cells: true,
            jitter: true,
            bend_shadow_rays: false,
            seed: 0,
            resolved_accuracy: None,
            resolved_estimate_limit: None,
        }
    }
}

mod material_serde {
    //! `material = "glass"` or `material = { glass = { ior = 1.5 } }`.
    use super::Material;
    use serde::de::value::MapAccessDeserializer;
    use serde::de::{MapAccess, Visitor};
    use serde::{Deserialize, Deserializer};

    #[derive(Deserialize)]
    #[serde(rename_all = "kebab-case", deny_unknown_fields)]
    enum Table {
        Diffuse {
            #[serde(default = "grey")]
            color: [f64; 3],
        },
        Checker {
            #[serde(default = "white")]
            color_a: [f64; 3],
            #[serde(default = "dark")]
            color_b: [f64; 3],
            #[serde(default = "one")]
            scale: f64,
        },
        Mirror {
            #[serde(default = "white")]
            color: [f64; 3],
        },
        Metal {
            #[serde(default = "steel")]
            color: [f64; 3],
        },
        Glass {
            #[serde(default = "glass_ior")]
            ior: f64,
            #[serde(default = "white")]
            color: [f64; 3],
        },
        Texture {
            path: String,
            #[serde(default)]
            size: Option<[f64; 2]>,
            #[serde(default)]
            center: Option<[f64; 3]>,
            #[serde(default)]
            repeat: bool,
            #[serde(default)]
            border: [f64; 3],
            #[serde(default = "white")]
            color: [f64; 3],
            #[serde(default)]
            emissive: bool,
        },
        Dots {
            #[serde(default = "dot_diameter")]
            diameter: f64,
            #[serde(default = "dot_density")]
            density: f64,
            #[serde(default = "dot_seed")]
            seed: u32,
            #[serde(default = "white")]
            color: [f64; 3],
            #[serde(default)]
            background: [f64; 3],
            #[serde(default)]
            center: Option<[f64; 3]>,
            #[serde(default)]
            emissive: bool,
        },
    }

    fn dot_diameter() -> f64 {
        crate::optics::Dots::default().diameter
    }
    fn dot_density() -> f64 {
        crate::optics::Dots::default().density
    }
    fn dot_seed() -> u32 {
        crate::optics::Dots::default().seed
    }

    fn grey() -> [f64; 3] {
        [0.8, 0.8, 0.8]
    }
    fn white() -> [f64; 3] {
        [1.0, 1.0, 1.0]
    }
    fn dark() -> [f64; 3] {
        [0.1, 0.1, 0.1]
    }
    /// Normal-incidence reflectance of polished steel, roughly.
    fn steel() -> [f64; 3] {
        [0.56, 0.57, 0.58]
    }
    fn one() -> f64 {
        1.0
    }
    /// Crown glass.
    fn glass_ior() -> f64 {
        1.5
    }

    impl From<Table> for Material {
        fn from(t: Table) -> Self {
            match t {
                Table::Diffuse { color } => Material::Diffuse { color },
                Table::Checker {
                    color_a,
                    color_b,
                    scale,
                } => Material::Checker {
                    color_a,
                    color_b,
                    scale,
                },
                Table::Mirror { color } => Material::Mirror { color },
                Table::Metal { color } => Material::Metal { color },
                Table::Glass { ior, color } => Material::Glass { ior, color },
                Table::Texture {
                    path,
                    size,
                    center,
                    repeat,
                    border,
                    color,
                    emissive,
                } => Material::Texture {
                    path,
                    size,
                    center,
                    repeat,
                    border,
                    color,
                    emissive,
                },
                Table::Dots {
                    diameter,
                    density,
                    seed,
                    color,
                    background,
                    center,
                    emissive,
                } => Material::Dots {
                    diameter,
                    density,
                    seed,
                    color,
                    background,
                    center,
                    emissive,
                },
            }
        }
    }

    /// A string names a material with default parameters; a table is parsed as [`Table`]
    /// directly so its errors (unknown keys, wrong types) keep their message and span.
    struct MaterialVisitor;

    impl<'de> Visitor<'de> for MaterialVisitor {
        type Value = Material;

        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("a material name or a table like { glass = { ior = 1.5 } }")
        }

        fn visit_str<E: serde::de::Error>(self, name: &str) -> Result<Material, E> {
            let table = match name {
                "diffuse" => Table::Diffuse { color: grey() },
                "checker" => Table::Checker {
                    color_a: white(),
                    color_b: dark(),
                    scale: one(),
                },
                "mirror" => Table::Mirror { color: white() },
                "metal" => Table::Metal { color: steel() },
                "glass" => Table::Glass {
                    ior: glass_ior(),
                    color: white(),
                },
                "dots" => Table::Dots {
                    diameter: dot_diameter(),
                    density: dot_density(),
                    seed: dot_seed(),
                    color: white(),
                    background: [0.0; 3],
                    center: None,
                    emissive: false,
                },
                "texture" => {
                    return Err(E::custom(
                        "material `texture` needs a table with its image: \
                         { texture = { path = \"plate.png\", size = [w, h] } }",
                    ));
                }
                other => {
                    return Err(E::custom(format!(
                        "unknown material `{other}`, expected one of diffuse, checker, mirror, metal, glass, texture, dots"
                    )));
                }
            };
            Ok(table.into())
        }

        fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Material, A::Error> {
            Table::deserialize(MapAccessDeserializer::new(map)).map(Into::into)
        }
    }

    impl<'de> Deserialize<'de> for Material {
        fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
            d.deserialize_any(MaterialVisitor)
        }
    }
}
