//! What a surface or the background shows besides a flat colour: images (PNG, EXR, HDR)
//! on planes and boxes, the random-dot pattern of BOS experiments, and the background
//! plate. Keep in sync with shaders/shared/surface.wgsl (same axes, same bilinear
//! lookup, same dot hash).

use std::path::Path;

use glam::DVec3;

use crate::primitives::Primitive;
use crate::rng::pcg_hash;

/// A decoded image: linear RGB, row 0 at the top.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub texels: Vec<[f32; 3]>,
}

/// Largest image side accepted (GPU 2D textures reach 8192-32768 texels a side).
pub const MAX_IMAGE_SIDE: usize = 16384;
/// Most texels an image may hold: 2^25 (8192x4096). Decoding holds the file's pixels, a
/// linear float copy and grin's texels at once, up to 32 bytes a texel: ~1 GiB here.
pub const MAX_IMAGE_TEXELS: usize = 1 << 25;
/// Most bytes the decoder may allocate for one image (its pixels and buffers).
const MAX_DECODE_BYTES: u64 = 1 << 30;

/// Refuse a declared size before anything of that size is allocated.
fn check_size(width: usize, height: usize) -> Result<(), String> {
    if width == 0 || height == 0 {
        return Err("the image is empty".into());
    }
    if width > MAX_IMAGE_SIDE || height > MAX_IMAGE_SIDE {
        return Err(format!(
            "{width}x{height} exceeds {MAX_IMAGE_SIDE} texels a side"
        ));
    }
    if width * height > MAX_IMAGE_TEXELS {
        return Err(format!(
            "{width}x{height} is {} texels, over the {MAX_IMAGE_TEXELS} ({} MiB decoded) \
             an image may hold",
            width * height,
            (MAX_IMAGE_TEXELS * 32) >> 20
        ));
    }
    Ok(())
}

/// The largest layer an EXR's headers declare (width, height), read without decoding any
/// pixel: every layer is checked, whichever the reader then takes.
pub fn exr_declared_size(path: &Path) -> Result<(usize, usize), String> {
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| e.to_string())?;
    meta.headers
        .iter()
        .map(|h| (h.layer_size.width(), h.layer_size.height()))
        .max_by_key(|&(w, h)| w.saturating_mul(h))
        .ok_or_else(|| "the EXR has no layer".to_string())
}

/// The size an image's header declares, read without decoding it.
fn declared_size(path: &Path, exr: bool) -> Result<(usize, usize), String> {
    if exr {
        return exr_declared_size(path);
    }
    let (w, h) = image::ImageReader::open(path)
        .map_err(|e| e.to_string())?
        .with_guessed_format()
        .map_err(|e| e.to_string())?
        .into_dimensions()
        .map_err(|e| e.to_string())?;
    Ok((w as usize, h as usize))
}

