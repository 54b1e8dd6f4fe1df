//! A sequence's frames before they render (`grin render --frames`): each frame's seeds
//! from `--seed`, and every file of the frames asked checked first (the missing ones
//! named, a VDB sequence's grids of one value type), so a sequence fails before its first
//! frame rather than part way.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};

/// Salt of the sensor's per-frame seed: the sensor's noise and the render's sampling
/// draw from unrelated seeds.
const SENSOR_SEED_SALT: u64 = 0x5e45_0a5e_ed00_0001;

/// `scene` (at frame `frame`) with its random seeds derived from `--seed` and the frame:
/// the render's (sub-pixel positions, jitter, sampling) and the sensor's. The BOS dot
/// pattern keeps its seed. Unchanged without `--seed`.
pub(super) fn seeded(
    mut scene: grin_scene::Scene,
    frame: i64,
    seed: Option<u64>,
) -> grin_scene::Scene {
    let Some(base) = seed else {
        return scene;
    };
    scene.render.seed = grin_scene::frames::frame_seed(base, frame);
    if let Some(sensor) = &mut scene.sensor {
        sensor.seed = grin_scene::frames::frame_seed(base ^ SENSOR_SEED_SALT, frame);
    }
    scene
}

/// Consecutive runs `(first, last)` of `frames` in their order: each frame of a run is
/// one more than the one before.
fn runs(frames: &[i64]) -> Vec<(i64, i64)> {
    let mut runs: Vec<(i64, i64)> = Vec::new();
    for &f in frames {
        match runs.last_mut() {
            Some((_, last)) if last.checked_add(1) == Some(f) => *last = f,
            _ => runs.push((f, f)),
        }
    }
    runs
}

/// Before any frame renders: every file of `frames` of the scene's sequence is there
/// (the missing ones named), and a VDB sequence's files hold the grid, scalar, with a
/// linear transform, all of one value type (as for a range, across the whole list).
pub(super) fn check_frames(
    scene_file: &Path,
    scene: &grin_scene::Scene,
    scene_dir: &Path,
    frames: &[i64],
) -> anyhow::Result<()> {
    let runs = runs(frames);
    let missing: Vec<String> = runs
        .iter()
        .flat_map(|&(a, b)| grin_scene::frames::missing_frames(scene, scene_dir, a, b))
        .collect();
    if !missing.is_empty() {
        let which = match runs[..] {
            [(first, last)] => format!("{first}..{last}"),
            _ => {
                let text = runs
                    .iter()
                    .map(|&(a, b)| {
                        if a == b {
                            format!("{a}")
                        } else {
                            format!("{a}-{b}")
                        }
                    })
                    .collect::<Vec<_>>()
                    .join(",");
                // Stepped runs compacted (`7-19:2`).
                grin_scene::frames::parse_frame_list(&text).map_or(text, |l| l.to_string())
            }
        };
        bail!(
            "{}: {} of frames {which} missing: {}",
            scene_file.display(),
            missing.len(),
            grin_scene::frames::summarize(&missing)
        );
    }
    for &(first, last) in &runs {
        grin_field::vdb::check_sequence(scene, scene_dir, first, last)
            .with_context(|| format!("{}", scene_file.display()))?;
    }
    same_value_type(scene, scene_dir, &runs).with_context(|| format!("{}", scene_file.display()))
}

/// A VDB sequence keeps one value type: [`grin_field::vdb::check_sequence`] checks that
/// within a run of consecutive frames; this compares the first frame of each further run
/// with the first run's (every file opened and its grid found by then).
fn same_value_type(
    scene: &grin_scene::Scene,
    scene_dir: &Path,
    runs: &[(i64, i64)],
) -> anyhow::Result<()> {
    let Some(grin_scene::FieldSpec::Vdb(spec)) = scene.medium.as_ref().map(|m| &m.field) else {
        return Ok(());
    };
    let Some(((f0, _), rest)) = runs.split_first() else {
        return Ok(());
    };
    if rest.is_empty() || !grin_scene::frames::has_frame_token(&spec.path) {
        return Ok(());
    }
    let value_type = |f: i64| -> anyhow::Result<(PathBuf, String)> {
        let name = grin_scene::frames::substitute_frame(&spec.path, f)
            .unwrap_or_else(|| spec.path.clone());
        let path = grin_field::vdb::resolve(scene_dir, &name);
        let in_frame = |e: vdb_sys::VdbError| anyhow::anyhow!("frame {f}: {e}");
        let file = vdb_sys::VdbFile::open(&path).map_err(in_frame)?;
        let value_type = file.grid(&spec.grid).map_err(in_frame)?.value_type.clone();
        Ok((path, value_type))
    };
    let (_, t0) = value_type(*f0)?;
    for &(f, _) in rest {
        let (path, t) = value_type(f)?;
        if t != t0 {
            bail!(
                "frame {f}: {}: grid `{}` is `{t}`, but `{t0}` in frame {f0}: a sequence keeps one type",
                path.display(),
                spec.grid
            );
        }
    }
    Ok(())
}
