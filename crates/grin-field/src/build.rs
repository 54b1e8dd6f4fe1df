//! From a scene's `[medium]` to a ready field: dispatch on the field kind, build it,
//! and run the shared n > 0 check on it.

use std::path::Path;
use std::sync::Arc;

use grin_scene::{FieldSpec, MediumSpec};

use crate::analytic::{
    Eaton, ExponentialAtmosphere, GrinRod, LinearN2, Luneburg, MaxwellFishEye, Plume, Uniform,
};
use crate::baked::Interp;
use crate::bounds::Bounds;
use crate::check::check_positive;
use crate::expr::ExprField;
use crate::field::{FieldError, IndexField};

/// Build the index field of `medium`; relative file paths (VDB, baked) are resolved
/// against `scene_dir`. Every field is checked to be finite and > 0 inside the bounds.
pub fn build_field(
    medium: &MediumSpec,
    scene_dir: &Path,
) -> Result<Arc<dyn IndexField>, FieldError> {
    build_field_capped(medium, scene_dir, crate::vdb::DEFAULT_MAX_DENSE_BYTES)
}

/// [`build_field`] with a memory cap in bytes for a VDB grid's voxels as loaded (the
/// bricks kept; its data box at a voxel a byte: the bake command passes its `--max-memory`).
pub fn build_field_capped(
    medium: &MediumSpec,
    scene_dir: &Path,
    max_dense_bytes: u64,
) -> Result<Arc<dyn IndexField>, FieldError> {
    let bounds = Bounds::from_spec(&medium.bounds);
    let ambient_param = |message: String| FieldError::Param {
        field: "medium".into(),
        param: "ambient_index".into(),
        message,
    };
    let fixed_ambient = medium.ambient();
    if let Some(a) = fixed_ambient
        && !(a.is_finite() && a > 0.0)
    {
        return Err(ambient_param(format!("must be finite and > 0, got {a}")));
    }
    // A path with a frame token names a sequence, not a file: the caller picks the frame
    // (`Scene::at_frame`).
    let sequence_path = match &medium.field {
        FieldSpec::Vdb(v) => Some(&v.path),
        FieldSpec::Baked { path, .. } => Some(path),
        _ => None,
    };
    if let Some(p) = sequence_path
        && grin_scene::frames::has_frame_token(p)
    {
        return Err(FieldError::Param {
            field: "medium.field".into(),
            param: "path".into(),
            message: format!(
                "`{p}` is a frame sequence (it holds a frame token): render frames of it (`grin render --frames A..B`, or an [animation] with frames = [A, B])"
            ),
        });
    }
    // The VDB field finds its own ambient where the scene leaves it to the data (the
    // background's index); every other kind needs a number.
    let field: Arc<dyn IndexField> = match (&medium.field, fixed_ambient) {
        (FieldSpec::Vdb(spec), _) => Arc::new(crate::vdb::VdbField::from_medium(
            medium,
            spec,
            scene_dir,
            max_dense_bytes,
        )?),
        (_, None) => {
            return Err(ambient_param(
                "\"auto\" takes the index a VDB grid's background maps to; give a number for \
                 this field"
                    .into(),
            ));
        }
        (FieldSpec::Uniform { n }, Some(ambient)) => Arc::new(Uniform::new(bounds, ambient, *n)?),
        (FieldSpec::LinearN2 { n0, k, axis }, Some(ambient)) => {
            Arc::new(LinearN2::new(bounds, ambient, *n0, *k, *axis)?)
        }
        (FieldSpec::GrinRod { n0, a, axis }, Some(ambient)) => {
            Arc::new(GrinRod::new(bounds, ambient, *n0, *a, *axis)?)
        }
        (FieldSpec::Luneburg { radius }, Some(ambient)) => {
            Arc::new(Luneburg::new(bounds, ambient, *radius)?)
        }
        (FieldSpec::MaxwellFishEye { n0, a }, Some(ambient)) => {
            Arc::new(MaxwellFishEye::new(bounds, ambient, *n0, *a)?)
        }
        (FieldSpec::Eaton { radius, core }, Some(ambient)) => {
            Arc::new(Eaton::new(bounds, ambient, *radius, *core)?)
        }
        (
            FieldSpec::ExponentialAtmosphere {
                e,
                scale_height,
                base,
                axis,
            },
            Some(ambient),
        ) => Arc::new(ExponentialAtmosphere::new(
            bounds,
            ambient,
            *e,
            *scale_height,
            *base,
            *axis,
        )?),
        (FieldSpec::Plume { plumes }, Some(ambient)) => {
            Arc::new(Plume::new(bounds, ambient, plumes)?)
        }
        // ExprField runs the n > 0 check itself (it needs the sampled range anyway).
        (FieldSpec::Expr { n, t }, Some(ambient)) => {
            return Ok(Arc::new(ExprField::new(n, bounds, ambient, *t)?));
        }

        // Kinds built by other modules: each arm is one call into its module.
        (FieldSpec::Noise(spec), Some(ambient)) => {
            Arc::new(crate::noise::NoiseField::new(spec, bounds, ambient)?)
        }
        (
            FieldSpec::Baked {
                path,
                interpolation,
            },
            Some(ambient),
        ) => match crate::grinf::load_for_medium(path, scene_dir, bounds, ambient)? {
            crate::grinf::Grinf::Dense(baked) => Arc::new(match interpolation {
                Some(i) => baked.with_interp(Interp::from(*i)),
                None => baked,
            }),
            crate::grinf::Grinf::Sparse(sparse) => {
                // A sparse bake is sampled as it was baked: its bricks hold the apron
                // Catmull-Rom reads, or none.
                let has = sparse.interp();
                if let Some(asked) = interpolation.map(Interp::from)
                    && asked != has
                {
                    return Err(FieldError::File {
                        path: scene_dir.join(path).display().to_string(),
                        message: format!(
                            "this sparse bake is {} (sampled as it was baked); `interpolation = \"{}\"` needs a sparse bake made with `grin bake --sparse --interp {}`",
                            has.name(),
                            asked.name(),
                            asked.name()
                        ),
                    });
                }
                Arc::new(sparse)
            }
        },
    };
    check_positive(field.as_ref(), &field.describe())?;
    Ok(field)
}

