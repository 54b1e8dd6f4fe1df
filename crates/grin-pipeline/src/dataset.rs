//! Datasets for learning: image pairs of randomised media with their ground truth,
//! deterministic by seed and sample index.
//!
//! Three kinds ([`Kind`]): background-oriented schlieren (`bos`: a dot plate seen without
//! and with the medium), knife-edge `schlieren` images, and heat-haze distortion (`haze`: a
//! background seen without and with the medium, with the ST map). Four sources of media
//! ([`Media`]): Gaussian plume sets, fBm/turbulence noise, expressions (a hot layer with
//! waves), and a pool of frames of the user's own scene (a VDB sequence, say).
//!
//! Sample `i` of seed `s` draws everything from `frame_seed(s, i)`: the medium, the camera
//! (distance, offset, focal length; it looks along +z at the medium's centre), the
//! background (dot size in pixels and cover, checker scale and contrast, or a plate image
//! from a pool), the knife and the sensor's noise. It is rendered as a scene file would be
//! (the sample's own TOML is kept in its JSON), so any sample can be rendered again alone
//! with `grin render`.
//!
//! Files of sample `i` in the output folder (`bos_000123.*`, `schlieren_...`, `haze_...`):
//! - `.exr`: the kind's channels (`reference` and `distorted` exposures for BOS;
//!   `schlieren` for schlieren; `reference.R/G/B` and `distorted.R/G/B` for haze), the true
//!   displacement where the kind has one (`displacement_px.X/Y`, `displacement.U/V`,
//!   `st.S/T`, `valid`), each pixel ray's deflection `deflection_rad.X/Y` (radians along
//!   the camera's right and up) and the projected gradient `grad_n_line.X/Y` (grad n
//!   integrated along the undeflected pixel ray, the same axes: deflection ~ it / n);
//! - `-slice.exr`: the medium's index `n` on the plane through its centre facing the
//!   camera ([`SLICE`] x [`SLICE`] nodes over its x, y box, row 0 at the largest y);
//! - `.png` (and `-reference.png`): 8-bit previews;
//! - `.json`: index, seeds, the medium, the camera's intrinsics and extrinsics, the
//!   background, the files and the scene TOML; written last, so a sample is complete
//!   exactly when its JSON exists. A run skips complete samples (a retried or resumed job
//!   redoes only what is missing); `manifest.jsonl` holds every sample's JSON, a line each,
//!   in index order.
//!
//! Over 600 lines: one concept, a sample of any kind: the kinds share the medium, camera,
//! background and files.

use std::path::{Path, PathBuf};

use anyhow::Context;
use glam::DVec3;
use grin_field::bake::SplitMix64;
use grin_render::image::{stage_channels_exr, stage_rgb8_png};
use serde_json::json;

use crate::{Image, Preview, Quiet, Renderer};

/// Samples per pixel of the haze images.
pub const HAZE_SPP: u32 = 4;

/// Nodes per side of the index slice.
pub const SLICE: usize = 64;

/// The box the generated media fill (metres), and air at 20 C around them.
const BOX_MIN: [f64; 3] = [-0.6, -0.6, -0.6];
const BOX_MAX: [f64; 3] = [0.6, 0.9, 0.6];
const AMBIENT: f64 = 1.000272;

/// What a sample shows.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, strum::IntoStaticStr, strum::VariantNames,
)]
#[strum(serialize_all = "kebab-case")]
pub enum Kind {
    /// Background-oriented schlieren: a random-dot plate without and with the medium.
    Bos,
    /// A knife-edge schlieren image.
    Schlieren,
    /// Heat-haze distortion: a background (a checker wall or a plate image) without and
    /// with the medium.
    Haze,
}

impl Kind {
    pub fn name(self) -> &'static str {
        self.into()
    }
}

/// Where the media come from.
#[derive(Debug, Clone)]
pub enum Media {
    /// One to four Gaussian hot-air plumes.
    Plumes,
    /// fBm or turbulence noise in a box.
    Noise,
    /// An expression: a hot layer with waves along it.
    Expr,
    /// The `[medium]` of a scene file at a random frame of its `[animation]` (a VDB or
    /// baked sequence: the pool of frames), as the scene places it.
    Scene {
        path: PathBuf,
        scene: Box<grin_scene::Scene>,
    },
}

