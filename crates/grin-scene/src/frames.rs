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

#[cfg(test)]
mod list_tests {
    use super::*;

    fn list(s: &str) -> Vec<i64> {
        parse_frame_list(s).expect("frame list").frames().to_vec()
    }

    fn err(s: &str) -> String {
        parse_frame_list(s).expect_err("refused")
    }

    #[test]
    fn items_ranges_and_steps_are_read_in_order() {
        assert_eq!(
            list("1-3,5,7-20:2"),
            vec![1, 2, 3, 5, 7, 9, 11, 13, 15, 17, 19]
        );
        assert_eq!(list("7"), vec![7]);
        assert_eq!(list("10,1-2"), vec![10, 1, 2]);
        assert_eq!(list(" 1 - 3 , 5 ,7-9:3 "), vec![1, 2, 3, 5, 7]);
        assert_eq!(list("1-10:20"), vec![1]);
        assert_eq!(list("0-9:3"), vec![0, 3, 6, 9]);
        // grin's own form, per item.
        assert_eq!(list("1..3,8..=9,20..24:2"), vec![1, 2, 3, 8, 9, 20, 22, 24]);
        assert_eq!(list("-2..1"), vec![-2, -1, 0, 1]);
        let parsed: FrameList = "4-5".parse().expect("FromStr");
        assert_eq!(parsed.frames(), &[4, 5]);
    }

    #[test]
    fn repeats_keep_their_first_place() {
        assert_eq!(list("5,1-6,3,5"), vec![5, 1, 2, 3, 4, 6]);
        assert_eq!(list("1-3,1-3"), vec![1, 2, 3]);
        assert_eq!(list("0-10:5,0-10:2"), vec![0, 5, 10, 2, 4, 6, 8]);
    }

    #[test]
    fn negative_frames_are_frames() {
        assert_eq!(list("-5--1"), vec![-5, -4, -3, -2, -1]);
        assert_eq!(list("-3"), vec![-3]);
        assert_eq!(list("-10--2:2"), vec![-10, -8, -6, -4, -2]);
        assert_eq!(list("-2-1"), vec![-2, -1, 0, 1]);
        assert_eq!(list("-1 - -1"), vec![-1]);
        assert_eq!(
            list("9223372036854775806-9223372036854775807,-9223372036854775808"),
            vec![i64::MAX - 1, i64::MAX, i64::MIN]
        );
        assert_eq!(
            list("-9223372036854775808--9223372036854775807"),
            vec![i64::MIN, i64::MIN + 1]
        );
    }

    #[test]
    fn bad_items_are_named() {
        assert_eq!(
            err("1,7-x"),
            "`7-x` is not a frame (A), a range (A-B) or a stepped range (A-B:S)"
        );
        for item in ["x", "5:2", "1-", "-", "--5", "1-5:x", "1-5:", "1.5", "a..b"] {
            assert_eq!(
                err(item),
                format!("`{item}` is not a frame (A), a range (A-B) or a stepped range (A-B:S)")
            );
        }
        assert_eq!(err("9-3"), "frame range 9-3 ends before it starts");
        assert_eq!(err("1--3"), "frame range 1--3 ends before it starts");
        assert_eq!(err("9..3"), "frame range 9..3 ends before it starts");
        assert_eq!(err("1-9:0"), "step 0 in `1-9:0` must be at least 1");
        assert_eq!(err("1-9:-2"), "step -2 in `1-9:-2` must be at least 1");
        assert_eq!(err("1,,3"), "empty item in `1,,3`");
        assert_eq!(err("1,2,"), "empty item in `1,2,`");
        assert_eq!(err(""), "empty frame list");
        assert_eq!(err("  "), "empty frame list");
    }

    #[test]
    fn too_many_frames_are_refused_before_listing_them() {
        assert_eq!(
            err("0-100000"),
            "`0-100000` has 100001 frames; at most 100000"
        );
        assert_eq!(list("0-99999").len(), 100_000);
        // Repeats count toward the cap.
        assert_eq!(
            err("0-99999,5"),
            "`0-99999,5` has 100001 frames; at most 100000"
        );
        assert_eq!(list("0-199998:2").len(), 100_000);
        // Counted without overflow and without allocating the frames first.
        let start = std::time::Instant::now();
        assert_eq!(
            err("0-9223372036854775806"),
            "`0-9223372036854775806` has 9223372036854775807 frames; at most 100000"
        );
        assert_eq!(
            err("-9223372036854775808-9223372036854775807,0-9223372036854775807"),
            "`-9223372036854775808-9223372036854775807,0-9223372036854775807` has \
             27670116110564327424 frames; at most 100000"
        );
        assert!(start.elapsed() < std::time::Duration::from_secs(2));
    }

    #[test]
    fn from_range_lists_a_range() {
        let l = FrameList::from_range(3, 6);
        assert_eq!(l.frames(), &[3, 4, 5, 6]);
        assert_eq!((l.len(), l.is_empty()), (4, false));
        assert_eq!((l.first(), l.last()), (Some(3), Some(6)));
        let empty = FrameList::from_range(6, 3);
        assert!(empty.is_empty());
        assert_eq!((empty.first(), empty.last()), (None, None));
        assert_eq!(
            FrameList::from_range(i64::MAX, i64::MAX).frames(),
            &[i64::MAX]
        );
    }

    #[test]
    #[should_panic(expected = "at most 100000")]
    fn from_range_refuses_too_many_frames() {
        FrameList::from_range(0, i64::MAX);
    }

