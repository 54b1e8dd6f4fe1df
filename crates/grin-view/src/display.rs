//! What the viewer shows of a frame: the beauty pass or one AOV as 8-bit RGBA, with the
//! scale the colours stand for (for the panel's legend).

use grin_render::image::{Frame, PixelOut, linear_to_srgb8};

/// The image the viewer shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
#[derive(strum::IntoStaticStr)]
#[strum(serialize_all = "kebab-case")]
pub enum Aov {
    /// The rendered image (sRGB of the linear radiance, clamped to [0, 1]).
    #[default]
    Beauty,
    /// Deflection angle of the camera ray in the medium (degrees), black to white.
    Deflection,
    /// Integration steps per sample, a heat map.
    Steps,
    /// Optical path difference against the straight ray: blue negative, red positive.
    Opd,
    /// Ray status: grey missed, green exited, blue absorbed, orange max_steps, red error,
    /// yellow degraded.
    Status,
}

impl Aov {
    pub const ALL: [Aov; 5] = [
        Aov::Beauty,
        Aov::Deflection,
        Aov::Steps,
        Aov::Opd,
        Aov::Status,
    ];

    pub fn name(self) -> &'static str {
        self.into()
    }
}

/// Status colours, indexed by `PixelOut::status`.
pub const STATUS_COLOURS: [[u8; 3]; 6] = [
    [90, 90, 90],
    [40, 170, 70],
    [50, 90, 200],
    [240, 150, 20],
    [220, 30, 30],
    [230, 220, 40],
];

/// An 8-bit RGBA picture of a frame's `aov`, and the value the full colour scale
/// stands for (the largest magnitude in the frame; 1 for beauty and status).
pub fn rgba(frame: &Frame, aov: Aov) -> (Vec<u8>, f32) {
    let value = |p: &PixelOut| match aov {
        Aov::Deflection => p.deflection_deg,
        Aov::Steps => p.steps,
        Aov::Opd => p.opd,
        Aov::Beauty | Aov::Status => 0.0,
    };
    let scale = match aov {
        Aov::Beauty | Aov::Status => 1.0,
        _ => frame
            .pixels
            .iter()
            .map(|p| value(p).abs())
            .filter(|v| v.is_finite())
            .fold(0.0f32, f32::max),
    };
    let inv = if scale > 0.0 { 1.0 / scale } else { 0.0 };
    let mut out = Vec::with_capacity(frame.pixels.len() * 4);
    for p in &frame.pixels {
        let rgb = match aov {
            Aov::Beauty => p.rgb.map(linear_to_srgb8),
            Aov::Status => STATUS_COLOURS
                .get(p.status as usize)
                .copied()
                .unwrap_or([255, 0, 255]),
            Aov::Deflection => {
                let g = linear_to_srgb8(value(p) * inv);
                [g, g, g]
            }
            Aov::Steps => heat(value(p) * inv),
            Aov::Opd => diverging(value(p) * inv),
        };
        out.extend_from_slice(&[rgb[0], rgb[1], rgb[2], 255]);
    }
    (out, scale)
}

/// Black -> red -> yellow -> white for t in [0, 1].
fn heat(t: f32) -> [u8; 3] {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let c = |x: f32| (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    [c(3.0 * t), c(3.0 * t - 1.0), c(3.0 * t - 2.0)]
}

/// Blue (-1) -> white (0) -> red (+1).
fn diverging(t: f32) -> [u8; 3] {
    let t = if t.is_finite() {
        t.clamp(-1.0, 1.0)
    } else {
        0.0
    };
    let c = |x: f32| (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    if t >= 0.0 {
        [255, c(1.0 - t), c(1.0 - t)]
    } else {
        [c(1.0 + t), c(1.0 + t), 255]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame() -> Frame {
        let px = |defl: f32, opd: f32, status: f32| PixelOut {
            rgb: [0.5, 0.25, 1.5],
            deflection_deg: defl,
            opd,
            steps: defl * 10.0,
            status,
            ..PixelOut::default()
        };
        Frame {
            width: 3,
            height: 1,
            pixels: vec![px(0.0, -2.0, 0.0), px(1.0, 0.0, 1.0), px(4.0, 1.0, 4.0)],
        }
    }

    #[test]
    fn each_aov_maps_its_own_channel() {
        let f = frame();
        let (b, s) = rgba(&f, Aov::Beauty);
        assert_eq!(s, 1.0);
        assert_eq!(&b[0..4], &[188, 137, 255, 255]);
        let (d, s) = rgba(&f, Aov::Deflection);
        assert_eq!(s, 4.0);
        assert_eq!((d[0], d[8]), (0, 255));
        let (o, s) = rgba(&f, Aov::Opd);
        assert_eq!(s, 2.0);
        assert_eq!(&o[0..3], &[0, 0, 255]); // -2 of 2: full blue
        assert_eq!(&o[4..7], &[255, 255, 255]); // 0: white
        let (st, _) = rgba(&f, Aov::Status);
        assert_eq!(&st[8..11], &STATUS_COLOURS[4]);
        let (h, s) = rgba(&f, Aov::Steps);
        assert_eq!(s, 40.0);
        assert_eq!(&h[8..11], &[255, 255, 255]);
    }
}
