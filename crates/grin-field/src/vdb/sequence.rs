//! The frames of a VDB sequence, checked before any is rendered or baked.

use std::path::Path;

use vdb_sys::VdbFile;

use super::resolve;
use crate::field::FieldError;

/// Every frame of a VDB sequence (frames `first..=last` of `scene`, whose medium's path
/// holds a frame token) before any is rendered or baked: each file opens and holds the
/// grid, as a scalar grid with a linear transform, of the same value type as the first
/// frame's. The error names the frame, its file and what differs. Not a VDB sequence: Ok.
pub fn check_sequence(
    scene: &grin_scene::Scene,
    scene_dir: &Path,
    first: i64,
    last: i64,
) -> Result<(), FieldError> {
    let Some(grin_scene::FieldSpec::Vdb(spec)) = scene.medium.as_ref().map(|m| &m.field) else {
        return Ok(());
    };
    if !grin_scene::frames::has_frame_token(&spec.path) {
        return Ok(());
    }
    let mut first_type: Option<(i64, String)> = None;
    for f in first..=last {
        let Some(name) = grin_scene::frames::substitute_frame(&spec.path, f) else {
            continue;
        };
        let path = resolve(scene_dir, &name);
        let in_frame = |e: String| FieldError::Other(format!("frame {f}: {e}"));
        let file = VdbFile::open(&path).map_err(|e| in_frame(e.to_string()))?;
        let info = file.grid(&spec.grid).map_err(|e| in_frame(e.to_string()))?;
        if !info.kind.is_scalar() {
            return Err(in_frame(format!(
                "{}: grid `{}` has value type `{}`, a scalar grid (float or double) is needed",
                path.display(),
                spec.grid,
                info.value_type
            )));
        }
        if !info.is_linear {
            return Err(in_frame(format!(
                "{}: grid `{}` has a non-linear transform ({})",
                path.display(),
                spec.grid,
                info.map_type
            )));
        }
        match &first_type {
            None => first_type = Some((f, info.value_type.clone())),
            Some((f0, t0)) if *t0 != info.value_type => {
                return Err(in_frame(format!(
                    "{}: grid `{}` is `{}`, but `{t0}` in frame {f0}: a sequence keeps one type",
                    path.display(),
                    spec.grid,
                    info.value_type
                )));
            }
            Some(_) => {}
        }
    }
    Ok(())
}
