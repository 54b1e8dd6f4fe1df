//! Datasets for learning: background-oriented schlieren (BOS) pairs of randomised hot-air
//! media, with their ground truth, deterministic by seed and sample index.
//!
//! Sample `i` of seed `s` draws everything from `frame_seed(s, i)`: one to four Gaussian
//! plumes (amplitude, width, place), the camera (distance, height, focal length), the dot
//! plate (dot size in pixels, cover, pattern) and the sensor's noise. It is rendered as a
//! scene file would be (the sample's own TOML is kept in its JSON), so any sample can be
//! rendered again alone with `grin render`.
//!
//! Files of sample `i` in the output folder (`bos_000123.*`):
//! - `.exr`: the BOS channels of `grin render` (`reference`, `distorted`: the two
//!   exposures; `displacement_px.X/Y`, `displacement.U/V`, `st.S/T`, `valid`: the true
//!   displacement) and `deflection_rad.X/Y` (each pixel ray's deflection: the line
//!   integral of the projected grad n / n);
//! - `-slice.exr`: the medium's index `n` on its mid-plane z = 0 ([`SLICE`] x [`SLICE`]
//!   nodes over the medium's x, y box);
//! - `.png` and `-reference.png`: 8-bit previews of the two exposures;
//! - `.json`: index, seeds, the medium, the camera's intrinsics and extrinsics, the files
//!   and the scene TOML; written last, so a sample is complete exactly when its JSON
//!   exists. A run skips complete samples (a retried or resumed job redoes only what is
//!   missing); `manifest.jsonl` holds every sample's JSON, a line each, in index order.

use std::path::{Path, PathBuf};

use anyhow::Context;
use glam::DVec3;
use grin_field::bake::SplitMix64;
use grin_render::image::{stage_channels_exr, stage_rgb8_png};
use serde_json::json;

use crate::{Quiet, Renderer};

/// Nodes per side of the index slice.
pub const SLICE: usize = 64;

/// The medium's box: plumes are placed well inside it.
const BOX_MIN: [f64; 3] = [-0.6, -0.6, -0.6];
const BOX_MAX: [f64; 3] = [0.6, 0.9, 0.6];
/// Air at 20 C.
const AMBIENT: f64 = 1.000272;
/// The dot plate's distance behind the medium's centre (m).
const PLATE_Z: f64 = 4.0;

/// A BOS dataset: its seed and image size.
#[derive(Debug, Clone, Copy)]
pub struct Bos {
    pub seed: u64,
    pub width: u32,
    pub height: u32,
}

/// One sample's scene and what it was drawn from.
#[derive(Debug, Clone)]
pub struct Sample {
    pub index: u64,
    pub toml: String,
    pub scene: grin_scene::Scene,
    /// Seeds, medium, camera (intrinsics, extrinsics), plate.
    pub meta: serde_json::Value,
}

/// A rendered sample: its channels (the BOS output's and `deflection_rad.X/Y`) and
/// previews, the index slice ([`SLICE`]², row 0 at the largest y) and its JSON.
#[derive(Debug, Clone)]
pub struct RenderedSample {
    pub image: crate::Image,
    pub slice: Vec<f32>,
    pub meta: serde_json::Value,
}

/// What a [`Bos::write`] run did.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RunSummary {
    pub rendered: usize,
    pub skipped: usize,
    pub seconds: f64,
    /// Samples rendered per second (wall clock of the run).
    pub samples_per_second: f64,
    /// Whether `manifest.jsonl` was written (every sample of the dataset is there).
    pub manifest: bool,
}

