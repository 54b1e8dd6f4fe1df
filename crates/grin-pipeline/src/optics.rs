//! The image-space output of a scene's `[optics]` mode as named channels and previews
//! (docs/optics.md). Displacement, schlieren, interferogram and BOS come from the rendered
//! frame's AOVs (either backend); the shadowgraph traces its own collimated beam.

use anyhow::Context;
use grin_render::image::Frame;
use grin_render::optics::{
    Displacement, Plane, bos_pair, deflection_angles, interferogram, schlieren,
};
use grin_render::scene::RenderScene;
use grin_render::sensor::record_all;
use grin_scene::{OpticsMode, OpticsSpec};
use serde_json::json;

use crate::{Image, Preview};

/// The mode's name as the scene writes it.
pub fn mode_name(mode: OpticsMode) -> &'static str {
    mode.into()
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

/// The optical output of `spec` from `frame` (rendered by `rs` at 1 sample a pixel;
/// `bos_images`: the BOS reference and distorted images where they were rendered through
/// the lens), and the summary of what it holds.
pub fn from_frame(
    spec: &OpticsSpec,
    sensor: Option<&grin_scene::Sensor>,
    bos_images: Option<(Vec<f64>, Vec<f64>)>,
    rs: &RenderScene,
    frame: &Frame,
) -> anyhow::Result<(Image, serde_json::Value)> {
    let cam = &rs.camera;
    let mut image = Image::new(frame.width, frame.height);
    let preview = |rgb8| Preview { suffix: None, rgb8 };
    let plane = match &spec.plane {
        Some(p) => Some(Plane::new(p, cam).context(
            "[optics] plane: its normal is zero or the plane is seen edge-on by the camera",
        )?),
        None => None,
    };
    let summary;
    match spec.mode {
        OpticsMode::Displacement | OpticsMode::Bos => {
            let mut images = None;
            let disp = Displacement::new(frame, cam, plane.as_ref());
            let st = disp.st();
            image.push("displacement_px.X", f32s(disp.pixels.iter().map(|d| d[0])));
            image.push("displacement_px.Y", f32s(disp.pixels.iter().map(|d| d[1])));
            image.push("displacement.U", f32s(disp.world.iter().map(|d| d[0])));
            image.push("displacement.V", f32s(disp.world.iter().map(|d| d[1])));
            image.push("st.S", f32s(st.iter().map(|d| d[0])));
            image.push("st.T", f32s(st.iter().map(|d| d[1])));
            image.push(
                "valid",
                f32s(disp.valid.iter().map(|&v| if v { 1.0 } else { 0.0 })),
            );
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
                image.previews.push(preview(grey(&distorted, 0.0, 1.0)));
                image.previews.push(Preview {
                    suffix: Some("reference"),
                    rgb8: grey(&reference, 0.0, 1.0),
                });
                image.push("reference", f32s(reference.into_iter()));
                image.push("distorted", f32s(distorted.into_iter()));
            } else {
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
                image.previews.push(preview(rgb));
            }
            summary = json!({
                "mode": mode_name(spec.mode),
                "images": images,
                "plane": spec.plane.is_some(),
                "max_displacement_px": max_px,
                "invalid_pixels": invalid,
                "channels": image.names(),
            });
        }
        OpticsMode::Schlieren => {
            let angles = deflection_angles(frame, cam);
            let signal = schlieren(&angles, &spec.knife);
            let max_rad = angles
                .iter()
                .filter(|a| a[0].is_finite())
                .fold(0.0f64, |m, a| m.max(a[0].hypot(a[1])));
            image.previews.push(preview(grey(&signal, 0.0, 2.0)));
            let saturated = signal
                .iter()
                .filter(|&&s| s <= 0.0 || s >= 1.0 / (1.0 - spec.knife.cutoff))
                .count();
            image.push("schlieren", f32s(signal.into_iter()));
            image.push("deflection_rad.X", f32s(angles.iter().map(|a| a[0])));
            image.push("deflection_rad.Y", f32s(angles.iter().map(|a| a[1])));
            summary = json!({
                "mode": "schlieren",
                "max_deflection_rad": max_rad,
                "saturated_pixels": saturated,
                "channels": image.names(),
            });
        }
        OpticsMode::Interferogram => {
            let (phase, mut intensity) = interferogram(frame, spec.wavelength_nm, &spec.fringes);
            if let Some(sensor) = sensor {
                record_all(sensor, &mut intensity, 1);
            }
            image.previews.push(preview(grey(&intensity, 0.0, 1.0)));
            let (lo, hi) = phase
                .iter()
                .filter(|p| p.is_finite())
                .fold((f64::MAX, f64::MIN), |(a, b), &p| (a.min(p), b.max(p)));
            image.push("intensity", f32s(intensity.into_iter()));
            image.push("phase_waves", f32s(phase.into_iter()));
            image.push("opd", frame.pixels.iter().map(|p| p.opd_plane).collect());
            summary = json!({
                "mode": "interferogram",
                "phase_range_waves": [lo, hi],
                "channels": image.names(),
            });
        }
        OpticsMode::Shadowgraph => anyhow::bail!("the shadowgraph traces its own beam"),
    }
    Ok((image, summary))
}

/// A shadowgraph (traced by either backend) as its one channel and preview, and its
/// summary.
pub fn from_shadowgraph(sg: &grin_trace::shadowgraph::Shadowgraph) -> (Image, serde_json::Value) {
    let mut image = Image::new(sg.width, sg.height);
    image.previews.push(Preview {
        suffix: None,
        rgb8: grey(&sg.intensity, 0.0, 2.0),
    });
    image.push("intensity", f32s(sg.intensity.iter().copied()));
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
        "channels": image.names(),
    });
    (image, summary)
}
