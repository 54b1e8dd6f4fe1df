//! Ray tables for `grin trace`: read the input CSV (`ox,oy,oz,dx,dy,dz`, in any order, and
//! any other columns, which are passed through), trace every ray in parallel, and write
//! the table back as CSV or JSON with the result columns
//! `status,px,py,pz,qx,qy,qz,opl,length,steps,evals` (ARCHITECTURE.md, "Ray tables").
//! CSV through the `csv` crate (quoting, `#` comments, a UTF-8 BOM), JSON through
//! serde_json; `-` reads standard input.

use std::io::{self, Write};
use std::path::{Path, PathBuf};

use glam::DVec3;
use grin_field::{IndexField, Real};
use rayon::prelude::*;

use crate::trace::{RayResult, RayStatus, TraceSettings, trace_ray};

/// The input columns, in order.
pub const INPUT_COLUMNS: [&str; 6] = ["ox", "oy", "oz", "dx", "dy", "dz"];
/// The result columns appended to the input columns.
pub const OUTPUT_COLUMNS: [&str; 11] = [
    "status", "px", "py", "pz", "qx", "qy", "qz", "opl", "length", "steps", "evals",
];

/// Why a ray table could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum TableError {
    #[error("{}: cannot read ray table: {}", path.display(), grin_output::plain(err))]
    Read { path: PathBuf, err: io::Error },
    #[error("{path}: empty ray table: expected the header `ox,oy,oz,dx,dy,dz`")]
    Empty { path: PathBuf },
    #[error(
        "{path}:{line}: header must name the columns ox,oy,oz,dx,dy,dz (other columns are passed through), found `{found}`"
    )]
    Header {
        path: PathBuf,
        line: usize,
        found: String,
    },
    #[error("{path}:{line}: expected {expected} columns (as in the header), found {found}")]
    Columns {
        path: PathBuf,
        line: usize,
        expected: usize,
        found: usize,
    },
    #[error("{path}:{line}: {message}")]
    Csv {
        path: PathBuf,
        line: usize,
        message: String,
    },
    #[error("{path}:{line}: column `{column}`: `{value}` is not a number")]
    Number {
        path: PathBuf,
        line: usize,
        column: &'static str,
        value: String,
    },
}

/// One input ray, the line it came from (1-based) and its other columns' values.
#[derive(Debug, Clone, PartialEq)]
pub struct RayRow {
    pub line: usize,
    pub origin: DVec3,
    pub dir: DVec3,
    /// Values of [`RayTable::extra_columns`], passed through to the output.
    pub extra: Vec<String>,
}

/// A parsed ray table: the rays and the names of the columns that are not ray inputs.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RayTable {
    pub extra_columns: Vec<String>,
    pub rows: Vec<RayRow>,
}

/// Output format of a traced table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TableFormat {
    Csv,
    /// An array of objects, one per ray, keyed by the column names; non-finite numbers are `null`.
    Json,
}

/// Read a ray table file, or standard input for `-`.
pub fn read_rays(path: &Path) -> Result<RayTable, TableError> {
    let read_err = |err| TableError::Read {
        path: path.to_owned(),
        err,
    };
    let text = if path.as_os_str() == "-" {
        let mut text = String::new();
        io::Read::read_to_string(&mut io::stdin().lock(), &mut text).map_err(read_err)?;
        text
    } else {
        std::fs::read_to_string(path).map_err(read_err)?
    };
    parse_rays(&text, path)
}

