use super::*;

fn p() -> &'static Path {
    Path::new("rays.csv")
}

#[test]
fn table_numbers_are_rusts_shortest_form() {
    // What `fmt_num_into` promises: `{:?}` without a trailing `.0`.
    let rust = |v: f64| {
        let t = format!("{v:?}");
        t.strip_suffix(".0").map_or(t.clone(), str::to_owned)
    };
    let mut cases = vec![
        0.0,
        -0.0,
        1.0,
        -1.0,
        0.1,
        1.0 / 3.0,
        1e-4,
        1e-4 * (1.0 - f64::EPSILON),
        1e-5,
        1e-5 * (1.0 - f64::EPSILON),
        9.999e-5,
        2.5e-5,
        1e15,
        1e16,
        1e16 * (1.0 - f64::EPSILON),
        1.5e16,
        1e17,
        1e21,
        1e22,
        123456789.0,
        9007199254740993.0,
        f64::MAX,
        f64::MIN_POSITIVE,
        5e-324,
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    // Random bit patterns (every exponent) and random values over 1e-30..1e30.
    let mut seed = 0x9e37_79b9_7f4a_7c15_u64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    for _ in 0..100_000 {
        cases.push(f64::from_bits(next()));
        let u = (next() >> 11) as f64 / (1u64 << 53) as f64;
        let sign = if next() & 1 == 0 { 1.0 } else { -1.0 };
        cases.push(sign * 10f64.powf(60.0 * u - 30.0));
    }
    let (mut buf, mut ryu) = (String::new(), ryu::Buffer::new());
    let mut ties = 0;
    for v in cases {
        fmt_num_into(&mut buf, v, &mut ryu);
        let want = rust(v);
        if buf == want {
            continue;
        }
        // Halfway between two shortest forms: the same length, the same number read
        // back, the last digit even here and one more in Rust's.
        let back = |t: &str| t.parse::<f64>().map(f64::to_bits);
        let last = |t: &str| t.bytes().last().map_or(0, |b| b - b'0');
        assert_eq!(buf.len(), want.len(), "{:#x}: {buf} vs {want}", v.to_bits());
        assert_eq!(back(&buf), Ok(v.to_bits()), "{:#x}: {buf}", v.to_bits());
        assert_eq!(back(&want), Ok(v.to_bits()), "{:#x}: {want}", v.to_bits());
        assert_eq!(
            buf[..buf.len() - 1],
            want[..want.len() - 1],
            "{buf} vs {want}"
        );
        assert!(
            last(&buf) % 2 == 0 && last(&want) == last(&buf) + 1,
            "{buf} vs {want}"
        );
        ties += 1;
    }
    // Ties need a short exact binary fraction: 284 of these 200,000 values.
    assert!(ties < 1000, "{ties} ties");
}

fn missed(row: &RayRow) -> RayResult {
    RayResult::at(RayStatus::Missed, row.origin, DVec3::Z)
}

#[test]
fn parses_rows_and_skips_comments() {
    let t = parse_rays(
        "\u{feff}ox, oy,oz,dx,dy,dz\n# c\n\n0,0,-3,0,0,1\n1e-3,2,3,nan,0,1\n",
        p(),
    )
    .expect("valid");
    assert_eq!(t.rows.len(), 2);
    assert!(t.extra_columns.is_empty());
    assert_eq!(t.rows[0].line, 4);
    assert_eq!(t.rows[0].origin, DVec3::new(0.0, 0.0, -3.0));
    assert_eq!(t.rows[1].line, 5);
    assert!(t.rows[1].dir.x.is_nan());
}

#[test]
fn errors_name_file_and_line() {
    let e = parse_rays("", p()).expect_err("empty").to_string();
    assert!(e.starts_with("rays.csv: empty ray table"), "{e}");
    let e = parse_rays("x,y,z\n", p()).expect_err("header").to_string();
    assert_eq!(
        e,
        "rays.csv:1: header must name the columns ox,oy,oz,dx,dy,dz (other columns are passed through), found `x,y,z`"
    );
    let e = parse_rays("ox,oy,oz,dx,dy,dz,ox\n", p())
        .expect_err("twice")
        .to_string();
    assert!(e.contains("found `ox,oy,oz,dx,dy,dz,ox`"), "{e}");
    let e = parse_rays("ox,oy,oz,dx,dy,dz\n0,0,0,1,0,0\n0,0,0,1\n", p())
        .expect_err("cols")
        .to_string();
    assert_eq!(
        e,
        "rays.csv:3: expected 6 columns (as in the header), found 4"
    );
    let e = parse_rays("ox,oy,oz,dx,dy,dz\n0,0,zero,1,0,0\n", p())
        .expect_err("num")
        .to_string();
    assert_eq!(e, "rays.csv:2: column `oz`: `zero` is not a number");
}

/// Columns in any order, extra columns (quoted, with commas) passed through in both
/// output formats.
#[test]
fn extra_columns_are_passed_through() {
    let t = parse_rays(
        "id,dz,dy,dx,oz,oy,ox,note\n7,2,0,0,-3,0.5,0,\"a, b\"\n",
        p(),
    )
    .expect("valid");
    assert_eq!(t.extra_columns, ["id", "note"]);
    let row = &t.rows[0];
    assert_eq!(
        (row.origin, row.dir),
        (DVec3::new(0.0, 0.5, -3.0), DVec3::new(0.0, 0.0, 2.0))
    );
    assert_eq!(row.extra, ["7", "a, b"]);
    let res = [missed(row)];
    let mut csv = Vec::new();
    write_table(&mut csv, TableFormat::Csv, &t, &res).expect("write");
    let csv = String::from_utf8(csv).expect("utf8");
    assert_eq!(
        csv,
        "ox,oy,oz,dx,dy,dz,id,note,status,px,py,pz,qx,qy,qz,opl,length,steps,evals\n0,0.5,-3,0,0,2,7,\"a, b\",missed,0,0.5,-3,0,0,1,0,0,0,0\n"
    );
    // The output reads back as a table with the result columns passed through.
    let again = parse_rays(&csv, p()).expect("output parses");
    assert_eq!(again.rows[0].extra[..2], ["7", "a, b"]);
    let mut json = Vec::new();
    write_table(&mut json, TableFormat::Json, &t, &res).expect("write");
    let v: serde_json::Value = serde_json::from_slice(&json).expect("valid JSON");
    assert_eq!(v[0]["note"], "a, b");
    assert_eq!(v[0]["id"], "7");
    assert_eq!(v[0]["status"], "missed");
    assert_eq!(v[0]["oz"], -3.0);
    let keys: Vec<&str> = v[0]
        .as_object()
        .expect("object")
        .keys()
        .map(String::as_str)
        .collect();
    assert_eq!(
        keys[..8],
        ["ox", "oy", "oz", "dx", "dy", "dz", "id", "note"]
    );
}

/// Batches of a long table keep the file's line numbers (comments and blank lines
/// between them, a quoted field over two lines, a `#` inside it), and a bad row far
/// down is named by its line.
#[test]
fn batches_keep_line_numbers() {
    let mut text = String::from("# a table\nox,oy,oz,dx,dy,dz,note\n");
    let mut line = 2;
    for i in 0..100_000 {
        if i % 7 == 0 {
            text.push_str("\n# comment\n");
            line += 2;
        }
        if i == 5 {
            text.push_str("0,0,0,0,0,1,\"two\n# lines\"\n");
            line += 2;
            continue;
        }
        text.push_str(&format!("{i},0,0,0,0,1,n\n"));
        line += 1;
    }
    let mut reader = RayReader::new(text.as_bytes(), p()).expect("header");
    let mut rows = Vec::new();
    while reader.next_batch(4096, &mut rows).expect("rows") > 0 {}
    assert_eq!(rows.len(), 100_000);
    assert_eq!(rows[5].extra, ["two\n# lines"]);
    assert_eq!(rows[5].line, 10, "where the quoted row starts");
    assert_eq!(rows[6].line, 12);
    let last = rows.last().expect("rows");
    assert_eq!((last.origin.x, last.line), (99_999.0, line));
    text.push_str("1,2,x,0,0,1,n\n");
    let e = parse_rays(&text, p()).expect_err("bad row").to_string();
    assert_eq!(
        e,
        format!("rays.csv:{}: column `oz`: `x` is not a number", line + 1)
    );
}

/// The streamed writer's output is the same in one batch or many, in both formats,
/// its rows (formatted in parallel chunks) in the table's order wherever the batches
/// split the chunks.
#[test]
fn batched_writes_equal_one_write_in_order() {
    let n = 2 * FORMAT_CHUNK + 7;
    let mut text = String::from("ox,oy,oz,dx,dy,dz,id\n");
    for i in 0..n {
        text.push_str(&format!("{i},0,-3,0,0,2,r{i}\n"));
    }
    let t = parse_rays(&text, p()).expect("valid");
    let res: Vec<RayResult> = t.rows.iter().map(missed).collect();
    for format in [TableFormat::Csv, TableFormat::Json] {
        let mut whole = Vec::new();
        write_table(&mut whole, format, &t, &res).expect("write");
        let mut parts = Vec::new();
        let mut w = TableWriter::new(format, &t.extra_columns);
        for (a, b) in [(0, 1), (1, FORMAT_CHUNK + 3), (FORMAT_CHUNK + 3, n)] {
            w.rows(&mut parts, &t.rows[a..b], &res[a..b])
                .expect("write");
        }
        w.finish(&mut parts).expect("finish");
        assert!(whole == parts, "{format:?}: batches differ from one write");
        let ids: Vec<String> = match format {
            TableFormat::Csv => String::from_utf8(whole)
                .expect("utf8")
                .lines()
                .skip(1)
                .map(|l| l.split(',').nth(6).expect("id").to_owned())
                .collect(),
            TableFormat::Json => serde_json::from_slice::<serde_json::Value>(&whole)
                .expect("valid JSON")
                .as_array()
                .expect("array")
                .iter()
                .map(|o| o["id"].as_str().expect("id").to_owned())
                .collect(),
        };
        let want: Vec<String> = (0..n).map(|i| format!("r{i}")).collect();
        assert!(ids == want, "{format:?}: rows out of order");
    }
    let mut empty = Vec::new();
    TableWriter::new(TableFormat::Json, &[])
        .finish(&mut empty)
        .expect("finish");
    assert_eq!(empty, b"[]\n");
}

#[test]
fn csv_and_json_output_columns() {
    let t = parse_rays("ox,oy,oz,dx,dy,dz\n0,0,-3,0,0,2\n", p()).expect("valid");
    let mut res = missed(&t.rows[0]);
    let mut csv = Vec::new();
    write_table(&mut csv, TableFormat::Csv, &t, &[res]).expect("write");
    let csv = String::from_utf8(csv).expect("utf8");
    assert_eq!(
        csv,
        "ox,oy,oz,dx,dy,dz,status,px,py,pz,qx,qy,qz,opl,length,steps,evals\n0,0,-3,0,0,2,missed,0,0,-3,0,0,1,0,0,0,0\n"
    );
    res.opl = f64::NAN;
    let mut json = Vec::new();
    write_table(&mut json, TableFormat::Json, &t, &[res]).expect("write");
    let v: serde_json::Value = serde_json::from_slice(&json).expect("valid JSON");
    assert_eq!(v[0]["px"], 0.0);
    assert!(v[0]["opl"].is_null(), "non-finite numbers are null");
    assert_eq!(
        (v[0]["steps"].as_u64(), v[0]["evals"].as_u64()),
        (Some(0), Some(0))
    );
}
