//! `grin render` of a scene with `[optics]`: the image-space output of its mode written as
//! an EXR of named channels and a PNG preview (docs/optics.md). Displacement, schlieren,
//! interferogram and BOS come from the rendered frame's AOVs (either backend); the
//! shadowgraph traces its own collimated beam on the CPU.

use std::path::Path;

use anyhow::Context;
use grin_output::Staged;
use grin_render::image::{Frame, stage_channels_exr, stage_rgb8_png};
use grin_render::optics::{
    Displacement, Plane, bos_pair, deflection_angles, interferogram, schlieren,
};
use grin_render::scene::RenderScene;
use grin_render::sensor::record_all;
use grin_scene::{OpticsMode, OpticsSpec};
use serde_json::json;

/// The mode's name as the scene writes it.
pub fn mode_name(mode: OpticsMode) -> &'static str {
    match mode {
        OpticsMode::Displacement => "displacement",
        OpticsMode::Schlieren => "schlieren",
        OpticsMode::Shadowgraph => "shadowgraph",
        OpticsMode::Interferogram => "interferogram",
        OpticsMode::Bos => "bos",
    }
}

/// Grey preview bytes of `values` mapped from [lo, hi] to [0, 255] (NaN: black).
fn grey(values: &[f64], lo: f64, hi: f64) -> Vec<u8> {
    values
        .iter()
        .flat_map(|&v| {
            let g = if v.is_finite() {
                ((v - lo) / (hi - lo)).clamp(0.0, 1.0)
            } else {
                0.0
            };
            [(g * 255.0).round() as u8; 3]
        })
        .collect()
}

fn f32s(values: impl Iterator<Item = f64>) -> Vec<f32> {
    values.map(|v| v as f32).collect()
}

/// The png beside `png` with `-suffix` before its extension.
fn sibling(png: &Path, suffix: &str) -> std::path::PathBuf {
    let stem = png
        .file_stem()
        .map_or_else(|| "out".into(), |s| s.to_string_lossy().into_owned());
    png.with_file_name(format!("{stem}-{suffix}.png"))
}

