//! Frame sequences: frame tokens in file paths (`fluid_####.vdb`, `fluid_%04d.vdb`,
//! `fluid_$F4.vdb`) and the scene of one frame ([`Scene::at_frame`]).
//!
//! Over 600 lines: one concept, frame tokens and the scene of one frame; half of it is their tests.

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

/// An ordered list of frames: the frames in the order given, each once (a repeat keeps
/// its first place). [`parse_frame_list`] reads one from a render farm's frame list.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FrameList {
    frames: Vec<i64>,
}

/// One item of a frame list: `first..=last` in steps of `step` (at least 1).
struct ListItem {
    first: i64,
    last: i64,
    step: i64,
}

impl ListItem {
    /// Frames the item holds, without overflow.
    fn count(&self) -> i128 {
        (i128::from(self.last) - i128::from(self.first)) / i128::from(self.step) + 1
    }
}

/// One trimmed, non-empty item of a frame list: `A`, `A-B`, `A-B:S`, `A..B` or `A..B:S`.
fn parse_list_item(item: &str) -> Result<ListItem, String> {
    let bad = || format!("`{item}` is not a frame (A), a range (A-B) or a stepped range (A-B:S)");
    let (range, step) = match item.rsplit_once(':') {
        Some((range, step)) => (range.trim(), Some(step.trim())),
        None => (item, None),
    };
    let (first, last, sep) = if let Some((a, b)) = range.split_once("..") {
        let b = b.trim();
        let b = b.strip_prefix('=').unwrap_or(b).trim();
        let a: i64 = a.trim().parse().map_err(|_| bad())?;
        let b: i64 = b.parse().map_err(|_| bad())?;
        (a, b, "..")
    } else if let Ok(a) = range.parse::<i64>() {
        if step.is_some() {
            return Err(bad());
        }
        (a, a, "")
    } else {
        // `-` both separates and signs: try each `-` after the first character.
        range
            .match_indices('-')
            .filter(|&(i, _)| i > 0)
            .find_map(|(i, _)| {
                let a = range[..i].trim().parse::<i64>().ok()?;
                let b = range[i + 1..].trim().parse::<i64>().ok()?;
                Some((a, b, "-"))
            })
            .ok_or_else(bad)?
    };
    let step = match step {
        Some(text) => {
            let step: i64 = text.parse().map_err(|_| bad())?;
            if step < 1 {
                return Err(format!("step {step} in `{item}` must be at least 1"));
            }
            step
        }
        None => 1,
    };
    if last < first {
        return Err(format!(
            "frame range {first}{sep}{last} ends before it starts"
        ));
    }
    Ok(ListItem { first, last, step })
}

/// A frame list in the OpenJD / Deadline syntax: comma-separated items, each a frame
/// `A`, a range `A-B` (inclusive), a stepped range `A-B:S` (A, A+S, ... up to B) or
/// grin's `A..B`; frames may be negative (`-5--1`). Repeats are dropped, keeping the
/// first. At most [`MAX_FRAMES`] frames, counting repeats, checked before any frame is
/// listed.
pub fn parse_frame_list(s: &str) -> Result<FrameList, String> {
    if s.trim().is_empty() {
        return Err("empty frame list".to_string());
    }
    let items = s
        .split(',')
        .map(|item| match item.trim() {
            "" => Err(format!("empty item in `{s}`")),
            item => parse_list_item(item),
        })
        .collect::<Result<Vec<_>, _>>()?;
    let total: i128 = items.iter().map(ListItem::count).sum();
    if total > i128::from(MAX_FRAMES) {
        return Err(format!(
            "`{}` has {total} frames; at most {MAX_FRAMES}",
            s.trim()
        ));
    }
    let mut seen = std::collections::HashSet::with_capacity(total as usize);
    let mut frames = Vec::with_capacity(total as usize);
    for item in &items {
        for k in 0..item.count() {
            // In range: at most `last`, which is an i64.
            let frame = (i128::from(item.first) + k * i128::from(item.step)) as i64;
            if seen.insert(frame) {
                frames.push(frame);
            }
        }
    }
    Ok(FrameList { frames })
}

impl std::str::FromStr for FrameList {
    type Err = String;

    /// The same as [`parse_frame_list`].
    fn from_str(s: &str) -> Result<Self, String> {
        parse_frame_list(s)
    }
}

