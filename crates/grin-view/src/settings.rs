//! The state the viewer's panel edits, and what each edit costs: the scene each frame is
//! rendered from is the scene file's, with these settings applied ([`ViewSettings::apply`]).

use grin_scene::{FieldSpec, IntegratorKind, Interpolation, Scene, StepSpec};

use crate::display::Aov;
use crate::orbit::OrbitCamera;

/// Step policies as the panel lists them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, strum::IntoStaticStr)]
pub enum StepKind {
    #[strum(serialize = "fixed (step)")]
    Fixed,
    #[strum(serialize = "heuristic (max step)")]
    Heuristic,
    #[strum(serialize = "adaptive (tolerance)")]
    Adaptive,
    #[strum(serialize = "auto (rad)")]
    Auto,
}

impl StepKind {
    pub const ALL: [StepKind; 4] = [
        StepKind::Fixed,
        StepKind::Heuristic,
        StepKind::Adaptive,
        StepKind::Auto,
    ];

    pub fn name(self) -> &'static str {
        self.into()
    }

    pub fn of(step: &StepSpec) -> Self {
        match step {
            StepSpec::Fixed(_) => StepKind::Fixed,
            StepSpec::Heuristic { .. } => StepKind::Heuristic,
            StepSpec::Adaptive { .. } => StepKind::Adaptive,
            StepSpec::Auto(_) => StepKind::Auto,
        }
    }

    /// The policy's one number: the step, the heuristic's longest step, the tolerance or
    /// the asked exit-direction error.
    pub fn value_of(step: &StepSpec) -> f64 {
        match *step {
            StepSpec::Fixed(ds) => ds,
            StepSpec::Heuristic { max, .. } => max,
            StepSpec::Adaptive { tolerance, .. } => tolerance,
            StepSpec::Auto(rad) => rad,
        }
    }

    /// The policy with value `v` (the heuristic's shortest step is a tenth of its
    /// longest, as in the paper's scenes).
    pub fn with_value(self, v: f64) -> StepSpec {
        match self {
            StepKind::Fixed => StepSpec::Fixed(v),
            StepKind::Heuristic => StepSpec::Heuristic {
                min: v * 0.1,
                max: v,
                amplitude: None,
            },
            StepKind::Adaptive => StepSpec::Adaptive {
                tolerance: v,
                initial: None,
            },
            StepKind::Auto => StepSpec::Auto(v),
        }
    }

    /// A sensible value when switching to this policy: the step for the step policies, a
    /// tolerance for the error-controlled ones.
    pub fn default_value(self, step_scale: f64) -> f64 {
        match self {
            StepKind::Fixed | StepKind::Heuristic => step_scale,
            StepKind::Adaptive => 1e-5 * step_scale.max(1e-12) / 0.01,
            StepKind::Auto => 1e-4,
        }
    }
}

/// Everything the panel edits. Changing any of it takes effect on the next frame,
/// without a restart: the worker compares the scene it renders with the last one and
/// rebakes, rebuilds pipelines, restarts accumulation or only redraws, as needed.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewSettings {
    pub camera: OrbitCamera,
    /// `None`: as the scene leaves it (with `auto` steps, chosen by the pilot rays).
    pub integrator: Option<IntegratorKind>,
    pub step: StepSpec,
    /// How the field's grid is sampled: `None` as baked (the GPU bake picks tricubic where
    /// trilinear misses the error budget; a baked file's own or the scene's choice).
    pub interpolation: Option<Interpolation>,
    pub aov: Aov,
    /// Internal resolution as a fraction of the window's image area (per side).
    pub resolution_scale: f64,
    /// Samples per pixel of each frame.
    pub spp: u32,
    /// Samples per pixel at which a still view counts as converged (accumulation stops).
    pub max_spp: u32,
    pub medium: bool,
    /// Time of animated media (noise drift, `expr` with t), seconds.
    pub time: f64,
    pub playing: bool,
    /// Seconds of scene time per second of wall time while playing.
    pub speed: f64,
    /// Frames per second aimed at while the camera moves (the internal resolution drops
    /// to keep it).
    pub target_fps: f64,
}

/// The centre of a medium's bounds: what the orbit turns about.
fn medium_centre(m: &grin_scene::MediumSpec) -> glam::DVec3 {
    match m.bounds {
        grin_scene::BoundsSpec::Sphere { center, .. } => glam::DVec3::from_array(center),
        grin_scene::BoundsSpec::Box { min, max } => {
            (glam::DVec3::from_array(min) + glam::DVec3::from_array(max)) * 0.5
        }
    }
}