/// Read a `.png` (8 or 16 bit, sRGB: decoded to linear), `.exr` (first RGBA layer,
/// linear) or `.hdr` (Radiance, linear) image. Its header's size is checked against
/// [`MAX_IMAGE_SIDE`] and [`MAX_IMAGE_TEXELS`] before any pixel is decoded, and the decoder
/// allocates within a limit, so a small file declaring a huge image is refused, not
/// decoded. The error is the message alone: callers name the file and what it was for.
pub fn load_image(path: &Path) -> Result<Image, String> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let exr = match ext.as_deref() {
        Some("exr") => true,
        Some("hdr" | "png") => false,
        _ => return Err("must be a .png, .exr or .hdr file".into()),
    };
    let (w, h) = declared_size(path, exr)?;
    check_size(w, h)?;
    let decode = |srgb: bool| -> Result<(usize, usize, Vec<[f32; 3]>), String> {
        let mut reader = image::ImageReader::open(path)
            .map_err(|e| e.to_string())?
            .with_guessed_format()
            .map_err(|e| e.to_string())?;
        let mut limits = image::Limits::default();
        limits.max_image_width = Some(MAX_IMAGE_SIDE as u32);
        limits.max_image_height = Some(MAX_IMAGE_SIDE as u32);
        limits.max_alloc = Some(MAX_DECODE_BYTES);
        reader.limits(limits);
        let img = reader.decode().map_err(|e| e.to_string())?.into_rgb32f();
        let (w, h) = (img.width() as usize, img.height() as usize);
        let texels = img
            .pixels()
            .map(|p| if srgb { p.0.map(srgb_to_linear) } else { p.0 })
            .collect();
        Ok((w, h, texels))
    };
    let (width, height, texels) = if exr {
        let image = exr::prelude::read_first_rgba_layer_from_file(
            path,
            |res, _| (res.width(), vec![[0.0f32; 3]; res.width() * res.height()]),
            |(w, px): &mut (usize, Vec<[f32; 3]>), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
                px[pos.y() * *w + pos.x()] = [r, g, b];
            },
        )
        .map_err(|e| e.to_string())?;
        let size = image.layer_data.size;
        (
            size.width(),
            size.height(),
            image.layer_data.channel_data.pixels.1,
        )
    } else {
        decode(ext.as_deref() == Some("png"))?
    };
    // The pixels decoded are the header's: a decoder that disagreed is refused too.
    check_size(width, height)?;
    if let Some(bad) = texels
        .iter()
        .flatten()
        .find(|v| !v.is_finite() || **v < 0.0)
    {
        return Err(format!("it has a non-finite or negative texel ({bad})"));
    }
    Ok(Image {
        width,
        height,
        texels,
    })
}

/// The sRGB transfer function inverted: an encoded value in [0, 1] to linear.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

impl Image {
    /// Texel (x, y), clamped to the image, or wrapped with `repeat`.
    fn texel(&self, x: i64, y: i64, repeat: bool) -> DVec3 {
        let (w, h) = (self.width as i64, self.height as i64);
        let (x, y) = if repeat {
            (x.rem_euclid(w), y.rem_euclid(h))
        } else {
            (x.clamp(0, w - 1), y.clamp(0, h - 1))
        };
        DVec3::from(self.texels[(y * w + x) as usize].map(f64::from))
    }

    /// Bilinear value at image position (x, y) in texels (x right, y down; texel (i, j)'s
    /// centre at (i + 0.5, j + 0.5)); beyond the edge the edge texels, or the image
    /// again with `repeat`.
    pub fn bilinear(&self, x: f64, y: f64, repeat: bool) -> DVec3 {
        let (x, y) = (x - 0.5, y - 0.5);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (xa, ya) = (x0 as i64, y0 as i64);
        let top = self
            .texel(xa, ya, repeat)
            .lerp(self.texel(xa + 1, ya, repeat), fx);
        let bottom = self
            .texel(xa, ya + 1, repeat)
            .lerp(self.texel(xa + 1, ya + 1, repeat), fx);
        top.lerp(bottom, fy)
    }

    /// The value at texture coordinates (u, v) (u right, v up, the image in [0, 1]^2);
    /// `None` outside it unless `repeat`.
    pub fn at_uv(&self, uv: [f64; 2], repeat: bool) -> Option<DVec3> {
        let inside = uv.iter().all(|c| (0.0..=1.0).contains(c));
        if !repeat && !inside {
            return None;
        }
        Some(self.bilinear(
            uv[0] * self.width as f64,
            (1.0 - uv[1]) * self.height as f64,
            repeat,
        ))
    }

    /// The mean colour.
    pub fn mean(&self) -> DVec3 {
        let sum = self
            .texels
            .iter()
            .fold(DVec3::ZERO, |s, t| s + DVec3::from(t.map(f64::from)));
        sum / self.texels.len() as f64
    }
}

