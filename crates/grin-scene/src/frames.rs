//! Frame sequences: frame tokens in file paths (`fluid_####.vdb`, `fluid_%04d.vdb`,
//! `fluid_$F4.vdb`) and the scene of one frame ([`Scene::at_frame`]).

use crate::{FieldSpec, Scene};

/// Most frames one `[animation]` range may hold.
pub const MAX_FRAMES: i64 = 100_000;

/// The first frame token in `s`: its byte range and zero-padded width. Tokens: a run of
/// `#` (width = its length), `%d` / `%0Nd` (width N, 1 for `%d`), `$F` / `$FN` (Houdini;
/// width N, 1 for `$F`).
fn find_token(s: &str) -> Option<(usize, usize, usize)> {
    let b = s.as_bytes();
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            b'#' => {
                let start = i;
                while i < b.len() && b[i] == b'#' {
                    i += 1;
                }
                return Some((start, i, i - start));
            }
            b'%' => {
                let mut j = i + 1;
                let digits_start = j;
                while j < b.len() && b[j].is_ascii_digit() {
                    j += 1;
                }
                if j < b.len() && b[j] == b'd' {
                    let width = s[digits_start..j].parse::<usize>().unwrap_or(1).clamp(1, 9);
                    return Some((i, j + 1, width));
                }
            }
            b'$' if b.get(i + 1) == Some(&b'F') => {
                let mut j = i + 2;
                let digits_start = j;
                while j < b.len() && b[j].is_ascii_digit() {
                    j += 1;
                }
                let width = s[digits_start..j].parse::<usize>().unwrap_or(1).clamp(1, 9);
                return Some((i, j, width));
            }
            _ => {}
        }
        i += 1;
    }
    None
}

/// Whether `s` holds a frame token.
pub fn has_frame_token(s: &str) -> bool {
    find_token(s).is_some()
}

/// `s` with every frame token replaced by `frame`, zero-padded to the token's width;
/// `None` when `s` has no token.
pub fn substitute_frame(s: &str, frame: i64) -> Option<String> {
    let mut rest = s;
    let mut out = String::new();
    let mut any = false;
    while let Some((a, b, width)) = find_token(rest) {
        any = true;
        out.push_str(&rest[..a]);
        out.push_str(&format!("{frame:0width$}"));
        rest = &rest[b..];
    }
    any.then(|| out + rest)
}

/// `A..B` (inclusive) or a single `A`.
pub fn parse_frame_range(s: &str) -> Result<(i64, i64), String> {
    let bad = || format!("`{s}` is not a frame range (A..B, e.g. 1..24, or one frame)");
    let (a, b) = match s.split_once("..") {
        Some((a, b)) => (a.trim(), b.trim().trim_start_matches('=')),
        None => (s.trim(), s.trim()),
    };
    let a: i64 = a.parse().map_err(|_| bad())?;
    let b: i64 = b.parse().map_err(|_| bad())?;
    if b < a {
        return Err(format!("frame range {a}..{b} ends before it starts"));
    }
    let count = frame_count(a, b);
    if count > MAX_FRAMES as u64 {
        return Err(format!(
            "frame range {a}..{b} has {count} frames; at most {MAX_FRAMES}"
        ));
    }
    Ok((a, b))
}

/// Frames in `first..=last` (0 when it ends before it starts, [`u64::MAX`] for the one
/// count past it, i64::MIN..=i64::MAX), without overflow at the ends of i64.
pub fn frame_count(first: i64, last: i64) -> u64 {
    let n = (i128::from(last) - i128::from(first) + 1).max(0);
    u64::try_from(n).unwrap_or(u64::MAX)
}

/// Most items of a long list that an error message spells out.
pub const SHOWN_IN_ERRORS: usize = 5;

/// `items` joined with `, `, the first [`SHOWN_IN_ERRORS`] of a longer list and how many
/// more (an error line stays a line when 100,000 frames are missing).
pub fn summarize(items: &[String]) -> String {
    let shown = items[..items.len().min(SHOWN_IN_ERRORS)].join(", ");
    match items.len().checked_sub(SHOWN_IN_ERRORS) {
        Some(more) if more > 0 => format!("{shown} and {more} more"),
        _ => shown,
    }
}

impl Scene {
    /// Frames per second of the scene's animation (24 without `[animation]`).
    pub fn fps(&self) -> f64 {
        self.animation.as_ref().map_or(24.0, |a| a.fps)
    }

    /// Whether the medium reads a file per frame (a frame token in its path).
    pub fn is_sequence(&self) -> bool {
        match self.medium.as_ref().map(|m| &m.field) {
            Some(FieldSpec::Vdb(v)) => has_frame_token(&v.path),
            Some(FieldSpec::Baked { path, .. }) => has_frame_token(path),
            _ => false,
        }
    }