#[cfg(test)]
mod tests {
    use super::*;
    use grin_scene::{BoundsSpec, parse_scene};

    fn medium(field: &str) -> MediumSpec {
        let text = format!(
            "[camera]\nposition = [0.0, 0.0, -4.0]\nlook_at = [0.0, 0.0, 0.0]\n[medium]\nbounds = {{ sphere = {{ center = [0.0, 0.0, 0.0], radius = 1.0 }} }}\nfield = {field}\n"
        );
        match parse_scene(&text, Path::new("test.toml")) {
            Ok(s) => s.medium.expect("medium"),
            Err(e) => panic!("{e}"),
        }
    }

    #[test]
    fn builds_each_analytic_kind() {
        let cases = [
            ("{ kind = \"uniform\", n = 1.5 }", "uniform n=1.5"),
            (
                "{ kind = \"linear-n2\", n0 = 1.2, k = 0.3 }",
                "linear-n2 n0=1.2 k=0.3 axis=y",
            ),
            (
                "{ kind = \"grin-rod\", n0 = 1.5, a = 0.5 }",
                "grin-rod n0=1.5 a=0.5 axis=z",
            ),
            ("{ kind = \"luneburg\" }", "luneburg R=1"),
            (
                "{ kind = \"maxwell-fish-eye\", n0 = 2.0, a = 1.0 }",
                "maxwell-fish-eye n0=2 a=1",
            ),
            ("{ kind = \"eaton\" }", "eaton R=1 core=0.02"),
            (
                "{ kind = \"exponential-atmosphere\", e = 3e-4, scale_height = 0.5 }",
                "exponential-atmosphere e=0.0003 H=0.5 base=0 axis=y",
            ),
            // Beyond 1e-4 ..= 1e6 in exponent form (1e-300 printed as 300 digits).
            (
                "{ kind = \"exponential-atmosphere\", e = -5e-5, scale_height = 2.0, base = -1e-12 }",
                "exponential-atmosphere e=-5e-5 H=2 base=-1e-12 axis=y",
            ),
            (
                "{ kind = \"plume\", plumes = [{ a = 1e-4, center = [0.0, 0.0, 0.0], s = 0.3 }] }",
                "plume (1 blobs)",
            ),
            (
                "{ kind = \"expr\", n = \"1 + 0.1*x*x\" }",
                "expr n = 1 + 0.1*x*x",
            ),
        ];
        for (spec, want) in cases {
            let f = build_field(&medium(spec), Path::new("."))
                .unwrap_or_else(|e| panic!("{spec}: {e}"));
            assert_eq!(f.describe(), want);
            assert_eq!(
                f.bounds(),
                Bounds::from_spec(&BoundsSpec::Sphere {
                    center: [0.0; 3],
                    radius: 1.0
                })
            );
            let (lo, hi) = f.n_range();
            assert!(lo > 0.0 && lo <= hi, "{want}: n_range ({lo}, {hi})");
        }
    }

