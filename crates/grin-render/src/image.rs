//! Rendered frames and their files: linear HDR EXR with the beauty pass and AOV channels,
//! a tonemapped sRGB PNG preview, and the per-pixel difference metric used to compare
//! the GPU with the CPU. Files are staged and committed through grin-output, so an
//! interrupted write never leaves a broken output file and an EXR and its PNG are replaced
//! together.

use std::path::Path;

use exr::prelude::*;
use grin_output::Staged;

/// `exr::prelude` exports its own `Result`; this module means std's.
type Result<T, E> = std::result::Result<T, E>;

use crate::scene::RenderError;

/// One output pixel: linear radiance and the AOVs. Plain f32s so the GPU can write the
/// same layout (keep in sync with grin-gpu's `gpu_data::PixelOut`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PixelOut {
    pub rgb: [f32; 3],
    /// Angle (degrees) between the camera ray entering the medium and leaving it.
    pub deflection_deg: f32,
    /// Unit direction leaving the medium (the camera ray if it missed the medium).
    pub exit_dir: [f32; 3],
    /// Optical path difference vs the straight ray through the bounds (world units).
    pub opd: f32,
    /// Integration steps per sample (mean over the pixel's samples, whole path).
    pub steps: f32,
    /// Field evaluations per sample (mean, whole path).
    pub evals: f32,
    /// `RayStatus` as a number: 0 missed, 1 exited, 2 absorbed, 3 max_steps, 4 error,
    /// 5 degraded (left, with an error estimate above the limit).
    pub status: f32,
    /// Where the camera ray left the medium (world): where it stopped for absorbed,
    /// max_steps and error; the camera's position if it missed the medium.
    pub exit_pos: [f32; 3],
    /// `opd` with both paths taken on to the plane through the straight ray's exit, normal
    /// to it: stationary in the deflection, the interferogram's OPD (docs/optics.md).
    pub opd_plane: f32,
}

/// A rendered image, row 0 at the top.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<PixelOut>,
}

/// EXR channel names: beauty as R, G, B; AOVs as `aov.*` channels of the same part.
pub const AOV_CHANNELS: [&str; 12] = [
    "aov.deflection_deg",
    "aov.exit_dir.X",
    "aov.exit_dir.Y",
    "aov.exit_dir.Z",
    "aov.opd",
    "aov.steps",
    "aov.evals",
    "aov.status",
    "aov.exit_pos.X",
    "aov.exit_pos.Y",
    "aov.exit_pos.Z",
    "aov.opd_plane",
];

fn output_err(path: &Path, message: impl ToString) -> RenderError {
    RenderError::Output {
        path: path.to_owned(),
        message: message.to_string(),
    }
}

impl Frame {
    fn channel(&self, f: impl Fn(&PixelOut) -> f32) -> Result<Vec<f32>, RenderError> {
        let mut out = grin_field::alloc::try_with_capacity(
            self.pixels.len(),
            &format!("the EXR channels of a {}x{} frame", self.width, self.height),
        )
        .map_err(|e| RenderError::Memory(e.to_string()))?;
        out.extend(self.pixels.iter().map(f));
        Ok(out)
    }

    /// Write the EXR alone (see [`Frame::stage_exr`]).
    pub fn write_exr(&self, path: &Path) -> Result<(), RenderError> {
        Ok(grin_output::commit(vec![self.stage_exr(path)?])?)
    }

    /// The EXR's channels by name: R, G, B and the `aov.*` channels ([`AOV_CHANNELS`]).
    pub fn channels(&self) -> Result<Vec<(&'static str, Vec<f32>)>, RenderError> {
        Ok(vec![
            ("R", self.channel(|p| p.rgb[0])?),
            ("G", self.channel(|p| p.rgb[1])?),
            ("B", self.channel(|p| p.rgb[2])?),
            (AOV_CHANNELS[0], self.channel(|p| p.deflection_deg)?),
            (AOV_CHANNELS[1], self.channel(|p| p.exit_dir[0])?),
            (AOV_CHANNELS[2], self.channel(|p| p.exit_dir[1])?),
            (AOV_CHANNELS[3], self.channel(|p| p.exit_dir[2])?),
            (AOV_CHANNELS[4], self.channel(|p| p.opd)?),
            (AOV_CHANNELS[5], self.channel(|p| p.steps)?),
            (AOV_CHANNELS[6], self.channel(|p| p.evals)?),
            (AOV_CHANNELS[7], self.channel(|p| p.status)?),
            (AOV_CHANNELS[8], self.channel(|p| p.exit_pos[0])?),
            (AOV_CHANNELS[9], self.channel(|p| p.exit_pos[1])?),
            (AOV_CHANNELS[10], self.channel(|p| p.exit_pos[2])?),
            (AOV_CHANNELS[11], self.channel(|p| p.opd_plane)?),
        ])
    }

    /// Linear HDR EXR: R, G, B and the `aov.*` channels, lossless ZIP compression,
    /// written in full to a temporary file; [`grin_output::commit`] puts it in place.
    pub fn stage_exr(&self, path: &Path) -> Result<Staged, RenderError> {
        let size = (self.width as usize, self.height as usize);
        stage_channels_exr(path, size, self.channels()?)
    }