/// The axes (u, v) an image or pattern takes on a surface of unit normal `n`: u
/// horizontal (x on a floor or ceiling, else up x n), v = n x u, so that an image on a
/// wall facing the camera reads upright and unmirrored.
pub fn face_axes(n: DVec3) -> (DVec3, DVec3) {
    let a = n.abs();
    let u = if a.y >= a.x && a.y >= a.z {
        DVec3::X
    } else {
        DVec3::new(n.z, 0.0, -n.x).normalize()
    };
    (u, n.cross(u))
}

/// The surface frame of a hit on `prim` (point `p`, unit normal `n`): coordinates (u, v)
/// in world units from the frame's centre along [`face_axes`], and the face's size (u,
/// v) on a box (`None` on planes and spheres). The centre is `center` when given, else
/// the plane's point or the box face's centre.
pub fn surface_coords(
    prim: &Primitive,
    p: DVec3,
    n: DVec3,
    center: Option<DVec3>,
) -> ([f64; 2], Option<[f64; 2]>) {
    let (u, v) = face_axes(n);
    let (c, face) = match *prim {
        Primitive::Box { min, max } => {
            let c = (min + max) * 0.5;
            let ext = max - min;
            // Face centre: the box centre moved to the face along the normal.
            let c = c + n * (n.abs().dot(ext) * 0.5);
            let size = [u.abs().dot(ext), v.abs().dot(ext)];
            (center.unwrap_or(c), Some(size))
        }
        Primitive::Plane { point, .. } => (center.unwrap_or(point), None),
        Primitive::Sphere { center: sc, .. } => (center.unwrap_or(sc), None),
    };
    let r = p - c;
    ([r.dot(u), r.dot(v)], face)
}

/// Texture coordinates of a hit for an image of world size `size` on a plane, or over
/// the whole face of a box (`face` from [`surface_coords`]).
pub fn texture_uv(coords: [f64; 2], size: Option<[f64; 2]>, face: Option<[f64; 2]>) -> [f64; 2] {
    let s = face.or(size).unwrap_or([1.0, 1.0]);
    [coords[0] / s[0] + 0.5, coords[1] / s[1] + 0.5]
}

/// The random-dot pattern: one Gaussian dot (1/e^2 diameter `diameter`) per square cell
/// of side diameter * sqrt(pi / (4 density)), at a position in the cell drawn from
/// `seed`; intensity at plane coordinates `uv`, clamped to 1.
pub fn dot_intensity(diameter: f64, density: f64, seed: u32, uv: [f64; 2]) -> f64 {
    let cell = diameter * (std::f64::consts::PI / (4.0 * density)).sqrt();
    let (ci, cj) = ((uv[0] / cell).floor() as i32, (uv[1] / cell).floor() as i32);
    let mut sum = 0.0;
    for di in -1..=1 {
        for dj in -1..=1 {
            let (i, j) = (ci.wrapping_add(di), cj.wrapping_add(dj));
            let (ru, rv) = cell_random(seed, i, j);
            let centre = [(f64::from(i) + ru) * cell, (f64::from(j) + rv) * cell];
            let r2 = (uv[0] - centre[0]).powi(2) + (uv[1] - centre[1]).powi(2);
            sum += (-8.0 * r2 / (diameter * diameter)).exp();
        }
    }
    sum.min(1.0)
}

