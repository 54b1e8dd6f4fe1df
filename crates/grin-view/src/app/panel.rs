//! The window's panel (numbers, controls, warnings) and the image area beside it, and
//! how the mouse and keys over the image move the orbit camera.

use std::time::Instant;

use grin_scene::{IntegratorKind, Interpolation};

use super::{App, PANEL_WIDTH};
use crate::display::Aov;
use crate::settings::StepKind;

impl App {
    /// The panel and the image; returns the image area in pixels.
    pub(super) fn ui(&mut self, ui: &mut egui::Ui) -> (u32, u32) {
        egui::Panel::left("grin panel")
            .resizable(false)
            .exact_size(PANEL_WIDTH)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().show(ui, |ui| self.panel(ui));
            });
        let mut avail = (0, 0);
        egui::CentralPanel::no_frame().show(ui, |ui| {
            let ppp = ui.ctx().pixels_per_point();
            let size = ui.available_size();
            avail = (
                (size.x * ppp).floor().max(1.0) as u32,
                (size.y * ppp).floor().max(1.0) as u32,
            );
            let shown = if self.headless() || self.opts.size.is_some() {
                egui::vec2(self.image_px.0 as f32, self.image_px.1 as f32) / ppp
            } else {
                size
            };
            let (rect, resp) = ui.allocate_exact_size(shown, egui::Sense::click_and_drag());
            if let Some((id, _)) = self.texture {
                egui::Image::new((id, shown)).paint_at(ui, rect);
            } else {
                ui.put(
                    rect,
                    egui::Label::new("baking the field and building the pipelines…"),
                );
            }
            self.camera_input(ui, &resp, shown.y * ppp);
        });
        avail
    }

    fn camera_input(&mut self, ui: &egui::Ui, resp: &egui::Response, height_px: f32) {
        let before = self.settings.camera.clone();
        let ppp = ui.ctx().pixels_per_point() as f64;
        if resp.dragged_by(egui::PointerButton::Primary) {
            let d = resp.drag_delta();
            self.settings
                .camera
                .orbit(f64::from(d.x) * ppp, f64::from(d.y) * ppp);
        }
        if resp.dragged_by(egui::PointerButton::Secondary)
            || resp.dragged_by(egui::PointerButton::Middle)
        {
            let d = resp.drag_delta();
            self.settings.camera.pan(
                f64::from(d.x) * ppp,
                f64::from(d.y) * ppp,
                f64::from(height_px),
            );
        }
        if resp.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            if scroll != 0.0 {
                self.settings.camera.zoom(f64::from(scroll) / 50.0);
            }
        }
        if !ui.ctx().egui_wants_keyboard_input() {
            let (dt, keys) = ui.input(|i| {
                let k = |key| if i.key_down(key) { 1.0 } else { 0.0 };
                (
                    f64::from(i.stable_dt.min(0.1)),
                    [
                        k(egui::Key::W) - k(egui::Key::S),
                        k(egui::Key::D) - k(egui::Key::A),
                        k(egui::Key::E) - k(egui::Key::Q),
                        if i.key_pressed(egui::Key::R) {
                            1.0
                        } else {
                            0.0
                        },
                        if i.key_pressed(egui::Key::Space) {
                            1.0
                        } else {
                            0.0
                        },
                    ],
                )
            });
            if keys[..3].iter().any(|&k| k != 0.0) {
                self.settings
                    .camera
                    .fly(keys[0] * dt, keys[1] * dt, keys[2] * dt);
            }
            if keys[3] != 0.0 {
                self.settings.camera = self.file_settings.camera.clone();
            }
            if keys[4] != 0.0 && self.animated {
                self.settings.playing = !self.settings.playing;
            }
        }
        if self.settings.camera != before {
            self.last_move = Some(Instant::now());
        }
    }

    fn panel(&mut self, ui: &mut egui::Ui) {
        ui.heading("grin view");
        ui.label(
            self.opts
                .scene
                .file_name()
                .map_or_else(String::new, |n| n.to_string_lossy().into_owned()),
        );
        ui.separator();
        // Numbers.
        let n = self.stats.shown.len();
        let recent: Vec<f64> = self
            .stats
            .shown
            .iter()
            .rev()
            .take(10)
            .collect::<Vec<_>>()
            .windows(2)
            .map(|w| (*w[0] - *w[1]).as_secs_f64())
            .collect();
        let fps = if recent.is_empty() {
            0.0
        } else {
            recent.len() as f64 / recent.iter().sum::<f64>().max(1e-9)
        };
        ui.label(format!("frames shown: {n}, {fps:.1} fps"));
        if let Some(f) = &self.frame {
            let r = &f.rendered;
            let device = r.device_seconds.map_or(String::new(), |d| {
                format!(" ({:.1} on the device)", d * 1e3)
            });
            ui.label(format!(
                "frame {:.1} ms{device}, {:.2} Mrays/s, {:.0} kB read back",
                r.gpu_seconds * 1e3,
                r.rays_per_second * 1e-6,
                r.read_back_bytes as f64 * 1e-3
            ));
            ui.label(format!(
                "{:.1} steps, {:.1} field evals per ray",
                r.steps_per_ray, r.evals_per_ray
            ));
            let chosen = if matches!(f.settings.step, grin_scene::StepSpec::Auto(_)) {
                " (chosen by pilot rays)"
            } else {
                ""
            };
            ui.label(format!("method: {}{chosen}", r.method));
            ui.label(format!(
                "{}x{} ({:.0}%), {} / {} spp{}",
                r.width,
                r.height,
                f.scale * 100.0,
                r.samples,
                f.settings.max_spp,
                if r.converged { ", converged" } else { "" }
            ));
            if let Some((d, bytes)) = f.field_grid {
                ui.label(format!(
                    "field grid {}x{}x{}, {:.1} MB{}",
                    d[0],
                    d[1],
                    d[2],
                    bytes as f64 * 1e-6,
                    match f.cache {
                        Some(grin_gpu::cache::CacheUse::Hit) => ", from the bake cache",
                        Some(grin_gpu::cache::CacheUse::Stored) => ", baked and cached",
                        _ => "",
                    }
                ));
            }
            for w in &f.warnings {
                ui.colored_label(egui::Color32::YELLOW, w);
            }
        }
        ui.label(format!(
            "render: {}",
            self.adapter.as_deref().unwrap_or("starting…")
        ));
        ui.label(format!("window: {}", self.display_adapter));
        if let Some(e) = &self.reload_error {
            ui.colored_label(egui::Color32::LIGHT_RED, format!("scene not reloaded: {e}"));
        }
        if let Some(e) = &self.frame_error {
            ui.colored_label(egui::Color32::LIGHT_RED, e);
        }
        ui.separator();
        self.controls(ui);
    }

    fn controls(&mut self, ui: &mut egui::Ui) {
        let s = &mut self.settings;
        let integrator_name = |k: Option<IntegratorKind>| k.map_or("auto", |k| k.name());
        egui::ComboBox::from_label("integrator")
            .selected_text(integrator_name(s.integrator))
            .show_ui(ui, |ui| {
                for k in std::iter::once(None).chain(IntegratorKind::ALL.map(Some)) {
                    ui.selectable_value(&mut s.integrator, k, integrator_name(k));
                }
            });
        let mut kind = StepKind::of(&s.step);
        let mut value = StepKind::value_of(&s.step);
        let scale = StepKind::value_of(&self.file_settings.step);
        egui::ComboBox::from_label("step policy")
            .selected_text(kind.name())
            .show_ui(ui, |ui| {
                for k in StepKind::ALL {
                    if ui.selectable_value(&mut kind, k, k.name()).changed() {
                        value = k.default_value(scale);
                    }
                }
            });
        ui.add(
            egui::Slider::new(&mut value, 1e-9..=1.0)
                .logarithmic(true)
                .text("step / tolerance"),
        );
        s.step = kind.with_value(value);
        let interp_name = |i: Option<Interpolation>| match i {
            None => "as baked",
            Some(Interpolation::Trilinear) => "trilinear",
            Some(Interpolation::Tricubic) => "tricubic",
        };
        egui::ComboBox::from_label("interpolation")
            .selected_text(interp_name(s.interpolation))
            .show_ui(ui, |ui| {
                for i in [
                    None,
                    Some(Interpolation::Trilinear),
                    Some(Interpolation::Tricubic),
                ] {
                    ui.selectable_value(&mut s.interpolation, i, interp_name(i));
                }
            });
        egui::ComboBox::from_label("shown")
            .selected_text(s.aov.name())
            .show_ui(ui, |ui| {
                for a in Aov::ALL {
                    ui.selectable_value(&mut s.aov, a, a.name());
                }
            });
        if s.aov != Aov::Beauty && s.aov != Aov::Status {
            ui.label(format!("full scale: {:.4e}", self.aov_scale));
        }
        ui.add(egui::Slider::new(&mut s.resolution_scale, 0.125..=1.0).text("resolution"));
        ui.add(egui::Slider::new(&mut s.target_fps, 2.0..=60.0).text("fps while moving"));
        ui.add(egui::Slider::new(&mut s.spp, 1..=64).text("spp per frame"));
        ui.add(
            egui::Slider::new(&mut s.max_spp, 1..=4096)
                .logarithmic(true)
                .text("spp to converge"),
        );
        ui.checkbox(&mut s.medium, "medium");
        if self.animated {
            ui.horizontal(|ui| {
                let label = if s.playing { "pause" } else { "play" };
                if ui.button(label).clicked() {
                    s.playing = !s.playing;
                }
                ui.add(egui::Slider::new(&mut s.speed, 0.0..=10.0).text("speed"));
            });
            match self.animation {
                Some(a) => {
                    let mut frame = s.sequence_frame(&a);
                    ui.add(egui::Slider::new(&mut frame, a.frames[0]..=a.frames[1]).text("frame"));
                    s.time = frame as f64 / a.fps;
                }
                None => {
                    ui.add(egui::Slider::new(&mut s.time, 0.0..=60.0).text("time (s)"));
                }
            }
        }
        if ui.button("reset camera (R)").clicked() {
            s.camera = self.file_settings.camera.clone();
        }
        ui.label("drag: orbit · right-drag: pan · scroll: zoom · WASD/QE: fly");
    }
}
