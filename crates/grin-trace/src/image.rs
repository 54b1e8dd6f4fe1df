//! Rendered frames and their files: linear HDR EXR with the beauty pass and AOV channels,
//! a tonemapped sRGB PNG preview, and the per-pixel difference metric used to compare
//! the GPU with the CPU. Files are written to a temporary file in the same directory and
//! renamed, so an interrupted write never leaves a broken output file.

use std::path::{Path, PathBuf};

use exr::prelude::*;

/// `exr::prelude` exports its own `Result`; this module means std's.
type Result<T, E> = std::result::Result<T, E>;

use crate::render::RenderError;

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
    /// `RayStatus` as a number: 0 missed, 1 exited, 2 absorbed, 3 max_steps, 4 error.
    pub status: f32,
}

/// A rendered image, row 0 at the top.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<PixelOut>,
}

/// EXR channel names: beauty as R, G, B; AOVs as `aov.*` channels of the same part.
pub const AOV_CHANNELS: [&str; 8] = [
    "aov.deflection_deg",
    "aov.exit_dir.X",
    "aov.exit_dir.Y",
    "aov.exit_dir.Z",
    "aov.opd",
    "aov.steps",
    "aov.evals",
    "aov.status",
];

fn output_err(path: &Path, message: impl ToString) -> RenderError {
    RenderError::Output {
        path: path.to_owned(),
        message: message.to_string(),
    }
}

/// `dir/.name.tmp-<pid>`: a sibling of `path`, so the final rename stays on one filesystem.
fn temp_sibling(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map_or_else(|| "out".into(), |n| n.to_string_lossy().into_owned());
    path.with_file_name(format!(".{name}.tmp-{}", std::process::id()))
}

/// Write with `write` to a temporary sibling of `path`, then rename it into place.
fn write_atomically(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), String>,
) -> Result<(), RenderError> {
    let tmp = temp_sibling(path);
    if let Err(message) = write(&tmp) {
        let _ = std::fs::remove_file(&tmp);
        return Err(output_err(path, message));
    }
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        output_err(path, e)
    })
}

impl Frame {
    fn channel(&self, f: impl Fn(&PixelOut) -> f32) -> Vec<f32> {
        self.pixels.iter().map(f).collect()
    }

    /// Linear HDR EXR: R, G, B and the `aov.*` channels, lossless ZIP compression.
    pub fn write_exr(&self, path: &Path) -> Result<(), RenderError> {
        let size = (self.width as usize, self.height as usize);
        let named: Vec<(&str, Vec<f32>)> = vec![
            ("R", self.channel(|p| p.rgb[0])),
            ("G", self.channel(|p| p.rgb[1])),
            ("B", self.channel(|p| p.rgb[2])),
            (AOV_CHANNELS[0], self.channel(|p| p.deflection_deg)),
            (AOV_CHANNELS[1], self.channel(|p| p.exit_dir[0])),
            (AOV_CHANNELS[2], self.channel(|p| p.exit_dir[1])),
            (AOV_CHANNELS[3], self.channel(|p| p.exit_dir[2])),
            (AOV_CHANNELS[4], self.channel(|p| p.opd)),
            (AOV_CHANNELS[5], self.channel(|p| p.steps)),
            (AOV_CHANNELS[6], self.channel(|p| p.evals)),
            (AOV_CHANNELS[7], self.channel(|p| p.status)),
        ];
        let channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = named
            .into_iter()
            .map(|(name, data)| AnyChannel::new(name, FlatSamples::F32(data)))
            .collect();
        let layer = Layer::new(
            size,
            LayerAttributes::named("grin"),
            Encoding::SMALL_LOSSLESS,
            AnyChannels::sort(channels),
        );
        let image = Image::from_layer(layer);
        write_atomically(path, |tmp| {
            image.write().to_file(tmp).map_err(|e| e.to_string())
        })
    }

    /// Read an EXR written by [`Frame::write_exr`] (beauty and AOVs).
    pub fn read_exr(path: &Path) -> Result<Frame, RenderError> {
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
        let aov: Vec<Vec<f32>> = AOV_CHANNELS
            .iter()
            .map(|n| get(n))
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

    /// Write the PNG preview.
    pub fn write_png(&self, path: &Path) -> Result<(), RenderError> {
        let buf = self.preview_rgb8();
        write_atomically(path, |tmp| {
            image::save_buffer_with_format(
                tmp,
                &buf,
                self.width,
                self.height,
                image::ColorType::Rgb8,
                image::ImageFormat::Png,
            )
            .map_err(|e| e.to_string())
        })
    }

    /// Mean of primary-ray steps per pixel sample.
    pub fn mean_steps(&self) -> f64 {
        self.pixels.iter().map(|p| f64::from(p.steps)).sum::<f64>()
            / self.pixels.len().max(1) as f64
    }
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
/// difference of each pixel, summarised.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiffStats {
    pub mean: f64,
    pub p99: f64,
    pub max: f64,
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
                .map(|c| f64::from((p.rgb[c] - q.rgb[c]).abs()))
                .fold(0.0, f64::max)
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
    }
}