/// Stage the optical output of `spec` from `frame` (rendered by `rs` at 1 sample a
/// pixel) to `exr` and the PNG preview(s) at `png`; returns the staged files and the
/// summary of what was written.
pub fn stage_from_frame(
    spec: &OpticsSpec,
    sensor: Option<&grin_scene::Sensor>,
    bos_images: Option<(Vec<f64>, Vec<f64>)>,
    rs: &RenderScene,
    frame: &Frame,
    exr: &Path,
    png: Option<&Path>,
) -> anyhow::Result<(Vec<Staged>, serde_json::Value)> {
    let cam = &rs.camera;
    let size = (frame.width as usize, frame.height as usize);
    let plane = match &spec.plane {
        Some(p) => Some(Plane::new(p, cam).context(
            "[optics] plane: its normal is zero or the plane is seen edge-on by the camera",
        )?),
        None => None,
    };
    let mut staged = Vec::new();
    let mut pngs = Vec::new();
    let summary;
    match spec.mode {
        OpticsMode::Displacement | OpticsMode::Bos => {
            let mut images = None;
            let disp = Displacement::new(frame, cam, plane.as_ref());
            let st = disp.st();
            let mut named: Vec<(&str, Vec<f32>)> = vec![
                ("displacement_px.X", f32s(disp.pixels.iter().map(|d| d[0]))),
                ("displacement_px.Y", f32s(disp.pixels.iter().map(|d| d[1]))),
                ("displacement.U", f32s(disp.world.iter().map(|d| d[0]))),
                ("displacement.V", f32s(disp.world.iter().map(|d| d[1]))),
                ("st.S", f32s(st.iter().map(|d| d[0]))),
                ("st.T", f32s(st.iter().map(|d| d[1]))),
                (
                    "valid",
                    f32s(disp.valid.iter().map(|&v| if v { 1.0 } else { 0.0 })),
                ),
            ];
            let max_px = disp
                .pixels
                .iter()
                .filter(|d| d[0].is_finite())
                .fold(0.0f64, |m, d| m.max(d[0].hypot(d[1])));
            let invalid = disp.valid.iter().filter(|v| !**v).count();
            if spec.mode == OpticsMode::Bos {
                let pl = plane
                    .as_ref()
                    .context("[optics] BOS needs a plane for its dots")?;
                // Rendered through the lens at the scene's spp, or point-sampled from
                // each pixel centre's ray.
                let rendered = bos_images.is_some();
                let (mut reference, mut distorted) =
                    bos_images.unwrap_or_else(|| bos_pair(frame, cam, pl, &spec.dots));
                images = Some(if rendered {
                    "rendered"
                } else {
                    "pixel centres"
                });
                if let Some(sensor) = sensor {
                    // Two exposures: independent noise.
                    record_all(sensor, &mut reference, 1);
                    record_all(sensor, &mut distorted, 2);
                }
                if let Some(png) = png {
                    let r = sibling(png, "reference");
                    staged.push(stage_rgb8_png(
                        &r,
                        frame.width,
                        frame.height,
                        &grey(&reference, 0.0, 1.0),
                    )?);
                    staged.push(stage_rgb8_png(
                        png,
                        frame.width,
                        frame.height,
                        &grey(&distorted, 0.0, 1.0),
                    )?);
                    pngs.push(png.to_owned());
                    pngs.push(r);
                }
                named.push(("reference", f32s(reference.into_iter())));
                named.push(("distorted", f32s(distorted.into_iter())));
            } else if let Some(png) = png {
                // Flow colours: red right, green down, 0.5 grey at rest; full scale = the
                // largest displacement.
                let scale = max_px.max(1e-12);
                let rgb: Vec<u8> = disp
                    .pixels
                    .iter()
                    .flat_map(|d| {
                        let c = |v: f64| {
                            if v.is_finite() {
                                ((0.5 + 0.5 * v / scale).clamp(0.0, 1.0) * 255.0).round() as u8
                            } else {
                                0
                            }
                        };
                        [c(d[0]), c(d[1]), 128]
                    })
                    .collect();
                staged.push(stage_rgb8_png(png, frame.width, frame.height, &rgb)?);
                pngs.push(png.to_owned());
            }
            summary = json!({
                "mode": mode_name(spec.mode),
                "images": images,
                "plane": spec.plane.is_some(),
                "max_displacement_px": max_px,
                "invalid_pixels": invalid,
                "channels": named.iter().map(|(n, _)| *n).collect::<Vec<_>>(),
            });
            staged.insert(0, stage_channels_exr(exr, size, named)?);
        }
        OpticsMode::Schlieren => {
            let angles = deflection_angles(frame, cam);
            let signal = schlieren(&angles, &spec.knife);
            let max_rad = angles
                .iter()
                .filter(|a| a[0].is_finite())
                .fold(0.0f64, |m, a| m.max(a[0].hypot(a[1])));
            if let Some(png) = png {
                staged.push(stage_rgb8_png(
                    png,
                    frame.width,
                    frame.height,
                    &grey(&signal, 0.0, 2.0),
                )?);
                pngs.push(png.to_owned());
            }
            summary = json!({
                "mode": "schlieren",
                "max_deflection_rad": max_rad,
                "saturated_pixels": signal.iter().filter(|&&s| s <= 0.0 || s >= 1.0 / (1.0 - spec.knife.cutoff)).count(),
                "channels": ["schlieren", "deflection_rad.X", "deflection_rad.Y"],
            });
            let named = vec![
                ("schlieren", f32s(signal.into_iter())),
                ("deflection_rad.X", f32s(angles.iter().map(|a| a[0]))),
                ("deflection_rad.Y", f32s(angles.iter().map(|a| a[1]))),
            ];
            staged.insert(0, stage_channels_exr(exr, size, named)?);
        }
        OpticsMode::Interferogram => {
            let (phase, mut intensity) = interferogram(frame, spec.wavelength_nm, &spec.fringes);
            if let Some(sensor) = sensor {
                record_all(sensor, &mut intensity, 1);
            }
            if let Some(png) = png {
                staged.push(stage_rgb8_png(
                    png,
                    frame.width,
                    frame.height,
                    &grey(&intensity, 0.0, 1.0),
                )?);
                pngs.push(png.to_owned());
            }
            let (lo, hi) = phase
                .iter()
                .filter(|p| p.is_finite())
                .fold((f64::MAX, f64::MIN), |(a, b), &p| (a.min(p), b.max(p)));
            summary = json!({
                "mode": "interferogram",
                "phase_range_waves": [lo, hi],
                "channels": ["intensity", "phase_waves", "opd"],
            });
            let named = vec![
                ("intensity", f32s(intensity.into_iter())),
                ("phase_waves", f32s(phase.into_iter())),
                ("opd", frame.pixels.iter().map(|p| p.opd_plane).collect()),
            ];
            staged.insert(0, stage_channels_exr(exr, size, named)?);
        }
        OpticsMode::Shadowgraph => anyhow::bail!("the shadowgraph traces its own beam"),
    }
    let mut summary = summary;
    summary["pngs"] = json!(pngs);
    Ok((staged, summary))
}

/// Stage a shadowgraph (traced by either backend) to `exr` and `png`.
pub fn stage_shadowgraph(
    sg: &grin_trace::shadowgraph::Shadowgraph,
    exr: &Path,
    png: Option<&Path>,
) -> anyhow::Result<(Vec<Staged>, serde_json::Value)> {
    let mut staged = vec![stage_channels_exr(
        exr,
        (sg.width as usize, sg.height as usize),
        vec![("intensity", f32s(sg.intensity.iter().copied()))],
    )?];
    if let Some(png) = png {
        staged.push(stage_rgb8_png(
            png,
            sg.width,
            sg.height,
            &grey(&sg.intensity, 0.0, 2.0),
        )?);
    }
    let peak = sg.intensity.iter().fold(0.0f64, |m, &v| m.max(v));
    let summary = json!({
        "mode": "shadowgraph",
        "rays_launched": sg.launched,
        "rays_on_screen": sg.landed,
        "rays_stopped": sg.stopped,
        "energy_on_screen": sg.landed as f64 / sg.launched.max(1) as f64,
        "peak_intensity": peak,
        "screen_size": sg.size,
        "screen_centre": sg.centre.to_array(),
        "channels": ["intensity"],
        "pngs": png.map(|p| vec![p.to_owned()]).unwrap_or_default(),
    });
    Ok((staged, summary))
}