impl Media {
    /// `plumes`, `noise`, `expr` or `scene:PATH`.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "plumes" => Ok(Media::Plumes),
            "noise" => Ok(Media::Noise),
            "expr" => Ok(Media::Expr),
            _ => match s.strip_prefix("scene:") {
                Some(path) => {
                    let path = PathBuf::from(path);
                    let scene = grin_scene::load_scene(&path).map_err(|e| e.to_string())?;
                    if scene.medium.is_none() {
                        return Err(format!("{}: the scene has no [medium]", path.display()));
                    }
                    Ok(Media::Scene {
                        path,
                        scene: Box::new(scene),
                    })
                }
                None => Err(format!(
                    "unknown media `{s}` (plumes, noise, expr or scene:PATH)"
                )),
            },
        }
    }

    pub fn name(&self) -> String {
        match self {
            Media::Plumes => "plumes".into(),
            Media::Noise => "noise".into(),
            Media::Expr => "expr".into(),
            Media::Scene { path, .. } => format!("scene:{}", path.display()),
        }
    }
}

/// A dataset: its kind, media, backgrounds, seed and image size.
#[derive(Debug, Clone)]
pub struct Dataset {
    pub kind: Kind,
    pub media: Media,
    /// Plate images for `haze` backgrounds, seen at infinity (one drawn per sample).
    pub plates: Vec<PathBuf>,
    /// Texture images for `haze` backgrounds, on the wall behind the medium (one drawn
    /// per sample, with the plates). No plates and no textures: a checker wall.
    pub textures: Vec<PathBuf>,
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
    /// Seeds, medium, camera (intrinsics, extrinsics), background.
    pub meta: serde_json::Value,
    /// The slice plane's z and its x, y box.
    slice: (f64, [f64; 2], [f64; 2]),
}

/// A rendered sample: its channels and previews, the index slice ([`SLICE`]², row 0 at
/// the largest y) and its JSON.
#[derive(Debug, Clone)]
pub struct RenderedSample {
    pub image: Image,
    pub slice: Vec<f32>,
    pub meta: serde_json::Value,
}

/// What a [`Dataset::write`] run did.
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

/// A TOML array of three numbers.
fn v3(v: [f64; 3]) -> String {
    format!("[{:?}, {:?}, {:?}]", v[0], v[1], v[2])
}

impl Dataset {
    /// A `kind` dataset of `media` at `width` x `height`.
    pub fn new(kind: Kind, media: Media, seed: u64, width: u32, height: u32) -> Self {
        Self {
            kind,
            media,
            plates: Vec::new(),
            textures: Vec::new(),
            seed,
            width,
            height,
        }
    }