    /// Read an EXR written by [`Frame::write_exr`] (beauty and AOVs).
    pub fn read_exr(path: &Path) -> Result<Frame, RenderError> {
        // The header's size first: a small file declaring a huge image is refused unread.
        let (w, h) = crate::surface::exr_declared_size(path).map_err(|e| output_err(path, e))?;
        if w as u64 * h as u64 > crate::scene::MAX_PIXELS {
            return Err(output_err(
                path,
                format!(
                    "{w}x{h} exceeds the {} pixels a frame may hold",
                    crate::scene::MAX_PIXELS
                ),
            ));
        }
        let image = read_all_flat_layers_from_file(path).map_err(|e| output_err(path, e))?;
        let layer = image
            .layer_data
            .first()
            .ok_or_else(|| output_err(path, "no layer"))?;
        let (w, h) = (layer.size.width(), layer.size.height());
        let get = |name: &str| -> Result<Vec<f32>, RenderError> {
            let ch = layer
                .channel_data
                .list
                .iter()
                .find(|c| c.name.to_string() == name)
                .ok_or_else(|| output_err(path, format!("missing channel `{name}`")))?;
            Ok(ch.sample_data.values_as_f32().collect())
        };
        let r = get("R")?;
        let g = get("G")?;
        let b = get("B")?;
        // The exit position came later than the others: older files read as zeros.
        let aov: Vec<Vec<f32>> = AOV_CHANNELS
            .iter()
            .map(|n| match get(n) {
                Err(_) if n.starts_with("aov.exit_pos") || *n == "aov.opd_plane" => {
                    Ok(vec![0.0; w * h])
                }
                other => other,
            })
            .collect::<Result<_, _>>()?;
        let pixels = (0..w * h)
            .map(|i| PixelOut {
                rgb: [r[i], g[i], b[i]],
                deflection_deg: aov[0][i],
                exit_dir: [aov[1][i], aov[2][i], aov[3][i]],
                opd: aov[4][i],
                steps: aov[5][i],
                evals: aov[6][i],
                status: aov[7][i],
                exit_pos: [aov[8][i], aov[9][i], aov[10][i]],
                opd_plane: aov[11][i],
            })
            .collect();
        Ok(Frame {
            width: w as u32,
            height: h as u32,
            pixels,
        })
    }

    /// The tonemapped 8-bit sRGB preview (clamped linear, sRGB transfer function).
    pub fn preview_rgb8(&self) -> Vec<u8> {
        self.pixels
            .iter()
            .flat_map(|p| p.rgb.map(linear_to_srgb8))
            .collect()
    }

    /// Write the PNG preview alone.
    pub fn write_png(&self, path: &Path) -> Result<(), RenderError> {
        Ok(grin_output::commit(vec![self.stage_png(path)?])?)
    }

    /// The PNG preview, staged like [`Frame::stage_exr`].
    pub fn stage_png(&self, path: &Path) -> Result<Staged, RenderError> {
        stage_rgb8_png(path, self.width, self.height, &self.preview_rgb8())
    }

    /// Mean of primary-ray steps per pixel sample.
    pub fn mean_steps(&self) -> f64 {
        self.pixels.iter().map(|p| f64::from(p.steps)).sum::<f64>()
            / self.pixels.len().max(1) as f64
    }
}

/// Named f32 channels of one `width` x `height` part as a lossless (ZIP) EXR, staged for
/// [`grin_output::commit`].
pub fn stage_channels_exr<N: AsRef<str>>(
    path: &Path,
    size: (usize, usize),
    named: Vec<(N, Vec<f32>)>,
) -> Result<Staged, RenderError> {
    let channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = named
        .into_iter()
        .map(|(name, data)| AnyChannel::new(name.as_ref(), FlatSamples::F32(data)))
        .collect();
    let layer = Layer::new(
        size,
        LayerAttributes::named("grin"),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(channels),
    );
    let image = Image::from_layer(layer);
    Ok(grin_output::stage_path(path, |tmp| {
        image.write().to_file(tmp).map_err(|e| e.to_string())
    })?)
}

/// 8-bit RGB pixels (row 0 at the top) as a PNG, staged for [`grin_output::commit`].
pub fn stage_rgb8_png(
    path: &Path,
    width: u32,
    height: u32,
    rgb: &[u8],
) -> Result<Staged, RenderError> {
    Ok(grin_output::stage_path(path, |tmp| {
        image::save_buffer_with_format(
            tmp,
            rgb,
            width,
            height,
            image::ColorType::Rgb8,
            image::ImageFormat::Png,
        )
        .map_err(|e| e.to_string())
    })?)
}