    #[test]
    fn parameter_errors_propagate() {
        let e = build_field(
            &medium("{ kind = \"luneburg\", radius = 0.5 }"),
            Path::new("."),
        )
        .expect_err("bounds too big");
        assert!(
            e.to_string()
                .starts_with("luneburg: invalid parameter `radius`"),
            "{e}"
        );
        let e = build_field(&medium("{ kind = \"expr\", n = \"x\" }"), Path::new("."))
            .expect_err("n <= 0 for x <= 0");
        assert!(
            e.to_string()
                .contains("inside the medium; n must be positive"),
            "{e}"
        );
        // n beyond any material's: a formula, and an atmosphere whose scale height puts
        // an infinite index at the bottom of its bounds (its rays ended with NaN).
        let e = build_field(
            &medium("{ kind = \"expr\", n = \"1 + 3e3 * (1 + x)\" }"),
            Path::new("."),
        )
        .expect_err("n up to 6e3");
        assert!(
            e.to_string()
                .contains("inside the medium is above the largest index grin takes, 1e3"),
            "{e}"
        );
        let e = build_field(
            &medium("{ kind = \"exponential-atmosphere\", e = 0.1, scale_height = 1e-300 }"),
            Path::new("."),
        )
        .expect_err("n = inf at the bottom");
        assert!(
            e.to_string().starts_with(
                "exponential-atmosphere: invalid parameter `scale_height`: n = 1 + e exp(-h / H) reaches inf"
            ),
            "{e}"
        );
    }

    /// Every example scene parses, validates and builds. Kinds whose builder is not wired
    /// into [`build_field`] yet (noise, vdb, baked) are skipped, and only those.
    #[test]
    fn every_example_scene_builds() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/scenes");
        let mut built = 0;
        let entries = std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
        for entry in entries {
            let path = entry.expect("dir entry").path();
            if path.extension().and_then(|e| e.to_str()) != Some("toml") {
                continue;
            }
            let scene = grin_scene::load_scene(&path).unwrap_or_else(|e| panic!("{e}"));
            let Some(medium) = scene.medium else { continue };
            match build_field(&medium, &dir) {
                Ok(f) => {
                    let (lo, hi) = f.n_range();
                    assert!(
                        lo > 0.0 && lo <= hi,
                        "{}: n_range ({lo}, {hi})",
                        path.display()
                    );
                    built += 1;
                }
                Err(FieldError::Other(m))
                    if m.ends_with("is not available yet")
                        && matches!(
                            medium.field,
                            FieldSpec::Noise(_) | FieldSpec::Vdb(_) | FieldSpec::Baked { .. }
                        ) => {}
                Err(e) => panic!("{}: {e}", path.display()),
            }
        }
        assert!(built >= 4, "only {built} example scenes built");
    }

    /// `field = { kind = "baked", interpolation = ... }` overrides the file's stored
    /// interpolation; without it the file's choice stands.
    #[test]
    fn baked_interpolation_overrides_the_file_header() {
        let source = medium(r#"{ kind = "luneburg" }"#);
        let luneburg = build_field(&source, Path::new(".")).expect("luneburg");
        let opts = crate::bake::BakeOptions {
            resolution: Some(24),
            interp: Interp::Trilinear,
            ..Default::default()
        };
        let (baked, _) = crate::bake::bake(luneburg.as_ref(), &opts, &|_, _, _| {}).expect("bake");
        let dir = tempfile::tempdir().expect("temp dir");
        crate::grinf::save(&baked, &dir.path().join("l.grinf")).expect("save");

        let p = glam::DVec3::new(0.31, -0.22, 0.17);
        let from_file = build_field(
            &medium(r#"{ kind = "baked", path = "l.grinf" }"#),
            dir.path(),
        )
        .expect("baked, file default");
        let tricubic = build_field(
            &medium(r#"{ kind = "baked", path = "l.grinf", interpolation = "tricubic" }"#),
            dir.path(),
        )
        .expect("baked, tricubic");
        assert_eq!(
            from_file.sample(p),
            baked.sample(p),
            "file default is trilinear"
        );
        let cubic = baked.with_interp(Interp::Tricubic);
        assert_eq!(
            tricubic.sample(p),
            cubic.sample(p),
            "override selects tricubic"
        );
        // Tricubic is the closer of the two to the source at an off-node point.
        let exact = luneburg.sample(p).n;
        assert!((tricubic.sample(p).n - exact).abs() < (from_file.sample(p).n - exact).abs());
    }
}