/// Parse a ray table (`path` only names it in errors). Blank lines and lines starting
/// with `#` are skipped. `nan`/`inf` values parse (those rays trace as `error`); text that
/// is not a number and rows with the wrong number of columns are errors naming the line.
pub fn parse_rays(text: &str, path: &Path) -> Result<RayTable, TableError> {
    let text = text.trim_start_matches('\u{feff}');
    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .trim(csv::Trim::All)
        .flexible(true)
        .has_headers(false)
        .from_reader(text.as_bytes());
    // 1-based line where the record read from byte `at` starts: csv reports where it began
    // reading, before the blank and `#` lines it skipped.
    let line_of = |at: u64| {
        let mut at = (at as usize).min(text.len());
        let mut line = 1 + text.as_bytes()[..at]
            .iter()
            .filter(|&&b| b == b'\n')
            .count();
        while let Some(end) = text[at..].find('\n') {
            let l = text[at..at + end].trim();
            if !(l.is_empty() || l.starts_with('#')) {
                break;
            }
            at += end + 1;
            line += 1;
        }
        line
    };
    let csv_err = |e: csv::Error| TableError::Csv {
        path: path.to_owned(),
        line: e.position().map_or(0, |p| line_of(p.byte())),
        message: e.to_string(),
    };
    let mut records = reader.records();
    let header = match records.next() {
        None => {
            return Err(TableError::Empty {
                path: path.to_owned(),
            });
        }
        Some(r) => r.map_err(csv_err)?,
    };
    let hline = header.position().map_or(1, |p| line_of(p.byte()));
    let names: Vec<&str> = header.iter().collect();
    let index: Vec<Option<usize>> = INPUT_COLUMNS
        .iter()
        .map(|c| names.iter().position(|n| n == c))
        .collect();
    let unique = INPUT_COLUMNS
        .iter()
        .all(|c| names.iter().filter(|n| *n == c).count() == 1);
    let (Some(index), true) = (index.into_iter().collect::<Option<Vec<usize>>>(), unique) else {
        return Err(TableError::Header {
            path: path.to_owned(),
            line: hline,
            found: names.join(","),
        });
    };
    let extra_at: Vec<usize> = (0..names.len()).filter(|i| !index.contains(i)).collect();
    let mut table = RayTable {
        extra_columns: extra_at.iter().map(|&i| names[i].to_owned()).collect(),
        rows: Vec::new(),
    };
    for record in records {
        let record = record.map_err(csv_err)?;
        let line = record.position().map_or(0, |p| line_of(p.byte()));
        if record.len() != names.len() {
            return Err(TableError::Columns {
                path: path.to_owned(),
                line,
                expected: names.len(),
                found: record.len(),
            });
        }
        let mut v = [0.0; 6];
        for (k, &i) in index.iter().enumerate() {
            let f = &record[i];
            v[k] = f.parse::<f64>().map_err(|_| TableError::Number {
                path: path.to_owned(),
                line,
                column: INPUT_COLUMNS[k],
                value: f.to_owned(),
            })?;
        }
        table.rows.push(RayRow {
            line,
            origin: DVec3::new(v[0], v[1], v[2]),
            dir: DVec3::new(v[3], v[4], v[5]),
            extra: extra_at.iter().map(|&i| record[i].to_owned()).collect(),
        });
    }
    Ok(table)
}

/// Trace every row in parallel (rayon) in precision `R`; `tick` is called once per ray
/// (progress bars).
pub fn trace_rows<R: Real>(
    field: &dyn IndexField,
    settings: &TraceSettings,
    rows: &[RayRow],
    tick: &(dyn Fn() + Sync),
) -> Vec<RayResult> {
    rows.par_iter()
        .map(|row| {
            let res = trace_ray::<R>(field, settings, row.origin, row.dir);
            tick();
            res
        })
        .collect()
}

/// Counts and means over a traced table.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TableSummary {
    pub rays: usize,
    pub missed: usize,
    pub exited: usize,
    pub absorbed: usize,
    pub max_steps: usize,
    pub error: usize,
    /// Left the medium with an error estimate above the limit (`degraded`).
    pub degraded: usize,
    /// Mean steps and field evaluations over the rays that entered the medium.
    pub mean_steps: f64,
    pub mean_evals: f64,
}

impl TableSummary {
    pub fn of(results: &[RayResult]) -> Self {
        let mut s = TableSummary {
            rays: results.len(),
            ..Default::default()
        };
        let (mut steps, mut evals, mut entered) = (0u64, 0u64, 0u64);
        for r in results {
            match r.status {
                RayStatus::Missed => s.missed += 1,
                RayStatus::Exited => s.exited += 1,
                RayStatus::Absorbed => s.absorbed += 1,
                RayStatus::MaxSteps => s.max_steps += 1,
                RayStatus::Error => s.error += 1,
                RayStatus::Degraded => s.degraded += 1,
            }
            if r.steps > 0 {
                entered += 1;
                steps += u64::from(r.steps);
                evals += r.evals;
            }
        }
        if entered > 0 {
            s.mean_steps = steps as f64 / entered as f64;
            s.mean_evals = evals as f64 / entered as f64;
        }
        s
    }
}

