//! Reading a scene file: TOML -> [`Scene`], then validation, with every error located
//! at file:line:column and named by its dotted key path.

use std::path::Path;

use crate::span::{Document, line_column};
use crate::validate::validate;
use crate::{Scene, SceneError, Shape};

/// Read and validate a scene file.
pub fn load_scene(path: &Path) -> Result<Scene, SceneError> {
    let text = std::fs::read_to_string(path).map_err(|err| SceneError::Io {
        path: path.to_owned(),
        err,
    })?;
    parse_scene(&text, path)
}

/// Parse and validate scene text; `path` is used in error messages.
pub fn parse_scene(text: &str, path: &Path) -> Result<Scene, SceneError> {
    // TOML syntax first (located by toml's span), then the scene's shape, each error at
    // the key path the deserializer was at (crate::de): an unknown key is pointed at
    // itself, typed, without reading it out of a message.
    let table: toml::Table = text.parse().map_err(|e: toml::de::Error| {
        let offset = e.span().map_or(0, |s| s.start);
        let key = Document::parse(text)
            .key_at(offset)
            .unwrap_or_else(|| "(document)".to_owned());
        let (line, column) = line_column(text, offset);
        SceneError::Parse {
            path: path.to_owned(),
            line,
            column,
            key,
            message: one_line(e.message()),
        }
    })?;
    let fov_given = table
        .get("camera")
        .and_then(|c| c.get("fov_y_deg"))
        .is_some();
    let mut scene: Scene = crate::de::from_table(table).map_err(|e| {
        let key = e.key();
        let doc = Document::parse(text);
        // An unknown key at the key; a wrong value at the value.
        let exact = match e.kind {
            crate::de::DeErrorKind::UnknownField { .. } => doc.exact_span_of(&key),
            crate::de::DeErrorKind::Other(_) => doc.value_span_of(&key),
        };
        let offset = exact.or_else(|| doc.span_of(&key)).map_or(0, |s| s.start);
        let (line, column) = line_column(text, offset);
        SceneError::Parse {
            path: path.to_owned(),
            line,
            column,
            key: if key.is_empty() {
                "(document)".to_owned()
            } else {
                key
            },
            message: one_line(&e.to_string()),
        }
    })?;
    let lens_conflict =
        (fov_given && scene.camera.focal_length_mm.is_some()).then(|| crate::validate::Problem {
            key: "camera.focal_length_mm".into(),
            message: "give fov_y_deg or focal_length_mm with the sensor, not both".into(),
        });
    lens_conflict
        .map_or_else(|| validate(&scene), Err)
        .map_err(|p| {
            let offset = Document::parse(text).span_of(&p.key).map_or(0, |s| s.start);
            let (line, column) = line_column(text, offset);
            SceneError::Invalid {
                path: path.to_owned(),
                line,
                column,
                key: p.key,
                message: p.message,
            }
        })?;
    normalize(&mut scene);
    Ok(scene)
}

/// Unit plane normals (validated non-zero above); a lens's field of view.
fn normalize(scene: &mut Scene) {
    let c = &mut scene.camera;
    if let Some(f) = c.focal_length_mm {
        let sensor = c
            .sensor_height_mm
            .or(c
                .pixel_pitch_um
                .map(|p| p * 1e-3 * f64::from(scene.render.height)))
            .unwrap_or(24.0);
        c.fov_y_deg = 2.0 * (0.5 * sensor / f).atan().to_degrees();
    }
    for o in &mut scene.objects {
        if let Shape::Plane { normal, .. } = &mut o.shape {
            let len = normal.iter().map(|c| c * c).sum::<f64>().sqrt();
            for c in normal.iter_mut() {
                *c /= len;
            }
        }
    }
}

/// Errors are one line on stderr.
fn one_line(message: &str) -> String {
    message.trim().replace('\n', "; ")
}

/// 1-based (line, column) of a dotted key path (`medium.field.n`, `object[2].shape`) in
/// scene text, for errors found after loading (e.g. by field builders) that should point
/// into the file. `None` if no part of the path is in the text.
pub fn locate_key(text: &str, key: &str) -> Option<(usize, usize)> {
    Document::parse(text)
        .span_of(key)
        .map(|span| line_column(text, span.start))
}

impl crate::Scene {
    /// The files the scene reads besides itself, resolved against `scene_dir` (the scene
    /// file's directory): the medium's VDB or baked file, the sky's map or plate, the
    /// textures' images. A path with a frame token is the sequence's: take the scene
    /// [at its frame](crate::Scene::at_frame) for that frame's file.
    pub fn files(&self, scene_dir: &std::path::Path) -> Vec<std::path::PathBuf> {
        use crate::{Material, Sky};
        let medium = self.medium.as_ref().and_then(|m| m.field.file());
        let sky = match &self.sky {
            Sky::Map { path, .. } | Sky::Plate { path, .. } => Some(path.as_str()),
            _ => None,
        };
        let textures = self.objects.iter().filter_map(|o| match &o.material {
            Material::Texture { path, .. } => Some(path.as_str()),
            _ => None,
        });
        medium
            .into_iter()
            .chain(sky)
            .chain(textures)
            .map(|p| scene_dir.join(p))
            .collect()
    }
}
