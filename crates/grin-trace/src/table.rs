//! Ray tables for `grin trace`: read the input CSV (`ox,oy,oz,dx,dy,dz`), trace every ray
//! in parallel, and write the table back as CSV or JSON with the result columns
//! `status,px,py,pz,qx,qy,qz,opl,length,steps,evals` (ARCHITECTURE.md, "Ray tables").

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
    #[error("{path}:{line}: header must be `ox,oy,oz,dx,dy,dz`, found `{found}`")]
    Header {
        path: PathBuf,
        line: usize,
        found: String,
    },
    #[error("{path}:{line}: expected 6 columns (ox,oy,oz,dx,dy,dz), found {found}")]
    Columns {
        path: PathBuf,
        line: usize,
        found: usize,
    },
    #[error("{path}:{line}: column `{column}`: `{value}` is not a number")]
    Number {
        path: PathBuf,
        line: usize,
        column: &'static str,
        value: String,
    },
}

/// One input ray and the line it came from (1-based).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayRow {
    pub line: usize,
    pub origin: DVec3,
    pub dir: DVec3,
}

/// Output format of a traced table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TableFormat {
    Csv,
    /// An array of objects, one per ray, keyed by the column names; non-finite numbers are `null`.
    Json,
}

/// Read a ray table file.
pub fn read_rays(path: &Path) -> Result<Vec<RayRow>, TableError> {
    let text = std::fs::read_to_string(path).map_err(|err| TableError::Read {
        path: path.to_owned(),
        err,
    })?;
    parse_rays(&text, path)
}