fn result_values(r: &RayResult) -> [f64; 8] {
    [
        r.position.x,
        r.position.y,
        r.position.z,
        r.direction.x,
        r.direction.y,
        r.direction.z,
        r.opl,
        r.length,
    ]
}

fn row_values(row: &RayRow) -> [f64; 6] {
    [
        row.origin.x,
        row.origin.y,
        row.origin.z,
        row.dir.x,
        row.dir.y,
        row.dir.z,
    ]
}

/// A number in Rust's shortest round-trip form, with an exponent where that is shorter
/// (`1e-11`, not `0.00000000001`) and no `.0` on integers.
fn fmt_num(v: f64) -> String {
    let s = format!("{v:?}");
    match s.strip_suffix(".0") {
        Some(int) => int.to_owned(),
        None => s,
    }
}

/// Write a traced table: the ray columns, the passed-through columns, then the results.
/// CSV numbers are in Rust's shortest round-trip form; JSON is an array of objects keyed
/// by column name (non-finite numbers `null`, passed-through values as strings).
pub fn write_table(
    w: &mut dyn Write,
    format: TableFormat,
    table: &RayTable,
    results: &[RayResult],
) -> io::Result<()> {
    match format {
        TableFormat::Csv => {
            let mut out = csv::Writer::from_writer(w);
            let header = INPUT_COLUMNS
                .iter()
                .copied()
                .chain(table.extra_columns.iter().map(String::as_str))
                .chain(OUTPUT_COLUMNS);
            out.write_record(header)?;
            for (row, r) in table.rows.iter().zip(results) {
                let mut record: Vec<String> = row_values(row).map(fmt_num).to_vec();
                record.extend(row.extra.iter().cloned());
                record.push(r.status.name().to_owned());
                record.extend(result_values(r).map(fmt_num));
                record.push(r.steps.to_string());
                record.push(r.evals.to_string());
                out.write_record(&record)?;
            }
            out.flush()?;
        }
        TableFormat::Json => {
            use serde_json::{Map, Value};
            let num = |v: f64| serde_json::Number::from_f64(v).map_or(Value::Null, Value::Number);
            let rows: Vec<Value> = table
                .rows
                .iter()
                .zip(results)
                .map(|(row, r)| {
                    let mut o = Map::new();
                    for (name, v) in INPUT_COLUMNS.iter().zip(row_values(row)) {
                        o.insert((*name).to_owned(), num(v));
                    }
                    for (name, v) in table.extra_columns.iter().zip(&row.extra) {
                        o.insert(name.clone(), Value::String(v.clone()));
                    }
                    o.insert("status".into(), Value::String(r.status.name().into()));
                    for (name, v) in OUTPUT_COLUMNS[1..9].iter().zip(result_values(r)) {
                        o.insert((*name).to_owned(), num(v));
                    }
                    o.insert("steps".into(), Value::from(r.steps));
                    o.insert("evals".into(), Value::from(r.evals));
                    Value::Object(o)
                })
                .collect();
            serde_json::to_writer_pretty(&mut *w, &rows).map_err(io::Error::other)?;
            writeln!(w)?;
        }
    }
    Ok(())
}

/// Write a traced table to `path` through grin-output: a failed write leaves no partial
/// output, `-` is standard output, a device or FIFO is written into.
pub fn write_table_file(
    path: &Path,
    format: TableFormat,
    table: &RayTable,
    results: &[RayResult],
) -> Result<(), grin_output::OutputError> {
    grin_output::write_file(path, |w| write_table(w, format, table, results))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> &'static Path {
        Path::new("rays.csv")
    }

    fn missed(row: &RayRow) -> RayResult {
        RayResult {
            status: RayStatus::Missed,
            position: row.origin,
            direction: DVec3::Z,
            opl: 0.0,
            length: 0.0,
            steps: 0,
            evals: 0,
            transmittance: 1.0,
            error_estimate: 0.0,
        }
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
}