    #[test]
    fn shards_split_evenly_in_order() {
        let l = FrameList::from_range(1, 11);
        let sizes: Vec<usize> = (0..3).map(|i| l.shard(i, 3).len()).collect();
        assert_eq!(sizes, vec![4, 4, 3]);
        assert_eq!(l.shard(0, 3), vec![1, 2, 3, 4]);
        assert_eq!(l.shard(2, 3), vec![9, 10, 11]);
        for (len, count) in [
            (11, 3),
            (0, 1),
            (0, 4),
            (1, 1),
            (3, 10),
            (7, 7),
            (8, 7),
            (100, 7),
            (12, 4),
            (1000, 999),
        ] {
            let l = FrameList::from_range(-5, -5 + len as i64 - 1);
            let shards: Vec<Vec<i64>> = (0..count).map(|i| l.shard(i, count)).collect();
            assert_eq!(shards.concat(), l.frames(), "{len} frames in {count}");
            let sizes: Vec<usize> = shards.iter().map(Vec::len).collect();
            let (min, max) = (sizes.iter().min(), sizes.iter().max());
            assert!(max.zip(min).is_some_and(|(a, b)| a - b <= 1), "{sizes:?}");
            assert!(sizes.windows(2).all(|w| w[0] >= w[1]), "{sizes:?}");
            if count as usize > len {
                assert!(sizes.contains(&0), "{sizes:?}");
            }
        }
        // Shards follow the list's order, not the frames' values.
        let l = parse_frame_list("9,1,5,3").expect("list");
        assert_eq!((l.shard(0, 2), l.shard(1, 2)), (vec![9, 1], vec![5, 3]));
        assert!(l.shard(2, 2).is_empty() && l.shard(0, 0).is_empty());
    }

    #[test]
    fn chunks_cut_the_list_into_tasks() {
        let l = parse_frame_list("1-7,10").expect("list");
        assert_eq!(l.chunks(3), vec![vec![1, 2, 3], vec![4, 5, 6], vec![7, 10]]);
        assert_eq!(l.chunks(100), vec![l.frames().to_vec()]);
        assert_eq!(l.chunks(0), l.chunks(1));
        assert_eq!(l.chunks(1).len(), 8);
        assert!(FrameList::from_range(1, 0).chunks(4).is_empty());
    }

    #[test]
    fn display_is_compact_and_reads_back() {
        let shown = |s: &str| parse_frame_list(s).expect("list").to_string();
        assert_eq!(shown("1-3,5,7-20:2"), "1-3,5-19:2");
        assert_eq!(shown("1,2,3,4"), "1-4");
        assert_eq!(shown("1,3,4,5"), "1,3-5");
        assert_eq!(shown("5,4,3"), "5,4,3");
        assert_eq!(shown("-5--1"), "-5--1");
        assert_eq!(shown("-10--2:2"), "-10--2:2");
        assert_eq!(shown("1,3"), "1,3");
        assert_eq!(FrameList::from_range(1, 0).to_string(), "");
        for s in [
            "1-3,5,7-20:2",
            "5,1-6,3,5",
            "-5--1,10,-20--10:3",
            "1,2,4,6,8,9,10,20",
            "100,99,98,1-1000:7",
            "9223372036854775807,-9223372036854775808,0",
            "-9223372036854775808--9223372036854775807,9223372036854775806-9223372036854775807",
            "0,9223372036854775806,-9223372036854775806",
            "3..7,1",
        ] {
            let l = parse_frame_list(s).expect("list");
            assert_eq!(
                parse_frame_list(&l.to_string()),
                Ok(l.clone()),
                "{s} -> {l}"
            );
        }
    }

    #[test]
    fn shards_parse_and_refuse_nonsense() {
        assert_eq!(parse_shard("0/4"), Ok((0, 4)));
        assert_eq!(parse_shard("3/4"), Ok((3, 4)));
        assert_eq!(parse_shard("0/1"), Ok((0, 1)));
        assert_eq!(parse_shard(" 2 / 5 "), Ok((2, 5)));
        assert_eq!(
            parse_shard("3/3"),
            Err("`3/3`: shard index 3 must be below the shard count 3".to_string())
        );
        assert_eq!(
            parse_shard("0/0"),
            Err("`0/0`: the shard count must be at least 1".to_string())
        );
        for s in ["x/2", "1", "-1/2", "1/2/3", "/2", "1/", ""] {
            assert_eq!(
                parse_shard(s),
                Err(format!("`{s}` is not a shard (I/N, e.g. 0/4)"))
            );
        }
    }

    #[test]
    fn frame_seeds_are_stable_distinct_and_unrelated() {
        let seeds: Vec<u64> = (0..1000).map(|f| frame_seed(42, f)).collect();
        let again: Vec<u64> = (0..1000).map(|f| frame_seed(42, f)).collect();
        assert_eq!(seeds, again);
        let distinct: std::collections::HashSet<u64> = (-1000..1000)
            .map(|f| frame_seed(42, f))
            .chain((0..1000).map(|f| frame_seed(0, f)))
            .collect();
        assert_eq!(distinct.len(), 3000 - 1000 + 1000);
        assert_ne!(frame_seed(1, 7), frame_seed(2, 7));
        assert_ne!(frame_seed(0, 0), 0);
        // Neighbouring frames differ in about half their bits.
        let flipped: u32 = seeds.windows(2).map(|w| (w[0] ^ w[1]).count_ones()).sum();
        let mean = f64::from(flipped) / 999.0;
        assert!((30.0..34.0).contains(&mean), "{mean}");
    }
}