/// Parse a ray table (`path` only names it in errors). Blank lines and lines starting
/// with `#` are skipped. `nan`/`inf` values parse (those rays trace as `error`); text that
/// is not a number and rows with the wrong number of columns are errors naming the line.
pub fn parse_rays(text: &str, path: &Path) -> Result<Vec<RayRow>, TableError> {
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
    let Some((hline, header)) = lines.next() else {
        return Err(TableError::Empty {
            path: path.to_owned(),
        });
    };
    let header = header.trim_start_matches('\u{feff}');
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    if names != INPUT_COLUMNS {
        return Err(TableError::Header {
            path: path.to_owned(),
            line: hline,
            found: header.to_owned(),
        });
    }
    let mut rows = Vec::new();
    for (line, l) in lines {
        let fields: Vec<&str> = l.split(',').map(str::trim).collect();
        if fields.len() != INPUT_COLUMNS.len() {
            return Err(TableError::Columns {
                path: path.to_owned(),
                line,
                found: fields.len(),
            });
        }
        let mut v = [0.0; 6];
        for (k, f) in fields.iter().enumerate() {
            v[k] = f.parse::<f64>().map_err(|_| TableError::Number {
                path: path.to_owned(),
                line,
                column: INPUT_COLUMNS[k],
                value: (*f).to_owned(),
            })?;
        }
        rows.push(RayRow {
            line,
            origin: DVec3::new(v[0], v[1], v[2]),
            dir: DVec3::new(v[3], v[4], v[5]),
        });
    }
    Ok(rows)
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

/// Write a traced table. Numbers are printed in Rust's shortest round-trip form.
pub fn write_table(
    w: &mut dyn Write,
    format: TableFormat,
    rows: &[RayRow],
    results: &[RayResult],
) -> io::Result<()> {
    match format {
        TableFormat::Csv => {
            writeln!(
                w,
                "{},{}",
                INPUT_COLUMNS.join(","),
                OUTPUT_COLUMNS.join(",")
            )?;
            for (row, r) in rows.iter().zip(results) {
                for v in row_values(row) {
                    write!(w, "{},", fmt_num(v))?;
                }
                write!(w, "{}", r.status.name())?;
                for v in result_values(r) {
                    write!(w, ",{}", fmt_num(v))?;
                }
                writeln!(w, ",{},{}", r.steps, r.evals)?;
            }
        }
        TableFormat::Json => {
            let num = |v: f64| {
                if v.is_finite() {
                    format!("{v:?}")
                } else {
                    "null".to_owned()
                }
            };
            writeln!(w, "[")?;
            for (i, (row, r)) in rows.iter().zip(results).enumerate() {
                write!(w, "  {{")?;
                for (name, v) in INPUT_COLUMNS.iter().zip(row_values(row)) {
                    write!(w, "\"{name}\": {}, ", num(v))?;
                }
                write!(w, "\"status\": \"{}\"", r.status.name())?;
                for (name, v) in OUTPUT_COLUMNS[1..9].iter().zip(result_values(r)) {
                    write!(w, ", \"{name}\": {}", num(v))?;
                }
                let sep = if i + 1 < rows.len() { "," } else { "" };
                writeln!(w, ", \"steps\": {}, \"evals\": {}}}{sep}", r.steps, r.evals)?;
            }
            writeln!(w, "]")?;
        }
    }
    Ok(())
}

/// Write a traced table to `path` through grin-output: a failed write leaves no partial
/// output, `-` is standard output, a device or FIFO is written into.
pub fn write_table_file(
    path: &Path,
    format: TableFormat,
    rows: &[RayRow],
    results: &[RayResult],
) -> Result<(), grin_output::OutputError> {
    grin_output::write_file(path, |w| write_table(w, format, rows, results))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> &'static Path {
        Path::new("rays.csv")
    }

    #[test]
    fn parses_rows_and_skips_comments() {
        let rows = parse_rays(
            "ox, oy,oz,dx,dy,dz\n# c\n\n0,0,-3,0,0,1\n1e-3,2,3,nan,0,1\n",
            p(),
        )
        .expect("valid");
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[0].line, 4);
        assert_eq!(rows[0].origin, DVec3::new(0.0, 0.0, -3.0));
        assert_eq!(rows[1].line, 5);
        assert!(rows[1].dir.x.is_nan());
    }

    #[test]
    fn errors_name_file_and_line() {
        let e = parse_rays("", p()).expect_err("empty").to_string();
        assert!(e.starts_with("rays.csv: empty ray table"), "{e}");
        let e = parse_rays("x,y,z\n", p()).expect_err("header").to_string();
        assert_eq!(
            e,
            "rays.csv:1: header must be `ox,oy,oz,dx,dy,dz`, found `x,y,z`"
        );
        let e = parse_rays("ox,oy,oz,dx,dy,dz\n0,0,0,1,0,0\n0,0,0,1\n", p())
            .expect_err("cols")
            .to_string();
        assert_eq!(
            e,
            "rays.csv:3: expected 6 columns (ox,oy,oz,dx,dy,dz), found 4"
        );
        let e = parse_rays("ox,oy,oz,dx,dy,dz\n0,0,zero,1,0,0\n", p())
            .expect_err("num")
            .to_string();
        assert_eq!(e, "rays.csv:2: column `oz`: `zero` is not a number");
    }

    #[test]
    fn csv_and_json_output_columns() {
        let rows = parse_rays("ox,oy,oz,dx,dy,dz\n0,0,-3,0,0,2\n", p()).expect("valid");
        let res = RayResult {
            status: RayStatus::Missed,
            position: rows[0].origin,
            direction: DVec3::Z,
            opl: 0.0,
            length: 0.0,
            steps: 0,
            evals: 0,
            transmittance: 1.0,
        };
        let mut csv = Vec::new();
        write_table(&mut csv, TableFormat::Csv, &rows, &[res]).expect("write");
        let csv = String::from_utf8(csv).expect("utf8");
        assert_eq!(
            csv,
            "ox,oy,oz,dx,dy,dz,status,px,py,pz,qx,qy,qz,opl,length,steps,evals\n0,0,-3,0,0,2,missed,0,0,-3,0,0,1,0,0,0,0\n"
        );
        let mut json = Vec::new();
        write_table(&mut json, TableFormat::Json, &rows, &[res]).expect("write");
        let json = String::from_utf8(json).expect("utf8");
        assert!(
            json.contains("\"status\": \"missed\", \"px\": 0.0"),
            "{json}"
        );
        assert!(
            json.trim_end().ends_with("\"steps\": 0, \"evals\": 0}\n]"),
            "{json}"
        );
    }
}