/// Linear [0, 1] to 8-bit sRGB (IEC 61966-2-1 transfer function).
pub fn linear_to_srgb8(x: f32) -> u8 {
    let x = if x.is_finite() {
        x.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let s = if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

/// Per-pixel difference between two frames' beauty passes: the largest channel
/// difference of each pixel, summarised. A pixel where either frame holds a NaN or an
/// infinity (and the two are not the same infinity) differs by +inf, so one broken pixel
/// makes `max` and `mean` infinite and no tolerance accepts it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiffStats {
    pub mean: f64,
    pub p99: f64,
    pub max: f64,
    /// Pixels whose difference is infinite (a NaN or an unmatched infinity).
    pub nonfinite: usize,
}

/// |a - b| of one channel; +inf where either is NaN or the two are unequal infinities.
fn channel_difference(a: f32, b: f32) -> f64 {
    if a.is_nan() || b.is_nan() {
        return f64::INFINITY;
    }
    if a == b {
        return 0.0;
    }
    f64::from((a - b).abs())
}

/// Compare beauty passes; `None` if the sizes differ.
pub fn diff_frames(a: &Frame, b: &Frame) -> Option<(DiffStats, Frame)> {
    if (a.width, a.height) != (b.width, b.height) {
        return None;
    }
    let d: Vec<f64> = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .map(|(p, q)| {
            (0..3)
                .map(|c| channel_difference(p.rgb[c], q.rgb[c]))
                .fold(0.0, |m: f64, x| if x > m { x } else { m })
        })
        .collect();
    let mut sorted = d.clone();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len().max(1);
    let stats = DiffStats {
        mean: d.iter().sum::<f64>() / n as f64,
        p99: sorted
            .get(((n as f64 * 0.99) as usize).min(n - 1))
            .copied()
            .unwrap_or(0.0),
        max: sorted.last().copied().unwrap_or(0.0),
        nonfinite: d.iter().filter(|x| !x.is_finite()).count(),
    };
    let diff = Frame {
        width: a.width,
        height: a.height,
        pixels: d
            .iter()
            .map(|&x| PixelOut {
                rgb: [x as f32; 3],
                ..PixelOut::default()
            })
            .collect(),
    };
    Some((stats, diff))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame() -> Frame {
        let pixels = (0..6)
            .map(|i| PixelOut {
                rgb: [i as f32 * 0.1, 0.5, 2.0],
                deflection_deg: i as f32,
                exit_dir: [0.0, 0.6, 0.8],
                opd: -1e-4 * i as f32,
                steps: 10.0 + i as f32,
                evals: 30.0,
                status: 1.0,
                exit_pos: [0.5, -0.25, 2.0 + i as f32],
                opd_plane: -2e-4 * i as f32,
            })
            .collect();
        Frame {
            width: 3,
            height: 2,
            pixels,
        }
    }

    #[test]
    fn exr_round_trip_keeps_every_channel() {
        let dir = std::env::temp_dir().join(format!("grin-image-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp dir");
        let path = dir.join("f.exr");
        let f = frame();
        f.write_exr(&path).expect("write");
        assert_eq!(Frame::read_exr(&path).expect("read"), f);
        f.write_png(&dir.join("f.png")).expect("png");
        let names: Vec<_> = std::fs::read_dir(&dir)
            .expect("ls")
            .map(|e| e.expect("entry").file_name())
            .collect();
        assert_eq!(names.len(), 2, "no temporary files left: {names:?}");
        // Writing into a missing directory fails with the path in the message.
        let e = f
            .write_exr(&dir.join("missing/x.exr"))
            .expect_err("missing dir");
        assert!(e.to_string().contains("missing/x.exr"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn srgb_transfer_and_diff_metric() {
        assert_eq!(linear_to_srgb8(0.0), 0);
        assert_eq!(linear_to_srgb8(1.0), 255);
        assert_eq!(linear_to_srgb8(5.0), 255);
        // Linear 0.5 is sRGB 0.7354 = 187.5 / 255.
        assert_eq!(linear_to_srgb8(0.5), 188);
        assert_eq!(linear_to_srgb8(0.002), 7);
        let a = frame();
        let mut b = a.clone();
        b.pixels[4].rgb[2] += 0.5;
        let (s, diff) = diff_frames(&a, &b).expect("same size");
        assert!((s.max - 0.5).abs() < 1e-6 && (s.mean - 0.5 / 6.0).abs() < 1e-6);
        assert_eq!(diff.pixels[4].rgb[0], 0.5);
        assert_eq!(s.nonfinite, 0);
    }

    #[test]
    fn a_nan_or_infinite_pixel_fails_the_comparison() {
        let a = frame();
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let mut b = a.clone();
            b.pixels[2].rgb[1] = bad;
            let (s, diff) = diff_frames(&a, &b).expect("same size");
            assert_eq!((s.max, s.nonfinite), (f64::INFINITY, 1), "{bad}");
            assert!(s.mean.is_infinite(), "{bad}");
            assert!(diff.pixels[2].rgb[0].is_infinite());
            // The same pixel broken in both frames is still a broken pixel (NaN), while
            // the same infinity in both is equal.
            let (s, _) = diff_frames(&b, &b).expect("same size");
            assert_eq!(s.nonfinite, usize::from(bad.is_nan()), "{bad}");
        }
    }
}
