//! The panel kept in a texture of its own on a CPU adapter (lavapipe), so a frame
//! rasterizes only the image.
//!
//! On lavapipe the window's drawing runs on the cores the render thread marches on, and
//! rasterizing egui's panel (text, widgets) every frame took about half of them: with the
//! panel not drawn, the orbiting heat haze's moving image grew from ~2,400 to ~4,500
//! pixels at the same 20 fps. Here egui's shapes up to the image (the side panel) are
//! drawn into [`UiLayer`] only when they look different, at most every [`LAYER_PERIOD`]
//! while the camera moves (the panel's figures then change four times a second); each
//! frame copies the layer into the window (no shader) and draws the image and what egui
//! paints after it (popups, tooltips) on top.

use std::hash::{Hash, Hasher};
use std::time::{Duration, Instant};

use egui::epaint::{ClippedPrimitive, Primitive};

/// How often a panel that looks different is drawn again while the camera moves.
pub(super) const LAYER_PERIOD: Duration = Duration::from_millis(250);

/// The panel as last drawn.
pub(super) struct UiLayer {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    /// [`look`] of the shapes drawn; `None` before the first drawing (a new layer is
    /// blank: drawn at once, moving or not).
    look: Option<u64>,
    drawn: Instant,
}

impl UiLayer {
    /// A layer of the surface's size and format (copied into the surface's textures).
    pub(super) fn new(device: &wgpu::Device, config: &wgpu::SurfaceConfiguration) -> Self {
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("viewer panel layer"),
            size: wgpu::Extent3d {
                width: config.width,
                height: config.height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: config.format,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        Self {
            texture,
            view,
            look: None,
            drawn: Instant::now(),
        }
    }

    /// Whether the layer is of the surface's size.
    pub(super) fn fits(&self, config: &wgpu::SurfaceConfiguration) -> bool {
        let s = self.texture.size();
        (s.width, s.height) == (config.width, config.height)
    }

    /// Whether shapes of `look` should be drawn into the layer now: they look different,
    /// and the camera is still or the layer is [`LAYER_PERIOD`] old.
    pub(super) fn stale(&self, look: u64, moving: bool) -> bool {
        match self.look {
            None => true,
            Some(drawn) => look != drawn && (!moving || self.drawn.elapsed() >= LAYER_PERIOD),
        }
    }

    pub(super) fn view(&self) -> &wgpu::TextureView {
        &self.view
    }

    pub(super) fn texture(&self) -> &wgpu::Texture {
        &self.texture
    }

    /// Record that shapes of `look` were drawn.
    pub(super) fn drawn(&mut self, look: u64) {
        self.look = Some(look);
        self.drawn = Instant::now();
    }
}

/// `prims` split where `image` is first painted: the shapes under it (the panel, kept in
/// the layer) and the image with everything after it (drawn every frame).
pub(super) fn split_at_image(
    mut prims: Vec<ClippedPrimitive>,
    image: Option<egui::TextureId>,
) -> (Vec<ClippedPrimitive>, Vec<ClippedPrimitive>) {
    let at = prims
        .iter()
        .position(|p| matches!(&p.primitive, Primitive::Mesh(m) if Some(m.texture_id) == image))
        .unwrap_or(prims.len());
    let over = prims.split_off(at);
    (prims, over)
}

/// A hash of how `prims` look: their clip rectangles, textures, vertices and indices.
pub(super) fn look(prims: &[ClippedPrimitive]) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for p in prims {
        let r = p.clip_rect;
        for v in [r.min.x, r.min.y, r.max.x, r.max.y] {
            v.to_bits().hash(&mut h);
        }
        match &p.primitive {
            Primitive::Mesh(m) => {
                m.texture_id.hash(&mut h);
                m.indices.hash(&mut h);
                for v in &m.vertices {
                    for c in [v.pos.x, v.pos.y, v.uv.x, v.uv.y] {
                        c.to_bits().hash(&mut h);
                    }
                    v.color.to_array().hash(&mut h);
                }
            }
            // Painted by a callback: never the same twice.
            Primitive::Callback(_) => Instant::now().hash(&mut h),
        }
    }
    h.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use egui::epaint::{Color32, Mesh, Pos2, Rect};

    fn mesh(texture: u64, colour: Color32) -> ClippedPrimitive {
        let mut m = Mesh::with_texture(egui::TextureId::User(texture));
        let r = Rect::from_min_max(Pos2::ZERO, Pos2::new(10.0, 5.0));
        m.add_rect_with_uv(r, r, colour);
        ClippedPrimitive {
            clip_rect: Rect::EVERYTHING,
            primitive: Primitive::Mesh(m),
        }
    }

    #[test]
    fn the_shapes_under_the_image_are_the_layer_and_the_rest_is_drawn_each_frame() {
        let image = egui::TextureId::User(7);
        let prims = vec![
            mesh(1, Color32::RED),
            mesh(2, Color32::RED),
            mesh(7, Color32::WHITE),
            mesh(1, Color32::BLUE),
        ];
        let (under, over) = split_at_image(prims.clone(), Some(image));
        assert_eq!((under.len(), over.len()), (2, 2));
        assert!(matches!(&over[0].primitive, Primitive::Mesh(m) if m.texture_id == image));
        // No image yet: everything is the layer.
        let (under, over) = split_at_image(prims, None);
        assert_eq!((under.len(), over.len()), (4, 0));
    }

    #[test]
    fn the_layer_is_drawn_again_when_it_looks_different_at_most_every_period_while_moving() {
        let a = look(&[mesh(1, Color32::RED)]);
        assert_eq!(a, look(&[mesh(1, Color32::RED)]));
        let b = look(&[mesh(1, Color32::BLUE)]);
        assert_ne!(a, b, "a colour changes the look");
        assert_ne!(a, look(&[mesh(2, Color32::RED)]), "so does a texture");
        let Some(ctx) = grin_testkit::skip::require_gpu(
            "the_layer_is_drawn_again_when_it_looks_different_at_most_every_period_while_moving",
            grin_gpu::GpuContext::new_headless(),
        ) else {
            return;
        };
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format: wgpu::TextureFormat::Rgba8UnormSrgb,
            width: 32,
            height: 16,
            present_mode: wgpu::PresentMode::AutoNoVsync,
            desired_maximum_frame_latency: 2,
            alpha_mode: wgpu::CompositeAlphaMode::Auto,
            view_formats: vec![],
            color_space: wgpu::SurfaceColorSpace::Auto,
        };
        let mut layer = UiLayer::new(&ctx.device, &config);
        assert!(layer.fits(&config));
        assert!(
            layer.stale(a, true),
            "a new layer is drawn at once, moving or not"
        );
        layer.drawn(a);
        assert!(
            !layer.stale(a, false) && !layer.stale(a, true),
            "the same look"
        );
        assert!(layer.stale(b, false), "a still camera: at once");
        assert!(!layer.stale(b, true), "moving: not within the period");
        layer.drawn = Instant::now() - LAYER_PERIOD;
        assert!(layer.stale(b, true), "moving: after the period");
        let bigger = wgpu::SurfaceConfiguration {
            width: 64,
            ..config
        };
        assert!(!layer.fits(&bigger));
    }
}