impl ViewSettings {
    /// The settings of the scene file as it is.
    pub fn from_scene(scene: &Scene) -> Self {
        ViewSettings {
            camera: OrbitCamera::from_scene_about(
                &scene.camera,
                scene.medium.as_ref().map(medium_centre),
            ),
            integrator: scene.render.integrator,
            step: scene.render.step,
            interpolation: match &scene.medium.as_ref().map(|m| &m.field) {
                Some(FieldSpec::Baked { interpolation, .. }) => *interpolation,
                _ => None,
            },
            aov: Aov::Beauty,
            resolution_scale: 1.0,
            spp: scene.render.spp,
            max_spp: (scene.render.spp * 16).max(64),
            medium: scene.medium.is_some(),
            time: match (scene.is_sequence(), scene.animation) {
                (true, Some(a)) => a.frames[0] as f64 / a.fps,
                _ => scene_time(scene).unwrap_or(0.0),
            },
            playing: false,
            speed: 1.0,
            target_fps: 30.0,
        }
    }

    /// `scene` (the scene file's) with these settings, rendered `width` x `height`.
    pub fn apply(&self, scene: &Scene, width: u32, height: u32) -> Scene {
        let mut s = scene.clone();
        s.camera = self.camera.to_scene();
        s.render.width = width.max(1);
        s.render.height = height.max(1);
        s.render.integrator = self.integrator;
        s.render.step = self.step;
        s.render.spp = self.spp.max(1);
        // A file per frame: the frame at this time (frame = time x fps, within the
        // [animation] range).
        if let (true, Some(a)) = (scene.is_sequence(), scene.animation) {
            s = s.at_frame(self.sequence_frame(&a), a.fps);
        }
        if !self.medium {
            s.medium = None;
        }
        if let Some(m) = &mut s.medium {
            match &mut m.field {
                FieldSpec::Noise(n) => n.t = self.time,
                FieldSpec::Expr { t, .. } => *t = self.time,
                FieldSpec::Baked { interpolation, .. } => {
                    *interpolation = self.interpolation.or(*interpolation)
                }
                _ => {}
            }
        }
        s
    }

    /// These settings less what only changes how a frame is shown (the AOV): two
    /// settings equal under this render the same image.
    pub fn without_display(mut self) -> Self {
        self.aov = Aov::Beauty;
        self
    }

    /// After the scene file changed from `old_file` to `new_file` (each read with
    /// [`Self::from_scene`]): take the new file's value of every setting the file
    /// changed, keep the user's own edits of the others.
    pub fn rebase(&mut self, old_file: &ViewSettings, new_file: &ViewSettings) {
        macro_rules! take {
            ($($f:ident),*) => {$(
                if old_file.$f != new_file.$f {
                    self.$f = new_file.$f.clone();
                }
            )*};
        }
        take!(
            camera,
            integrator,
            step,
            interpolation,
            spp,
            max_spp,
            medium,
            time
        );
    }

    /// The frame of a sequence shown at this time.
    pub fn sequence_frame(&self, a: &grin_scene::Animation) -> i64 {
        ((self.time * a.fps).round() as i64).clamp(a.frames[0], a.frames[1])
    }

    /// Whether the scene's medium changes with time (noise with a drift, an `expr` in t,
    /// a VDB sequence).
    pub fn animated(scene: &Scene) -> bool {
        if scene.is_sequence() && scene.animation.is_some() {
            return true;
        }
        match scene.medium.as_ref().map(|m| &m.field) {
            Some(FieldSpec::Noise(n)) => n.drift.iter().any(|&d| d != 0.0),
            Some(FieldSpec::Expr { n, .. }) => n
                .split(|c: char| !(c.is_alphanumeric() || c == '_'))
                .any(|w| w == "t"),
            _ => false,
        }
    }
}

/// The `t` the scene file gives its medium, if the medium has one.
pub fn scene_time(scene: &Scene) -> Option<f64> {
    match scene.medium.as_ref().map(|m| &m.field) {
        Some(FieldSpec::Noise(n)) => Some(n.t),
        Some(FieldSpec::Expr { t, .. }) => Some(*t),
        _ => None,
    }
}