/// Two numbers in [0, 1) for cell (i, j) of `seed` (the renderer's PCG hash), 24 bits each (exact in f32).
fn cell_random(seed: u32, i: i32, j: i32) -> (f64, f64) {
    let h = pcg_hash(seed ^ pcg_hash(i as u32 ^ pcg_hash(j as u32)));
    let a = f64::from(h >> 8) / f64::from(1u32 << 24);
    let b = f64::from(pcg_hash(h) >> 8) / f64::from(1u32 << 24);
    (a, b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axes_read_upright_from_the_camera_side() {
        // A wall facing +z seen from +z: u along +x (the camera's right), v up.
        let (u, v) = face_axes(DVec3::Z);
        assert_eq!((u, v), (DVec3::X, DVec3::Y));
        // Facing -z (camera at -z looking +z, whose right is -x): u = -x, v up.
        let (u, v) = face_axes(-DVec3::Z);
        assert!((u + DVec3::X).length() < 1e-12 && (v - DVec3::Y).length() < 1e-12);
        // A floor seen from above with the camera looking -z: u = x, v = -z (away).
        let (u, v) = face_axes(DVec3::Y);
        assert_eq!((u, v), (DVec3::X, -DVec3::Z));
        // Always a right-handed orthonormal frame (u, v, n).
        for n in [DVec3::new(0.3, -0.2, 0.9).normalize(), -DVec3::X, -DVec3::Y] {
            let (u, v) = face_axes(n);
            assert!(u.dot(v).abs() < 1e-12 && u.dot(n).abs() < 1e-12);
            assert!((u.cross(v) - n).length() < 1e-12, "{n}");
        }
    }

    #[test]
    fn box_faces_span_the_image() {
        let b = Primitive::Box {
            min: DVec3::new(-1.0, 0.0, -3.0),
            max: DVec3::new(1.0, 0.5, 3.0),
        };
        // The +z face's corner (x max, y max) is texture (1, 1).
        let (c, face) = surface_coords(&b, DVec3::new(1.0, 0.5, 3.0), DVec3::Z, None);
        assert_eq!(face, Some([2.0, 0.5]));
        assert_eq!(texture_uv(c, None, face), [1.0, 1.0]);
        // The top face's centre is (0.5, 0.5); its u spans x (2), v spans z (6).
        let (c, face) = surface_coords(&b, DVec3::new(0.0, 0.5, 0.0), DVec3::Y, None);
        assert_eq!(
            (texture_uv(c, None, face), face),
            ([0.5, 0.5], Some([2.0, 6.0]))
        );
    }

    #[test]
    fn bilinear_hits_texel_centres_and_blends_between() {
        let img = Image {
            width: 2,
            height: 1,
            texels: vec![[0.0, 0.0, 0.0], [1.0, 2.0, 4.0]],
        };
        assert_eq!(img.bilinear(0.5, 0.5, false), DVec3::ZERO);
        assert_eq!(img.bilinear(1.5, 0.5, false), DVec3::new(1.0, 2.0, 4.0));
        assert_eq!(img.bilinear(1.0, 0.5, false), DVec3::new(0.5, 1.0, 2.0));
        // Clamped past the edge, wrapped with repeat.
        assert_eq!(img.bilinear(5.0, 0.5, false), DVec3::new(1.0, 2.0, 4.0));
        assert_eq!(img.bilinear(2.0, 0.5, true), DVec3::new(0.5, 1.0, 2.0));
        assert_eq!(img.at_uv([1.2, 0.5], false), None);
        assert!(img.at_uv([1.2, 0.5], true).is_some());
        assert_eq!(img.mean(), DVec3::new(0.5, 1.0, 2.0));
        assert!((srgb_to_linear(0.5) - 0.214_041).abs() < 1e-6);
    }

    #[test]
    fn dots_cover_about_their_density_and_repeat_by_seed() {
        let (d, density) = (0.05, 0.3);
        let n = 300;
        let mut bright = 0;
        for i in 0..n {
            for j in 0..n {
                let uv = [f64::from(i) * 0.004, f64::from(j) * 0.004];
                let a = dot_intensity(d, density, 7, uv);
                assert_eq!(a, dot_intensity(d, density, 7, uv));
                if a > (-2.0f64).exp() {
                    bright += 1;
                }
            }
        }
        // Inside the 1/e^2 diameter: ~density of the area (dots overlap a little).
        let covered = f64::from(bright) / f64::from(n * n);
        assert!((covered - density).abs() < 0.06, "covered {covered}");
        assert_ne!(
            dot_intensity(d, density, 7, [0.1, 0.1]),
            dot_intensity(d, density, 8, [0.1, 0.1])
        );
    }

    /// CRC-32 (PNG's) of `bytes`, to seal crafted chunks.
    fn crc32(bytes: &[u8]) -> u32 {
        let mut c = !0u32;
        for &b in bytes {
            c ^= u32::from(b);
            for _ in 0..8 {
                c = if c & 1 == 1 {
                    0xEDB8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
            }
        }
        !c
    }

    /// A PNG whose header declares `w` x `h` grey pixels and whose data is one tiny
    /// (short) IDAT chunk: a few hundred bytes that would decode to gigabytes.
    fn png_bomb(w: u32, h: u32) -> Vec<u8> {
        let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
        let mut chunk = |kind: &[u8], data: &[u8]| {
            png.extend_from_slice(&(data.len() as u32).to_be_bytes());
            let mut body = kind.to_vec();
            body.extend_from_slice(data);
            png.extend_from_slice(&body);
            png.extend_from_slice(&crc32(&body).to_be_bytes());
        };
        let mut ihdr = w.to_be_bytes().to_vec();
        ihdr.extend_from_slice(&h.to_be_bytes());
        ihdr.extend_from_slice(&[8, 0, 0, 0, 0]);
        chunk(b"IHDR", &ihdr);
        // zlib stream of a few zero bytes (stored block), far short of the image.
        chunk(
            b"IDAT",
            &[0x78, 0x01, 0x01, 0x04, 0x00, 0xfb, 0xff, 0, 0, 0, 0],
        );
        chunk(b"IEND", &[]);
        png
    }

    fn temp(name: &str, bytes: &[u8]) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("grin-surface-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join(name);
        std::fs::write(&path, bytes).expect("write");
        path
    }

    /// Image bombs: a small file whose header declares a huge image is refused from its
    /// header, before anything of that size is allocated (the 20000^2 PNG took 9.4 GB, the
    /// 60000^2 EXR aborted), and a size under the side limit but over the texel budget is
    /// refused too.
    #[test]
    fn huge_declared_images_are_refused_unread() {
        let e = load_image(&temp("bomb.png", &png_bomb(20_000, 20_000))).expect_err("bomb");
        assert_eq!(e, "20000x20000 exceeds 16384 texels a side");
        let e = load_image(&temp("wide.png", &png_bomb(16_384, 16_384))).expect_err("budget");
        assert!(
            e.starts_with("16384x16384 is 268435456 texels, over the 33554432"),
            "{e}"
        );
        // A small valid image still loads; the crafted one's header is read the same way.
        let ok = load_image(&temp("small.png", &png_bomb(2, 2)));
        assert!(ok.is_err(), "the short IDAT is an error, not a panic");

        // An EXR of 4x4 texels whose data window is patched to declare 60000x60000.
        let path = temp("small.exr", b"");
        let pixels = exr::prelude::SpecificChannels::rgb(|_: exr::prelude::Vec2<usize>| {
            (0.5f32, 0.5f32, 0.5f32)
        });
        use exr::prelude::WritableImage as _;
        exr::prelude::Image::from_channels((4, 4), pixels)
            .write()
            .to_file(&path)
            .expect("exr");
        let good = load_image(&path).expect("a small EXR loads");
        assert_eq!((good.width, good.height), (4, 4));
        let mut bytes = std::fs::read(&path).expect("read");
        for name in [&b"dataWindow\0box2i\0"[..], &b"displayWindow\0box2i\0"[..]] {
            let at = bytes
                .windows(name.len())
                .position(|w| w == name)
                .expect("window attribute")
                + name.len()
                + 4;
            bytes[at + 8..at + 12].copy_from_slice(&59_999i32.to_le_bytes());
            bytes[at + 12..at + 16].copy_from_slice(&59_999i32.to_le_bytes());
        }
        let e = load_image(&temp("bomb.exr", &bytes)).expect_err("bomb");
        assert_eq!(e, "60000x60000 exceeds 16384 texels a side");
    }
}