impl Bos {
    /// Sample `index`'s scene.
    pub fn sample(&self, index: u64) -> anyhow::Result<Sample> {
        let seed = grin_scene::frames::frame_seed(self.seed, index as i64);
        let mut rng = SplitMix64(seed);
        let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.next_f64();
        let count = 1 + (u(0.0, 4.0) as usize).min(3);
        let plumes: Vec<[f64; 5]> = (0..count)
            .map(|_| {
                [
                    u(2.0e-4, 1.2e-3),
                    u(-0.3, 0.3),
                    u(-0.3, 0.5),
                    u(-0.25, 0.25),
                    u(0.06, 0.2),
                ]
            })
            .collect();
        let distance = u(3.5, 4.5);
        let position = [u(-0.15, 0.15), 0.15 + u(-0.1, 0.1), -distance];
        let look_at = [0.0, 0.15, 0.0];
        let focal_mm = u(40.0, 60.0);
        let sensor_mm = 10.5;
        // Dots of 2.5-4 pixels on the plate, 30-50 % cover.
        let pixel_on_plate = (distance + PLATE_Z) * sensor_mm / focal_mm / f64::from(self.height);
        let dot = pixel_on_plate * u(2.5, 4.0);
        let density = u(0.3, 0.5);
        let dots_seed = (u(0.0, 1.0) * 4_294_967_295.0) as u64;
        let sensor_seed = (u(0.0, 1.0) * 4_294_967_295.0) as u64;
        let plume_lines: Vec<String> = plumes
            .iter()
            .map(|p| {
                format!(
                    "    {{ a = {:e}, center = [{}, {}, {}], s = {} }},",
                    p[0], p[1], p[2], p[3], p[4]
                )
            })
            .collect();
        let toml = format!(
            "# grin dataset bos: seed {seed_base}, sample {index}\n\
             [camera]\nposition = [{}, {}, {}]\nlook_at = [{}, {}, {}]\n\
             focal_length_mm = {focal_mm}\nsensor_height_mm = {sensor_mm}\n\n\
             [sensor]\nfull_well = 20000.0\nread_noise = 2.0\nbits = 12\nseed = {sensor_seed}\n\n\
             [medium]\nbounds = {{ box = {{ min = {BOX_MIN:?}, max = {BOX_MAX:?} }} }}\n\
             ambient_index = {AMBIENT}\nfield = {{ kind = \"plume\", plumes = [\n{}\n] }}\n\n\
             [render]\nwidth = {}\nheight = {}\n\n\
             [optics]\nmode = \"bos\"\n\
             plane = {{ point = [0.0, 0.0, {PLATE_Z}], normal = [0.0, 0.0, -1.0] }}\n\
             dots = {{ diameter = {dot}, density = {density}, seed = {dots_seed} }}\n",
            position[0],
            position[1],
            position[2],
            look_at[0],
            look_at[1],
            look_at[2],
            plume_lines.join("\n"),
            self.width,
            self.height,
            seed_base = self.seed,
        );
        let scene = grin_scene::parse_scene(&toml, Path::new("<dataset sample>"))
            .with_context(|| format!("dataset sample {index}"))?;
        let cam = grin_render::camera::PinholeCamera::new(&scene.camera, self.width, self.height)
            .with_context(|| format!("dataset sample {index}: camera"))?;
        // Pixels: x right, y down; the camera looks along +z (OpenCV's convention).
        let fy = 0.5 * f64::from(self.height) / cam.tan_half_fov_y;
        let rotation = [
            cam.right.to_array(),
            (-cam.up).to_array(),
            cam.forward.to_array(),
        ];
        let meta = json!({
            "index": index,
            "dataset_seed": self.seed,
            "sample_seed": seed,
            "medium": {
                "kind": "plume",
                "ambient_index": AMBIENT,
                "bounds": {"min": BOX_MIN, "max": BOX_MAX},
                "plumes": plumes.iter().map(|p| json!({
                    "a": p[0], "center": [p[1], p[2], p[3]], "s": p[4],
                })).collect::<Vec<_>>(),
            },
            "camera": {
                "width": self.width,
                "height": self.height,
                "intrinsics": {
                    "fx": fy, "fy": fy,
                    "cx": 0.5 * f64::from(self.width), "cy": 0.5 * f64::from(self.height),
                    "focal_length_mm": focal_mm, "sensor_height_mm": sensor_mm,
                },
                "extrinsics": {
                    "position": position,
                    "look_at": look_at,
                    "camera_from_world_rotation": rotation,
                },
            },
            "plate": {
                "point": [0.0, 0.0, PLATE_Z], "normal": [0.0, 0.0, -1.0],
                "dot_diameter": dot, "dot_density": density, "dots_seed": dots_seed,
            },
            "sensor_seed": sensor_seed,
        });
        Ok(Sample {
            index,
            toml,
            scene,
            meta,
        })
    }

    /// The files of sample `index` in `dir`: (EXR, slice EXR, PNG, reference PNG, JSON).
    pub fn files(dir: &Path, index: u64) -> [PathBuf; 5] {
        let stem = format!("bos_{index:06}");
        [
            dir.join(format!("{stem}.exr")),
            dir.join(format!("{stem}-slice.exr")),
            dir.join(format!("{stem}.png")),
            dir.join(format!("{stem}-reference.png")),
            dir.join(format!("{stem}.json")),
        ]
    }

    /// Render sample `index` (relative paths from `dir`): the BOS channels with the
    /// deflection, the index slice, the previews and the JSON (without its files).
    pub fn render_sample(
        &self,
        renderer: &Renderer,
        dir: &Path,
        index: u64,
    ) -> anyhow::Result<RenderedSample> {
        let sample = self.sample(index)?;
        let label = format!("dataset sample {index}");
        let rendered = renderer.render(sample.scene.clone(), dir, &label, &Quiet)?;
        let mut image = rendered.image;
        let frame = rendered
            .frame
            .as_ref()
            .context("a BOS render keeps its frame")?;
        let angles = grin_render::optics::deflection_angles(frame, &rendered.camera);
        image.push(
            "deflection_rad.X",
            angles.iter().map(|a| a[0] as f32).collect(),
        );
        image.push(
            "deflection_rad.Y",
            angles.iter().map(|a| a[1] as f32).collect(),
        );
        let slice = index_slice(&sample.scene, dir)?;
        let mut meta = sample.meta;
        meta["slice"] = json!({
            "plane_z": 0.0, "nodes": SLICE,
            "x": [BOX_MIN[0], BOX_MAX[0]], "y": [BOX_MIN[1], BOX_MAX[1]],
            "row_0": "largest y",
        });
        meta["max_displacement_px"] = rendered
            .report
            .optics
            .as_ref()
            .map_or(json!(null), |o| o["max_displacement_px"].clone());
        meta["scene_toml"] = json!(sample.toml);
        Ok(RenderedSample { image, slice, meta })
    }