    /// The medium of a sample: its `[medium]` section (TOML), its box and its description.
    fn medium(
        &self,
        u: &mut dyn FnMut(f64, f64) -> f64,
    ) -> anyhow::Result<(String, [f64; 3], [f64; 3], serde_json::Value)> {
        let bounds = format!(
            "[medium]\nbounds = {{ box = {{ min = {}, max = {} }} }}\nambient_index = {AMBIENT:?}\n",
            v3(BOX_MIN),
            v3(BOX_MAX)
        );
        Ok(match &self.media {
            Media::Plumes => {
                let count = 1 + (u(0.0, 4.0) as usize).min(3);
                let plumes: Vec<[f64; 5]> = (0..count)
                    .map(|_| {
                        // Inside the box by 2.5 widths or more: n meets ambient at its
                        // faces (a jump there would refract every ray crossing it).
                        [
                            u(2.0e-4, 1.2e-3),
                            u(-0.2, 0.2),
                            u(-0.2, 0.5),
                            u(-0.2, 0.2),
                            u(0.05, 0.15),
                        ]
                    })
                    .collect();
                let lines: Vec<String> = plumes
                    .iter()
                    .map(|p| {
                        format!(
                            "    {{ a = {:?}, center = {}, s = {:?} }},",
                            p[0],
                            v3([p[1], p[2], p[3]]),
                            p[4]
                        )
                    })
                    .collect();
                let toml = format!(
                    "{bounds}field = {{ kind = \"plume\", plumes = [\n{}\n] }}\n",
                    lines.join("\n")
                );
                let meta = json!({
                    "kind": "plume",
                    "plumes": plumes.iter().map(|p| json!({
                        "a": p[0], "center": [p[1], p[2], p[3]], "s": p[4],
                    })).collect::<Vec<_>>(),
                });
                (toml, BOX_MIN, BOX_MAX, meta)
            }
            Media::Noise => {
                let noise = if u(0.0, 1.0) < 0.5 {
                    "fbm"
                } else {
                    "turbulence"
                };
                let octaves = 2 + (u(0.0, 4.0) as u32).min(3);
                let frequency = u(1.5, 5.0);
                let amplitude = -u(1.0e-4, 6.0e-4);
                let seed = (u(0.0, 1.0) * 4_294_967_295.0) as u32;
                let toml = format!(
                    "{bounds}field = {{ kind = \"noise\", noise = \"{noise}\", octaves = {octaves}, \
                     frequency = {frequency:?}, amplitude = {amplitude:?}, seed = {seed} }}\n"
                );
                let meta = json!({
                    "kind": "noise", "noise": noise, "octaves": octaves,
                    "frequency": frequency, "amplitude": amplitude, "seed": seed,
                });
                (toml, BOX_MIN, BOX_MAX, meta)
            }
            Media::Expr => {
                // The layer fades out well inside the box (a super-Gaussian in x and z).
                let (a, y0, w) = (u(2.0e-4, 1.0e-3), u(-0.1, 0.4), u(0.06, 0.15));
                let (b, kx, kz) = (u(0.0, 0.5), u(3.0, 12.0), u(2.0, 8.0));
                let tau = std::f64::consts::TAU;
                let (px, pz) = (u(0.0, tau), u(0.0, tau));
                let formula = format!(
                    "{AMBIENT:?} - {a:?} * exp(-(((y - ({y0:?})) / {w:?})^2)) * \
                     exp(-((x / 0.45)^8) - ((z / 0.45)^8)) * \
                     (1 + {b:?} * sin({kx:?} * x + {px:?}) * cos({kz:?} * z + {pz:?}))"
                );
                let toml = format!("{bounds}field = {{ kind = \"expr\", n = \"{formula}\" }}\n");
                let meta = json!({"kind": "expr", "n": formula});
                (toml, BOX_MIN, BOX_MAX, meta)
            }
            Media::Scene { path, scene } => {
                let frames = scene.animation.map_or([0, 0], |a| a.frames);
                let span = (frames[1] - frames[0]) as f64 + 1.0;
                let frame = frames[0] + (u(0.0, span) as i64).min(frames[1] - frames[0]);
                let at = scene.at_frame(frame, scene.fps());
                let mut medium = at.medium.context("the pool scene has a [medium]")?;
                // Paths become absolute: the sample's scene is read from the dataset folder.
                let dir = std::path::absolute(path.parent().unwrap_or(Path::new(".")))
                    .context("the pool scene's folder")?;
                let dir = dir.as_path();
                match &mut medium.field {
                    grin_scene::FieldSpec::Vdb(v) => {
                        v.path = grin_field::vdb::resolve(dir, &v.path)
                            .to_string_lossy()
                            .into_owned();
                    }
                    grin_scene::FieldSpec::Baked { path, .. } => {
                        *path = grin_field::vdb::resolve(dir, path)
                            .to_string_lossy()
                            .into_owned();
                    }
                    _ => {}
                }
                let (lo, hi) = grin_field::Bounds::from_spec(&medium.bounds).aabb();
                #[derive(serde::Serialize)]
                struct Section<'a> {
                    medium: &'a grin_scene::MediumSpec,
                }
                let toml = toml::to_string(&Section { medium: &medium })
                    .context("the pool scene's [medium]")?;
                let meta = json!({
                    "kind": "scene", "scene": path.display().to_string(), "frame": frame,
                });
                (toml, lo.to_array(), hi.to_array(), meta)
            }
        })
    }

    /// Sample `index`'s scene.
    pub fn sample(&self, index: u64) -> anyhow::Result<Sample> {
        let seed = grin_scene::frames::frame_seed(self.seed, index as i64);
        let mut rng = SplitMix64(seed);
        let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.next_f64();
        let (medium, lo, hi, medium_meta) = self.medium(&mut u)?;
        let (lo, hi) = (DVec3::from_array(lo), DVec3::from_array(hi));
        let centre = (lo + hi) * 0.5;
        let radius = ((hi - lo) * 0.5).length();
        // A camera on the -z side, looking along +z at the medium, which fills ~70 % of
        // the image's height.
        let focal_mm = u(40.0, 60.0);
        let sensor_mm = 10.5;
        let tan_half = 0.5 * sensor_mm / focal_mm;
        let distance = radius / (0.7 * tan_half) * u(0.9, 1.2);
        let position =
            centre + DVec3::new(u(-0.05, 0.05) * radius, u(-0.05, 0.05) * radius, -distance);
        let look_at = centre;
        // The background wall or plate stands behind the medium.
        let behind = distance * u(0.5, 1.2);
        let wall_z = centre.z + behind;
        let pixel_on_wall = (distance + behind) * 2.0 * tan_half / f64::from(self.height);
        let sensor_seed = (u(0.0, 1.0) * 4_294_967_295.0) as u64;
        let mut sections = vec![format!(
            "# grin dataset {kind}: seed {base}, sample {index}\n\
             [camera]\nposition = {}\nlook_at = {}\n\
             focal_length_mm = {focal_mm:?}\nsensor_height_mm = {sensor_mm:?}\n",
            v3(position.to_array()),
            v3(look_at.to_array()),
            kind = self.kind.name(),
            base = self.seed,
        )];
        sections.push(medium);
        sections.push(format!(
            "[render]\nwidth = {}\nheight = {}\n",
            self.width, self.height
        ));
        let wall = format!(
            "plane = {{ point = {}, normal = [0.0, 0.0, -1.0] }}",
            v3([centre.x, centre.y, wall_z])
        );
        let background = match self.kind {
            Kind::Bos => {
                let dot = pixel_on_wall * u(2.5, 4.0);
                let density = u(0.3, 0.5);
                let dots_seed = (u(0.0, 1.0) * 4_294_967_295.0) as u64;
                sections.push(format!(
                    "[sensor]\nfull_well = 20000.0\nread_noise = 2.0\nbits = 12\nseed = {sensor_seed}\n"
                ));
                sections.push(format!(
                    "[optics]\nmode = \"bos\"\n{wall}\n\
                     dots = {{ diameter = {dot:?}, density = {density:?}, seed = {dots_seed} }}\n"
                ));
                json!({"kind": "dots", "wall_z": wall_z, "dot_diameter": dot,
                       "dot_density": density, "dots_seed": dots_seed})
            }
            Kind::Schlieren => {
                let angle = if u(0.0, 1.0) < 0.5 { 0.0 } else { 90.0 };
                let source = u(2.0e-4, 1.0e-3);
                sections.push(format!(
                    "[optics]\nmode = \"schlieren\"\n\
                     knife = {{ angle_deg = {angle:?}, cutoff = 0.5, source_size_rad = {source:?} }}\n"
                ));
                json!({"kind": "none", "knife_angle_deg": angle, "cutoff": 0.5,
                       "source_size_rad": source})
            }
            Kind::Haze => {
                let images = self.plates.len() + self.textures.len();
                if images == 0 {
                    let scale = pixel_on_wall * u(6.0, 16.0);
                    let (a, b) = (u(0.6, 0.95), u(0.05, 0.35));
                    sections.push(format!(
                        "[[object]]\nshape = {{ {wall} }}\n\
                         material = {{ checker = {{ color_a = {}, color_b = {}, scale = {scale:?} }} }}\n\n\
                         [[light]]\ndirectional = {{ direction = [0.0, 0.0, 1.0], intensity = [1.0, 1.0, 1.0] }}\n",
                        v3([a; 3]),
                        v3([b; 3]),
                    ));
                    sections.push(format!("[optics]\nmode = \"displacement\"\n{wall}\n"));
                    json!({"kind": "checker", "wall_z": wall_z, "scale": scale,
                           "light": a, "dark": b})
                } else {
                    let pick = (u(0.0, images as f64) as usize).min(images - 1);
                    let (image, is_plate) = match self.plates.get(pick) {
                        Some(p) => (p, true),
                        None => (&self.textures[pick - self.plates.len()], false),
                    };
                    let image = std::path::absolute(image).unwrap_or_else(|_| image.clone());
                    let shown = image.to_string_lossy().into_owned();
                    if is_plate {
                        sections.push(format!("[sky]\nplate = {{ path = {shown:?} }}\n"));
                        sections.push("[optics]\nmode = \"displacement\"\n".to_owned());
                        json!({"kind": "plate", "path": shown})
                    } else {
                        // The image fills the view on the wall, with a margin for the
                        // camera's offset.
                        let h = (distance + behind) * 2.0 * tan_half * 1.2;
                        let w = h * f64::from(self.width) / f64::from(self.height);
                        sections.push(format!(
                            "[[object]]\nshape = {{ {wall} }}\n\
                             material = {{ texture = {{ path = {shown:?}, size = [{w:?}, {h:?}], \
                             center = {}, emissive = true }} }}\n",
                            v3([centre.x, centre.y, wall_z]),
                        ));
                        sections.push(format!("[optics]\nmode = \"displacement\"\n{wall}\n"));
                        json!({"kind": "texture", "path": shown, "wall_z": wall_z,
                               "size": [w, h]})
                    }
                }
            }
        };
        let toml = sections.join("\n");
        let scene = grin_scene::parse_scene(&toml, Path::new("<dataset sample>"))
            .with_context(|| format!("dataset sample {index}:\n{toml}"))?;
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
            "kind": self.kind.name(),
            "dataset_seed": self.seed,
            "sample_seed": seed,
            "medium": medium_meta,
            "camera": {
                "width": self.width,
                "height": self.height,
                "intrinsics": {
                    "fx": fy, "fy": fy,
                    "cx": 0.5 * f64::from(self.width), "cy": 0.5 * f64::from(self.height),
                    "focal_length_mm": focal_mm, "sensor_height_mm": sensor_mm,
                },
                "extrinsics": {
                    "position": position.to_array(),
                    "look_at": look_at.to_array(),
                    "camera_from_world_rotation": rotation,
                },
            },
            "background": background,
            "sensor_seed": sensor_seed,
        });
        Ok(Sample {
            index,
            toml,
            scene,
            meta,
            slice: (centre.z, [lo.x, hi.x], [lo.y, hi.y]),
        })
    }

    /// The files of sample `index` in `dir`: (EXR, slice EXR, PNG, reference PNG, JSON).
    pub fn files(&self, dir: &Path, index: u64) -> [PathBuf; 5] {
        let stem = format!("{}_{index:06}", self.kind.name());
        [
            dir.join(format!("{stem}.exr")),
            dir.join(format!("{stem}-slice.exr")),
            dir.join(format!("{stem}.png")),
            dir.join(format!("{stem}-reference.png")),
            dir.join(format!("{stem}.json")),
        ]
    }

    /// Render sample `index` (relative paths from `dir`): the kind's channels with the
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
            .context("an optics render keeps its frame")?;
        let angles = grin_render::optics::deflection_angles(frame, &rendered.camera);
        if self.kind == Kind::Haze {
            // The background without and with the medium: two beauty renders.
            // Anti-aliased (4 samples a pixel), so sub-pixel warps show.
            let mut beauty = sample.scene.clone();
            beauty.optics = None;
            beauty.render.spp = HAZE_SPP;
            let mut bare = beauty.clone();
            bare.medium = None;
            let mut previews = Vec::new();
            for (name, scene, suffix) in [
                ("distorted", beauty, None),
                ("reference", bare, Some("reference")),
            ] {
                let r = renderer.render_beauty(scene, dir, &label, &Quiet)?;
                for c in ["R", "G", "B"] {
                    let data = r.image.channel(c).context("a beauty render has RGB")?;
                    image.push(&format!("{name}.{c}"), data.to_vec());
                }
                let mut preview = r.image.previews.into_iter().next().context("a preview")?;
                preview.suffix = suffix;
                previews.push(preview);
            }
            image.previews = previews;
        }
        if self.kind != Kind::Schlieren {
            image.push(
                "deflection_rad.X",
                angles.iter().map(|a| a[0] as f32).collect(),
            );
            image.push(
                "deflection_rad.Y",
                angles.iter().map(|a| a[1] as f32).collect(),
            );
        }
        // The field the render read, not read again (a VDB pool's file).
        let field = rendered
            .field
            .clone()
            .context("a dataset sample has a medium")?;
        let (gx, gy) = line_gradient(field.as_ref(), &rendered.camera);
        image.push("grad_n_line.X", gx);
        image.push("grad_n_line.Y", gy);
        let slice = index_slice(field.as_ref(), &sample);
        let (z, x, y) = sample.slice;
        let mut meta = sample.meta;
        meta["slice"] = json!({
            "plane_z": z, "nodes": SLICE, "x": x, "y": y, "row_0": "largest y",
        });
        let optics = rendered.report.optics.unwrap_or_default();
        meta["output"] = json!({
            "channels": image.names(),
            "max_displacement_px": optics.get("max_displacement_px"),
            "max_deflection_rad": optics.get("max_deflection_rad"),
        });
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
        let [exr, slice_exr, png, reference_png, json_path] = self.files(dir, index);
        let size = (image.width as usize, image.height as usize);
        let mut staged = vec![stage_channels_exr(&exr, size, image.channels)?];
        staged.push(stage_channels_exr(
            &slice_exr,
            (SLICE, SLICE),
            vec![("n", slice)],
        )?);
        let mut pngs = serde_json::Map::new();
        for Preview { suffix, rgb8 } in &image.previews {
            let (key, path) = match suffix {
                None => ("png", &png),
                Some(_) => ("reference_png", &reference_png),
            };
            staged.push(stage_rgb8_png(path, image.width, image.height, rgb8)?);
            pngs.insert(key.into(), json!(file_name(path)));
        }
        grin_output::commit(staged)?;
        meta["files"] = json!({"exr": file_name(&exr), "slice_exr": file_name(&slice_exr)});
        for (k, v) in pngs {
            meta["files"][k] = v;
        }
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
            if self.files(dir, i)[4].exists() {
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
            let path = self.files(dir, i)[4].clone();
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

fn file_name(p: &Path) -> Option<String> {
    p.file_name().map(|n| n.to_string_lossy().into_owned())
}

/// Samples along each pixel's straight ray in [`line_gradient`].
const LINE_SAMPLES: usize = 256;

/// Each pixel's projected index gradient: the integrals of grad n along the camera's right
/// and up (as `deflection_rad`) along the undeflected ray through the pixel's centre,
/// across the medium's bounds (trapezoid rule, [`LINE_SAMPLES`] points): the quantity
/// BOS and schlieren reconstructions assume (deflection ~ this / n for small angles).
fn line_gradient(
    field: &dyn grin_field::IndexField,
    cam: &grin_render::camera::PinholeCamera,
) -> (Vec<f32>, Vec<f32>) {
    use rayon::prelude::*;
    let bounds = field.bounds();
    let (w, h) = (cam.width, cam.height);
    let rows: Vec<Vec<(f32, f32)>> = (0..h)
        .into_par_iter()
        .map(|py| {
            (0..w)
                .map(|px| {
                    let (o, d) = cam.camera_ray(px, py, 0.5, 0.5);
                    let (mut x, mut y) = (0.0, 0.0);
                    if let Some((t0, t1)) = bounds.intersect(o, d) {
                        let t0 = t0.max(0.0);
                        let dt = (t1 - t0) / (LINE_SAMPLES - 1) as f64;
                        for i in 0..LINE_SAMPLES {
                            let g = field.sample(o + d * (t0 + dt * i as f64)).grad_n;
                            let weight = if i == 0 || i == LINE_SAMPLES - 1 {
                                0.5
                            } else {
                                1.0
                            };
                            x += weight * dt * g.dot(cam.right);
                            y += weight * dt * g.dot(cam.up);
                        }
                    }
                    (x as f32, y as f32)
                })
                .collect()
        })
        .collect();
    rows.into_iter().flatten().unzip()
}

/// The medium's index on the plane z = the medium's centre: [`SLICE`]² nodes over its x, y
/// box, row 0 at the largest y.
fn index_slice(field: &dyn grin_field::IndexField, sample: &Sample) -> Vec<f32> {
    let (z, [x0, x1], [y0, y1]) = sample.slice;
    let step = |lo: f64, hi: f64, i: usize| lo + (hi - lo) * i as f64 / (SLICE - 1) as f64;
    let mut out = Vec::with_capacity(SLICE * SLICE);
    for row in 0..SLICE {
        let y = step(y1, y0, row);
        for col in 0..SLICE {
            out.push(field.n(DVec3::new(step(x0, x1, col), y, z)) as f32);
        }
    }
    out
}