impl FrameList {
    /// The frames `first..=last` in order; empty when it ends before it starts.
    ///
    /// # Panics
    ///
    /// When the range holds more than [`MAX_FRAMES`] frames (one from
    /// [`parse_frame_range`] never does).
    pub fn from_range(first: i64, last: i64) -> FrameList {
        let count = frame_count(first, last);
        assert!(
            count <= MAX_FRAMES as u64,
            "frame range {first}..{last} has {count} frames; at most {MAX_FRAMES}"
        );
        FrameList {
            frames: (first..=last).collect(),
        }
    }

    /// The frames, in order.
    pub fn frames(&self) -> &[i64] {
        &self.frames
    }

    /// How many frames the list holds.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// Whether the list holds no frame.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// The first frame of the list.
    pub fn first(&self) -> Option<i64> {
        self.frames.first().copied()
    }

    /// The last frame of the list.
    pub fn last(&self) -> Option<i64> {
        self.frames.last().copied()
    }

    /// The frames of shard `index` of `count` (0-based): the list cut into `count`
    /// contiguous pieces whose sizes differ by at most one, the earlier pieces taking
    /// the extra frames. The shards together hold each frame once, in order. Empty when
    /// `index >= count` or when there are more shards than frames left for it.
    pub fn shard(&self, index: u32, count: u32) -> Vec<i64> {
        if index >= count {
            return Vec::new();
        }
        let (index, count) = (index as usize, count as usize);
        let base = self.frames.len() / count;
        let extra = self.frames.len() % count;
        let start = index * base + index.min(extra);
        let size = base + usize::from(index < extra);
        self.frames[start..start + size].to_vec()
    }

    /// The list cut into pieces of `size` frames in order, the last piece shorter when
    /// the frames run out (Deadline's "frames per task"). A `size` of 0 counts as 1.
    pub fn chunks(&self, size: usize) -> Vec<Vec<i64>> {
        self.frames
            .chunks(size.max(1))
            .map(<[i64]>::to_vec)
            .collect()
    }
}

impl std::fmt::Display for FrameList {
    /// The list in the syntax [`parse_frame_list`] reads, compactly: runs of consecutive
    /// frames as `A-B`, runs of three or more at a steady step as `A-B:S`, the rest as
    /// single frames. An empty list prints as nothing.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let frames = &self.frames;
        let gap = |i: usize| i128::from(frames[i + 1]) - i128::from(frames[i]);
        let mut i = 0;
        while i < frames.len() {
            if i > 0 {
                f.write_str(",")?;
            }
            let mut end = i;
            if i + 1 < frames.len() && gap(i) > 0 {
                let step = gap(i);
                while end + 1 < frames.len() && gap(end) == step {
                    end += 1;
                }
                let run = end - i + 1;
                if step == 1 {
                    write!(f, "{}-{}", frames[i], frames[end])?;
                } else if run >= 3 {
                    write!(f, "{}-{}:{step}", frames[i], frames[end])?;
                } else {
                    end = i;
                    write!(f, "{}", frames[i])?;
                }
            } else {
                write!(f, "{}", frames[i])?;
            }
            i = end + 1;
        }
        Ok(())
    }
}

/// `I/N`: shard `I` of `N`, 0-based (`0 <= I < N`, `N >= 1`), as Slurm's
/// `$SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT` gives it for `--array=0-(N-1)`.
pub fn parse_shard(s: &str) -> Result<(u32, u32), String> {
    let bad = || format!("`{s}` is not a shard (I/N, e.g. 0/4)");
    let (index, count) = s.trim().split_once('/').ok_or_else(bad)?;
    let index: u32 = index.trim().parse().map_err(|_| bad())?;
    let count: u32 = count.trim().parse().map_err(|_| bad())?;
    if count == 0 {
        return Err(format!("`{s}`: the shard count must be at least 1"));
    }
    if index >= count {
        return Err(format!(
            "`{s}`: shard index {index} must be below the shard count {count}"
        ));
    }
    Ok((index, count))
}

/// The splitmix64 finalizer: a bijection on u64 whose output bits each depend on every
/// input bit.
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A seed for frame `frame` of a render seeded with `base`: splitmix64 of `base` XOR
/// the splitmix64 of the frame. It is deterministic, nearby frames get unrelated seeds,
/// and two different frames under one `base` never share a seed (each step is a
/// bijection).
pub fn frame_seed(base: u64, frame: i64) -> u64 {
    mix64(base ^ mix64((frame as u64).wrapping_add(0x9E37_79B9_7F4A_7C15)))
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
        self.medium
            .as_ref()
            .and_then(|m| m.field.file())
            .is_some_and(has_frame_token)
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
            let path = scene_dir.join(s.medium.as_ref()?.field.file()?);
            (!path.is_file()).then(|| format!("frame {f}: {}", path.display()))
        })
        .collect()
}

#[cfg(test)]
mod tests;
