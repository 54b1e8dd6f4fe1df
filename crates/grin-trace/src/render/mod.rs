//! The CPU renderer: the path loop around a GRIN medium over the render description of
//! grin-render (camera, primitives, materials, lights, sky), one pixel sample at a time
//! with rayon. The reference the GPU marcher is tested against: every function here has a
//! WGSL twin of the same name in shaders/.

pub mod medium;
pub mod shade;
#[cfg(test)]
mod tests;

use std::sync::atomic::{AtomicBool, Ordering};

use glam::DVec3;
use rayon::prelude::*;

use grin_render::image::{Frame, PixelOut};
use rng::Rng;

use grin_render::scene::{MIN_JITTER_FRACTION, RenderError, RenderScene, SceneMedium};
use grin_render::{materials, primitives, rng, surface};

/// All samples of pixel (px, py): mean radiance; AOVs of sample 0, steps and field
/// evaluations averaged over the samples.
pub fn render_pixel(scene: &RenderScene, px: u32, py: u32) -> PixelOut {
    let index = py * scene.settings.width + px;
    let mut rgb = DVec3::ZERO;
    let mut steps = 0u64;
    let mut evals = 0u64;
    let mut first = None;
    let seed = scene.settings.seed as u32;
    for sample in 0..scene.settings.spp {
        let mut rng = Rng::for_pixel(index, sample, seed);
        let (sx, sy) = scene.subpixel(&mut rng);
        // Drawn after the sub-pixel position, so the stream is unchanged when it is off.
        let jitter = if scene.settings.jitter {
            rng.next_f32().max(MIN_JITTER_FRACTION)
        } else {
            1.0
        };
        let (o, d) = scene.camera.camera_ray(px, py, sx, sy);
        // A thin lens's aperture point, drawn last (the stream is unchanged without
        // one), with the sub-pixel position's rule: none for a single-sample image.
        let (o, d) = if scene.camera.lens_radius > 0.0 && scene.settings.spp != 1 {
            let (u1, u2) = (rng.next_f32(), rng.next_f32());
            scene.camera.lens_ray(d, f64::from(u1), f64::from(u2))
        } else {
            (o, d)
        };
        let path = shade::CpuScene(scene).trace_path(o, d, f64::from(jitter), &mut rng);
        rgb += path.rgb;
        steps += u64::from(path.aov.steps);
        evals += path.aov.evals;
        first.get_or_insert(path.aov);
    }
    let spp = f64::from(scene.settings.spp);
    let Some(aov) = first else {
        return PixelOut::default();
    };
    PixelOut {
        rgb: (rgb / spp).as_vec3().to_array(),
        deflection_deg: aov.deflection_deg as f32,
        exit_dir: aov.exit_dir.as_vec3().to_array(),
        opd: aov.opd as f32,
        steps: (steps as f64 / spp) as f32,
        evals: (evals as f64 / spp) as f32,
        status: f32::from(shade::status_code(aov.status)),
        exit_pos: aov.exit_pos.as_vec3().to_array(),
        opd_plane: aov.opd_plane as f32,
    }
}

/// Render every pixel on the CPU with rayon. `progress(1)` is called after each row
/// (from worker threads); setting `cancel` stops the render with [`RenderError::Cancelled`].
pub fn render_cpu(
    scene: &RenderScene,
    progress: &(dyn Fn(u32) + Sync),
    cancel: &AtomicBool,
) -> Result<Frame, RenderError> {
    let (w, h) = (scene.settings.width, scene.settings.height);
    let mut pixels = grin_field::alloc::try_filled(
        w as usize * h as usize,
        PixelOut::default(),
        &format!("a {w}x{h} frame"),
    )
    .map_err(|e| RenderError::Memory(e.to_string()))?;
    pixels
        .par_chunks_mut(w as usize)
        .enumerate()
        .try_for_each(|(py, row)| {
            if cancel.load(Ordering::Relaxed) {
                return Err(RenderError::Cancelled);
            }
            for (px, out) in row.iter_mut().enumerate() {
                *out = render_pixel(scene, px as u32, py as u32);
            }
            progress(1);
            Ok(())
        })?;
    Ok(Frame {
        width: w,
        height: h,
        pixels,
    })
}
