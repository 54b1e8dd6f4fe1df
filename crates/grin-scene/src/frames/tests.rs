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

// The frame lists.

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