    /// Render sample `index` and write its files to `dir` (its JSON last); returns the
    /// JSON.
    pub fn write_sample(
        &self,
        renderer: &Renderer,
        dir: &Path,
        index: u64,
    ) -> anyhow::Result<serde_json::Value> {
        let RenderedSample {
            image,
            slice,
            mut meta,
        } = self.render_sample(renderer, dir, index)?;
        let [exr, slice_exr, png, reference_png, json_path] = Self::files(dir, index);
        let size = (image.width as usize, image.height as usize);
        let named: Vec<(&str, Vec<f32>)> = image
            .channels
            .iter()
            .map(|(n, d)| (n.as_str(), d.clone()))
            .collect();
        let mut staged = vec![stage_channels_exr(&exr, size, named)?];
        staged.push(stage_channels_exr(
            &slice_exr,
            (SLICE, SLICE),
            vec![("n", slice)],
        )?);
        for preview in &image.previews {
            let path = match preview.suffix {
                None => &png,
                Some(_) => &reference_png,
            };
            staged.push(stage_rgb8_png(
                path,
                image.width,
                image.height,
                &preview.rgb8,
            )?);
        }
        grin_output::commit(staged)?;
        let name = |p: &Path| p.file_name().map(|n| n.to_string_lossy().into_owned());
        meta["files"] = json!({
            "exr": name(&exr), "slice_exr": name(&slice_exr),
            "png": name(&png), "reference_png": name(&reference_png),
        });
        let text = serde_json::to_string(&meta)?;
        grin_output::commit(vec![grin_output::stage_writer(&json_path, |w| {
            w.write_all(text.as_bytes())?;
            w.write_all(b"\n")
        })?])?;
        Ok(meta)
    }

    /// Write samples `indices` of a `count`-sample dataset to `dir`, skipping complete
    /// ones; `progress(done, total)` after each. The manifest is written when every
    /// sample of the dataset is there.
    pub fn write(
        &self,
        renderer: &Renderer,
        dir: &Path,
        count: u64,
        indices: &[u64],
        progress: &dyn Fn(usize, usize),
    ) -> anyhow::Result<RunSummary> {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create the dataset folder", dir.display()))?;
        let start = std::time::Instant::now();
        let (mut rendered, mut skipped) = (0, 0);
        for (done, &i) in indices.iter().enumerate() {
            if Self::files(dir, i)[4].exists() {
                skipped += 1;
            } else {
                self.write_sample(renderer, dir, i)?;
                rendered += 1;
            }
            progress(done + 1, indices.len());
        }
        let seconds = start.elapsed().as_secs_f64();
        let manifest = self.write_manifest(dir, count)?;
        Ok(RunSummary {
            rendered,
            skipped,
            seconds,
            samples_per_second: rendered as f64 / seconds.max(1e-9),
            manifest,
        })
    }

    /// `manifest.jsonl` from the samples' JSON files, when all `count` are there.
    pub fn write_manifest(&self, dir: &Path, count: u64) -> anyhow::Result<bool> {
        let mut lines = Vec::new();
        for i in 0..count {
            let path = Self::files(dir, i)[4].clone();
            match std::fs::read_to_string(&path) {
                Ok(text) => lines.push(text),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(false),
                Err(e) => return Err(e).with_context(|| format!("{}", path.display())),
            }
        }
        let manifest = dir.join("manifest.jsonl");
        grin_output::commit(vec![grin_output::stage_writer(&manifest, |w| {
            for line in &lines {
                w.write_all(line.as_bytes())?;
            }
            Ok(())
        })?])?;
        Ok(true)
    }
}

/// The medium's index on its mid-plane z = 0: [`SLICE`]² nodes over its x, y box, row 0
/// at the largest y.
fn index_slice(scene: &grin_scene::Scene, dir: &Path) -> anyhow::Result<Vec<f32>> {
    let medium = scene
        .medium
        .as_ref()
        .context("a dataset sample has a medium")?;
    let field = grin_field::build_field(medium, dir)?;
    let step = |lo: f64, hi: f64, i: usize| lo + (hi - lo) * i as f64 / (SLICE - 1) as f64;
    let mut out = Vec::with_capacity(SLICE * SLICE);
    for row in 0..SLICE {
        let y = step(BOX_MAX[1], BOX_MIN[1], row);
        for col in 0..SLICE {
            let x = step(BOX_MIN[0], BOX_MAX[0], col);
            out.push(field.n(DVec3::new(x, y, 0.0)) as f32);
        }
    }
    Ok(out)
}