    /// The scene of frame `frame` at `fps`: the frame's file where the medium's path has
    /// a frame token, noise / `expr` time `t + frame / fps`, and a `[sensor]` seed of the
    /// frame's own (a sensor's noise changes from exposure to exposure; frame 0 keeps
    /// the scene's seed).
    pub fn at_frame(&self, frame: i64, fps: f64) -> Scene {
        let mut s = self.clone();
        if let Some(sensor) = &mut s.sensor {
            sensor.seed = sensor
                .seed
                .wrapping_add((frame as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        }
        if let Some(m) = &mut s.medium {
            let dt = frame as f64 / fps;
            match &mut m.field {
                FieldSpec::Vdb(v) => {
                    if let Some(p) = substitute_frame(&v.path, frame) {
                        v.path = p;
                    }
                }
                FieldSpec::Baked { path, .. } => {
                    if let Some(p) = substitute_frame(path, frame) {
                        *path = p;
                    }
                }
                FieldSpec::Noise(n) => n.t += dt,
                FieldSpec::Expr { t, .. } => *t += dt,
                _ => {}
            }
        }
        s
    }
}

/// The files of frames `first..=last` of `scene`'s sequence (paths relative to
/// `scene_dir`) that are not there, each as `frame N: PATH`; empty when every frame is
/// there or the medium is not a sequence.
pub fn missing_frames(
    scene: &Scene,
    scene_dir: &std::path::Path,
    first: i64,
    last: i64,
) -> Vec<String> {
    if !scene.is_sequence() {
        return Vec::new();
    }
    let fps = scene.fps();
    (first..=last)
        .filter_map(|f| {
            let s = scene.at_frame(f, fps);
            let path = match s.medium.as_ref().map(|m| &m.field) {
                Some(FieldSpec::Vdb(v)) => scene_dir.join(&v.path),
                Some(FieldSpec::Baked { path, .. }) => scene_dir.join(path),
                _ => return None,
            };
            (!path.is_file()).then(|| format!("frame {f}: {}", path.display()))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_frame_gets_its_own_sensor_noise() {
        let text = "[camera]\nposition = [0.0, 0.0, 0.0]\nlook_at = [0.0, 0.0, 1.0]\n\
                    [sensor]\nfull_well = 1000.0\nseed = 5\n";
        let scene = crate::parse_scene(text, std::path::Path::new("s.toml")).expect("scene");
        let seed = |f: i64| scene.at_frame(f, 24.0).sensor.expect("sensor").seed;
        assert_eq!(seed(0), 5);
        assert_eq!(seed(3), seed(3));
        assert!(seed(1) != seed(0) && seed(2) != seed(1) && seed(-1) != seed(0));
    }

    #[test]
    fn every_token_style_is_replaced_zero_padded() {
        assert_eq!(
            substitute_frame("fluid_####.vdb", 7).as_deref(),
            Some("fluid_0007.vdb")
        );
        assert_eq!(
            substitute_frame("fluid_#.vdb", 12).as_deref(),
            Some("fluid_12.vdb")
        );
        assert_eq!(
            substitute_frame("f_%04d.vdb", 3).as_deref(),
            Some("f_0003.vdb")
        );
        assert_eq!(substitute_frame("f_%d.vdb", 3).as_deref(), Some("f_3.vdb"));
        assert_eq!(
            substitute_frame("f.$F4.vdb", 42).as_deref(),
            Some("f.0042.vdb")
        );
        assert_eq!(
            substitute_frame("f.$F.vdb", 42).as_deref(),
            Some("f.42.vdb")
        );
        assert_eq!(
            substitute_frame("a_##/b_##.vdb", 5).as_deref(),
            Some("a_05/b_05.vdb")
        );
        assert_eq!(substitute_frame("plain.vdb", 5), None);
        assert_eq!(substitute_frame("100%.vdb", 5), None);
        assert!(!has_frame_token("$HOME/x.vdb"));
    }

    #[test]
    fn frame_ranges_parse_and_refuse_nonsense() {
        assert_eq!(parse_frame_range("1..4"), Ok((1, 4)));
        assert_eq!(parse_frame_range("1..=4"), Ok((1, 4)));
        assert_eq!(parse_frame_range("7"), Ok((7, 7)));
        assert!(
            parse_frame_range("4..1")
                .expect_err("refused")
                .contains("ends before")
        );
        assert!(
            parse_frame_range("a..b")
                .expect_err("refused")
                .contains("not a frame range")
        );
        assert!(
            parse_frame_range("0..100000")
                .expect_err("refused")
                .contains("at most")
        );
        // The ends of i64: no overflow slips a range past the cap.
        assert_eq!(
            parse_frame_range("-1..9223372036854775807").expect_err("refused"),
            "frame range -1..9223372036854775807 has 9223372036854775809 frames; at most 100000"
        );
        assert!(parse_frame_range("-9223372036854775808..9223372036854775807").is_err());
        assert_eq!(
            parse_frame_range("9223372036854775807"),
            Ok((i64::MAX, i64::MAX))
        );
        assert_eq!(frame_count(i64::MIN, i64::MAX), u64::MAX);
        assert_eq!(frame_count(3, 2), 0);
    }

    #[test]
    fn long_lists_are_summarised() {
        let items: Vec<String> = (0..100_000)
            .map(|f| format!("frame {f}: f.{f}.vdb"))
            .collect();
        assert_eq!(
            summarize(&items),
            "frame 0: f.0.vdb, frame 1: f.1.vdb, frame 2: f.2.vdb, frame 3: f.3.vdb, \
             frame 4: f.4.vdb and 99995 more"
        );
        assert_eq!(summarize(&items[..2]), "frame 0: f.0.vdb, frame 1: f.1.vdb");
    }
}
