//! Ray tables for `grin trace`: read the input CSV (`ox,oy,oz,dx,dy,dz`, in any order, and
//! any other columns, which are passed through), trace every ray in parallel, and write
//! the table back as CSV or JSON with the result columns
//! `status,px,py,pz,qx,qy,qz,opl,length,steps,evals` (docs/architecture.md, "Ray tables").
//! CSV through the `csv` crate (quoting, `#` comments, a UTF-8 BOM), JSON through
//! serde_json; `-` reads standard input.
//!
//! Tables stream: [`RayReader`] hands out batches of rows and [`TableWriter`] writes each
//! batch's results as it comes, so the cost is linear in the rows and the memory follows a
//! batch, not the table (a million rows trace in the memory of [`BATCH_ROWS`]).
//!
//! Over 600 lines: one concept, a ray table from its rows to its results (its tests in
//! `table/tests.rs`).

use std::collections::VecDeque;
use std::io::{self, BufRead, Write};
use std::path::{Path, PathBuf};

use glam::DVec3;
use grin_field::{IndexField, Real};
use rayon::prelude::*;

use crate::trace::{RayResult, RayStatus, trace_ray};
use grin_render::settings::TraceSettings;

/// The input columns, in order.
pub const INPUT_COLUMNS: [&str; 6] = ["ox", "oy", "oz", "dx", "dy", "dz"];
/// The result columns appended to the input columns.
pub const OUTPUT_COLUMNS: [&str; 11] = [
    "status", "px", "py", "pz", "qx", "qy", "qz", "opl", "length", "steps", "evals",
];
/// How many lines a warning about a table's rows names.
pub const LINES_NAMED: usize = 5;
/// Rows read, traced and written at a time by a streaming trace.
pub const BATCH_ROWS: usize = 1 << 16;

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

/// The input with its blank lines and `#` comment lines (outside quoted fields) left out,
/// a leading UTF-8 BOM dropped, and the file's line number of every line it passes on
/// kept, so the csv reader's line numbers map back to the file's. The map holds only the
/// lines the reader has not yet reported on.
#[derive(Debug)]
struct LineFilter<R> {
    inner: R,
    /// The passed line being handed out, and how much of it is gone.
    line: Vec<u8>,
    at: usize,
    /// Lines of the file read so far.
    read_lines: usize,
    /// Bytes of the file read so far.
    read_bytes: u64,
    /// Inside a quoted field that runs on past a line end.
    in_quotes: bool,
    /// File line of each passed line, from passed line `first_passed` (1-based) on.
    lines: VecDeque<usize>,
    first_passed: usize,
    /// `#` lines skipped after the header, and the first few of their file lines.
    comments_after_header: usize,
    comment_lines: Vec<usize>,
}

impl<R: BufRead> LineFilter<R> {
    fn new(inner: R) -> Self {
        LineFilter {
            inner,
            line: Vec::new(),
            at: 0,
            read_lines: 0,
            read_bytes: 0,
            in_quotes: false,
            lines: VecDeque::new(),
            first_passed: 1,
            comments_after_header: 0,
            comment_lines: Vec::new(),
        }
    }

    /// The file's line of the csv reader's line `passed` (1-based); 0 where unknown.
    fn file_line(&self, passed: u64) -> usize {
        let k = (passed as usize).checked_sub(self.first_passed);
        k.and_then(|k| self.lines.get(k)).copied().unwrap_or(0)
    }

    /// Forget the lines before the reader's line `passed`.
    fn forget_before(&mut self, passed: u64) {
        while self.first_passed < passed as usize && self.lines.len() > 1 {
            self.lines.pop_front();
            self.first_passed += 1;
        }
    }

    /// Read file lines until one is to be passed on (into `self.line`); false at the end.
    fn next_line(&mut self) -> io::Result<bool> {
        loop {
            self.line.clear();
            self.at = 0;
            let n = self.inner.read_until(b'\n', &mut self.line)?;
            if n == 0 {
                return Ok(false);
            }
            self.read_bytes += n as u64;
            self.read_lines += 1;
            if self.read_lines == 1 && self.line.starts_with("\u{feff}".as_bytes()) {
                self.line.drain(..3);
            }
            let starts_quoted = self.in_quotes;
            // `""` inside a quoted field toggles twice: the parity of quotes is the state.
            let quotes = self.line.iter().filter(|&&b| b == b'"').count();
            self.in_quotes ^= quotes % 2 == 1;
            if !starts_quoted {
                let text = self.line.trim_ascii();
                if text.is_empty() {
                    continue;
                }
                if text.starts_with(b"#") {
                    // After the header: some line was passed on already.
                    if !self.lines.is_empty() || self.first_passed > 1 {
                        self.comments_after_header += 1;
                        if self.comment_lines.len() < LINES_NAMED {
                            self.comment_lines.push(self.read_lines);
                        }
                    }
                    continue;
                }
            }
            self.lines.push_back(self.read_lines);
            return Ok(true);
        }
    }
}

impl<R: BufRead> io::Read for LineFilter<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if self.at == self.line.len() && !self.next_line()? {
            return Ok(0);
        }
        let n = buf.len().min(self.line.len() - self.at);
        buf[..n].copy_from_slice(&self.line[self.at..self.at + n]);
        self.at += n;
        Ok(n)
    }
}

/// A ray table read a batch of rows at a time: linear in the rows, its memory that of a
/// batch. Blank lines and lines starting with `#` are skipped. `nan`/`inf` values parse
/// (those rays trace as `error`); text that is not a number and rows with the wrong number
/// of columns are errors naming the line.
#[derive(Debug)]
pub struct RayReader<R: io::Read> {
    csv: csv::Reader<LineFilter<io::BufReader<R>>>,
    path: PathBuf,
    /// Where each of [`INPUT_COLUMNS`] is in a record.
    index: [usize; 6],
    /// Where each extra column is in a record.
    extra_at: Vec<usize>,
    width: usize,
    extra_columns: Vec<String>,
    replaced_columns: Vec<String>,
    record: csv::StringRecord,
}

impl RayReader<Box<dyn io::Read>> {
    /// Open a ray table file, or standard input for `-`, and read its header.
    pub fn open(path: &Path) -> Result<Self, TableError> {
        let input: Box<dyn io::Read> = if path.as_os_str() == "-" {
            Box::new(io::stdin())
        } else {
            Box::new(std::fs::File::open(path).map_err(|err| TableError::Read {
                path: path.to_owned(),
                err,
            })?)
        };
        RayReader::new(input, path)
    }
}

impl<R: io::Read> RayReader<R> {
    /// Read the header from `input` (`path` only names it in errors).
    pub fn new(input: R, path: &Path) -> Result<Self, TableError> {
        let filter = LineFilter::new(io::BufReader::with_capacity(1 << 16, input));
        let mut csv = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .flexible(true)
            .has_headers(false)
            .from_reader(filter);
        let mut header = csv::StringRecord::new();
        let got = csv.read_record(&mut header);
        let mut reader = RayReader {
            csv,
            path: path.to_owned(),
            index: [0; 6],
            extra_at: Vec::new(),
            width: 0,
            extra_columns: Vec::new(),
            replaced_columns: Vec::new(),
            record: csv::StringRecord::new(),
        };
        if !got.map_err(|e| reader.csv_err(e))? {
            return Err(TableError::Empty {
                path: path.to_owned(),
            });
        }
        let hline = reader.line_of(&header).max(1);
        let names: Vec<&str> = header.iter().collect();
        let index: Option<Vec<usize>> = INPUT_COLUMNS
            .iter()
            .map(|c| names.iter().position(|n| n == c))
            .collect();
        let unique = INPUT_COLUMNS
            .iter()
            .all(|c| names.iter().filter(|n| *n == c).count() == 1);
        let (Some(index), true) = (index, unique) else {
            return Err(TableError::Header {
                path: path.to_owned(),
                line: hline,
                found: names.join(","),
            });
        };
        reader.index.copy_from_slice(&index);
        // A column named as a result (an earlier trace's output read back) is replaced by
        // this trace's result, not passed through: each column is written once.
        let result = |i: &usize| OUTPUT_COLUMNS.contains(&names[*i]);
        reader.replaced_columns = (0..names.len())
            .filter(|i| !index.contains(i) && result(i))
            .map(|i| names[i].to_owned())
            .collect();
        reader.extra_at = (0..names.len())
            .filter(|i| !index.contains(i) && !result(i))
            .collect();
        reader.extra_columns = reader
            .extra_at
            .iter()
            .map(|&i| names[i].to_owned())
            .collect();
        reader.width = names.len();
        Ok(reader)
    }

    /// The names of the columns that are not ray inputs, passed through to the output.
    pub fn extra_columns(&self) -> &[String] {
        &self.extra_columns
    }

    /// The input's columns named as results ([`OUTPUT_COLUMNS`]): not passed through, this
    /// trace's results replace them.
    pub fn replaced_columns(&self) -> &[String] {
        &self.replaced_columns
    }

    /// Bytes of the input read so far (for progress).
    pub fn bytes_read(&self) -> u64 {
        self.csv.get_ref().read_bytes
    }

    /// The `#` lines skipped after the header so far, and the file lines of the first few
    /// ([`LINES_NAMED`]): a row whose first value starts with `#` reads as a comment.
    pub fn comments_after_header(&self) -> (usize, &[usize]) {
        let f = self.csv.get_ref();
        (f.comments_after_header, &f.comment_lines)
    }

    fn line_of(&self, record: &csv::StringRecord) -> usize {
        record
            .position()
            .map_or(0, |p| self.csv.get_ref().file_line(p.line()))
    }

    fn csv_err(&self, e: csv::Error) -> TableError {
        if let csv::ErrorKind::Io(err) = e.kind() {
            return TableError::Read {
                path: self.path.clone(),
                err: io::Error::new(err.kind(), err.to_string()),
            };
        }
        TableError::Csv {
            path: self.path.clone(),
            line: e
                .position()
                .map_or(0, |p| self.csv.get_ref().file_line(p.line())),
            message: e.to_string(),
        }
    }

    /// Append up to `max` rows to `out`; returns how many were appended (0 at the end).
    pub fn next_batch(&mut self, max: usize, out: &mut Vec<RayRow>) -> Result<usize, TableError> {
        let mut n = 0;
        while n < max {
            let mut record = std::mem::take(&mut self.record);
            let got = self.csv.read_record(&mut record);
            let got = got.map_err(|e| self.csv_err(e));
            self.record = record;
            if !got? {
                break;
            }
            let record = &self.record;
            let line = self.line_of(record);
            if let Some(p) = record.position() {
                self.csv.get_mut().forget_before(p.line());
            }
            if record.len() != self.width {
                return Err(TableError::Columns {
                    path: self.path.clone(),
                    line,
                    expected: self.width,
                    found: record.len(),
                });
            }
            let mut v = [0.0; 6];
            for (k, &i) in self.index.iter().enumerate() {
                let f = &record[i];
                v[k] = f.parse::<f64>().map_err(|_| TableError::Number {
                    path: self.path.clone(),
                    line,
                    column: INPUT_COLUMNS[k],
                    value: f.to_owned(),
                })?;
            }
            out.push(RayRow {
                line,
                origin: DVec3::new(v[0], v[1], v[2]),
                dir: DVec3::new(v[3], v[4], v[5]),
                extra: self
                    .extra_at
                    .iter()
                    .map(|&i| record[i].to_owned())
                    .collect(),
            });
            n += 1;
        }
        Ok(n)
    }

    /// Every remaining row.
    pub fn read_all(mut self) -> Result<RayTable, TableError> {
        let mut rows = Vec::new();
        while self.next_batch(BATCH_ROWS, &mut rows)? > 0 {}
        Ok(RayTable {
            extra_columns: self.extra_columns,
            rows,
        })
    }
}

/// Parse a ray table (`path` only names it in errors); see [`RayReader`].
pub fn parse_rays(text: &str, path: &Path) -> Result<RayTable, TableError> {
    RayReader::new(text.as_bytes(), path)?.read_all()
}

/// Rows a packet tracer takes from the table at a time (crate::packet): a quarter of
/// each thread's share, within these bounds. Its lanes idle while the last rays of a
/// chunk finish, so larger chunks waste less, and four chunks a thread keep the threads
/// evenly busy.
const PACKET_CHUNK: std::ops::RangeInclusive<usize> = 64..=1024;

/// Trace every row in parallel (rayon) in precision `R`: in packets
/// ([`crate::packet::trace_packets`], the same results) where the settings and the
/// precision (f64) allow, else ray by ray.
pub fn trace_rows<R: Real>(
    field: &dyn IndexField,
    settings: &TraceSettings,
    rows: &[RayRow],
) -> Vec<RayResult> {
    let mut out = Vec::new();
    trace_rows_into::<R>(field, settings, rows, &mut out);
    out
}

/// [`trace_rows`] into `out`, which ends with one result a row: a caller tracing batch
/// after batch passes the same vector, and no batch allocates or gathers its results
/// (each chunk of rows writes its own slice in place).
pub fn trace_rows_into<R: Real>(
    field: &dyn IndexField,
    settings: &TraceSettings,
    rows: &[RayRow],
    out: &mut Vec<RayResult>,
) {
    out.resize(rows.len(), crate::packet::untraced_result());
    if crate::packet::traced_in_packets::<R>(settings) {
        let share = rows.len() / (4 * rayon::current_num_threads());
        let chunk = share.clamp(*PACKET_CHUNK.start(), *PACKET_CHUNK.end());
        out.par_chunks_mut(chunk)
            .zip(rows.par_chunks(chunk))
            .for_each(|(out, rows)| {
                let rays: Vec<(DVec3, DVec3)> =
                    rows.iter().map(|row| (row.origin, row.dir)).collect();
                crate::packet::trace_packets_into(field, settings, &rays, out);
            });
    } else {
        out.par_iter_mut().zip(rows).for_each(|(out, row)| {
            *out = trace_ray::<R>(field, settings, row.origin, row.dir);
        });
    }
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
    /// Left the medium with an error estimate above the accuracy asked for (`degraded`).
    pub degraded: usize,
    /// The largest error estimate (rad) of an `exited` ray: what the table vouches for.
    pub worst_estimate: f64,
    /// Mean steps and field evaluations over the rays that entered the medium.
    pub mean_steps: f64,
    pub mean_evals: f64,
    /// Rays that entered the medium, their steps and evaluations (the means' sums).
    entered: u64,
    steps: u64,
    evals: u64,
}

impl TableSummary {
    /// Count a batch of results in.
    pub fn add(&mut self, results: &[RayResult]) {
        self.rays += results.len();
        for r in results {
            match r.status {
                RayStatus::Missed => self.missed += 1,
                RayStatus::Exited => {
                    self.exited += 1;
                    self.worst_estimate = self.worst_estimate.max(r.error_estimate);
                }
                RayStatus::Absorbed => self.absorbed += 1,
                RayStatus::MaxSteps => self.max_steps += 1,
                RayStatus::Error => self.error += 1,
                RayStatus::Degraded => self.degraded += 1,
            }
            if r.steps > 0 {
                self.entered += 1;
                self.steps += u64::from(r.steps);
                self.evals += r.evals;
            }
        }
        if self.entered > 0 {
            self.mean_steps = self.steps as f64 / self.entered as f64;
            self.mean_evals = self.evals as f64 / self.entered as f64;
        }
    }
}

/// A result's position, direction, optical path and length (the table's columns 1-8).
pub(crate) fn result_values(r: &RayResult) -> [f64; 8] {
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

/// A number in its shortest round-trip form, as Rust's `{:?}` writes it (an exponent
/// where that is shorter: `1e-11`, not `0.00000000001`) but with no `.0` on integers,
/// written into `buf`. `ryu` finds the digits several times faster than `{:?}`; between
/// 1e-5 and 1e-4, where it writes no exponent and Rust does, and for non-finite values,
/// Rust's own formatting writes them. Where the value lies exactly halfway between two
/// shortest forms (a value with a short exact binary fraction, such as 9803398934280.3125)
/// ryu picks the even last digit and Rust the upper one; either reads back as the same
/// number (tested).
fn fmt_num_into(buf: &mut String, v: f64, ryu: &mut ryu::Buffer) {
    use std::fmt::Write as _;
    buf.clear();
    if v.is_finite() && !(1e-5..1e-4).contains(&v.abs()) {
        buf.push_str(ryu.format_finite(v));
    } else {
        let _ = write!(buf, "{v:?}");
    }
    if buf.ends_with(".0") {
        buf.truncate(buf.len() - 2);
    }
}

/// Rows a table formats at a time (in parallel, [`TableWriter::rows`]).
const FORMAT_CHUNK: usize = 4096;

/// Write `rows` with their results as `format` gives each chunk of [`FORMAT_CHUNK`]
/// rows (from its index in `rows`), the chunks formatted in parallel, written in order.
fn write_in_chunks(
    w: &mut dyn Write,
    rows: &[RayRow],
    results: &[RayResult],
    format: impl Fn(usize, &[RayRow], &[RayResult]) -> io::Result<Vec<u8>> + Sync,
) -> io::Result<()> {
    let chunks = rows
        .par_chunks(FORMAT_CHUNK)
        .zip(results.par_chunks(FORMAT_CHUNK))
        .enumerate()
        .map(|(c, (rows, results))| format(c * FORMAT_CHUNK, rows, results))
        .collect::<io::Result<Vec<Vec<u8>>>>()?;
    for chunk in chunks {
        w.write_all(&chunk)?;
    }
    Ok(())
}

/// `rows` with their results as CSV records (no header).
fn csv_rows(rows: &[RayRow], results: &[RayResult]) -> io::Result<Vec<u8>> {
    let mut out = csv::Writer::from_writer(Vec::new());
    let (mut buf, mut ryu) = (String::new(), ryu::Buffer::new());
    for (row, r) in rows.iter().zip(results) {
        for v in row_values(row) {
            fmt_num_into(&mut buf, v, &mut ryu);
            out.write_field(&buf)?;
        }
        for v in &row.extra {
            out.write_field(v)?;
        }
        out.write_field(r.status.name())?;
        for v in result_values(r) {
            fmt_num_into(&mut buf, v, &mut ryu);
            out.write_field(&buf)?;
        }
        for count in [u64::from(r.steps), r.evals] {
            use std::fmt::Write as _;
            buf.clear();
            let _ = write!(buf, "{count}");
            out.write_field(&buf)?;
        }
        out.write_record(None::<&[u8]>)?;
    }
    out.into_inner()
        .map_err(|e| io::Error::other(e.to_string()))
}

/// Writes a traced table a batch at a time: [`TableWriter::rows`] for each batch, then
/// [`TableWriter::finish`]. CSV numbers are in their shortest round-trip form ([`fmt_num_into`]); JSON is an
/// array of objects keyed by column name (non-finite numbers `null`, passed-through values
/// as strings).
#[derive(Debug)]
pub struct TableWriter {
    format: TableFormat,
    extra_columns: Vec<String>,
    started: bool,
    rows: usize,
}

impl TableWriter {
    pub fn new(format: TableFormat, extra_columns: &[String]) -> Self {
        TableWriter {
            format,
            extra_columns: extra_columns.to_vec(),
            started: false,
            rows: 0,
        }
    }

    fn start(&mut self, w: &mut dyn Write) -> io::Result<()> {
        if self.started {
            return Ok(());
        }
        self.started = true;
        match self.format {
            TableFormat::Csv => {
                let mut out = csv::Writer::from_writer(&mut *w);
                let header = INPUT_COLUMNS
                    .iter()
                    .copied()
                    .chain(self.extra_columns.iter().map(String::as_str))
                    .chain(OUTPUT_COLUMNS);
                out.write_record(header)?;
                out.flush()
            }
            TableFormat::Json => w.write_all(b"["),
        }
    }

    /// Write a batch of rows with their results.
    pub fn rows(
        &mut self,
        w: &mut dyn Write,
        rows: &[RayRow],
        results: &[RayResult],
    ) -> io::Result<()> {
        self.start(w)?;
        match self.format {
            TableFormat::Csv => {
                write_in_chunks(w, rows, results, |_, rows, results| csv_rows(rows, results))?;
            }
            TableFormat::Json => {
                let before = self.rows;
                write_in_chunks(w, rows, results, |at, rows, results| {
                    self.json_rows(before + at, rows, results)
                })?;
                self.rows += rows.len();
            }
        }
        Ok(())
    }

    /// `rows` with their results as the table's JSON objects, indented, each after its
    /// separator (`first`: the table's index of the first of them).
    fn json_rows(
        &self,
        first: usize,
        rows: &[RayRow],
        results: &[RayResult],
    ) -> io::Result<Vec<u8>> {
        let mut out = Vec::new();
        for (i, (row, r)) in rows.iter().zip(results).enumerate() {
            let text =
                serde_json::to_string_pretty(&self.json_row(row, r)).map_err(io::Error::other)?;
            out.extend_from_slice(if first + i == 0 { b"\n" } else { b",\n" });
            for (k, line) in text.lines().enumerate() {
                if k > 0 {
                    out.push(b'\n');
                }
                out.extend_from_slice(b"  ");
                out.extend_from_slice(line.as_bytes());
            }
        }
        Ok(out)
    }

    fn json_row(&self, row: &RayRow, r: &RayResult) -> serde_json::Value {
        use serde_json::{Map, Value};
        let num = |v: f64| serde_json::Number::from_f64(v).map_or(Value::Null, Value::Number);
        let mut o = Map::new();
        for (name, v) in INPUT_COLUMNS.iter().zip(row_values(row)) {
            o.insert((*name).to_owned(), num(v));
        }
        for (name, v) in self.extra_columns.iter().zip(&row.extra) {
            o.insert(name.clone(), Value::String(v.clone()));
        }
        o.insert("status".into(), Value::String(r.status.name().into()));
        for (name, v) in OUTPUT_COLUMNS[1..9].iter().zip(result_values(r)) {
            o.insert((*name).to_owned(), num(v));
        }
        o.insert("steps".into(), Value::from(r.steps));
        o.insert("evals".into(), Value::from(r.evals));
        Value::Object(o)
    }

    /// End the table (the header alone where there were no rows).
    pub fn finish(mut self, w: &mut dyn Write) -> io::Result<()> {
        self.start(w)?;
        if self.format == TableFormat::Json {
            w.write_all(if self.rows == 0 { b"]\n" } else { b"\n]\n" })?;
        }
        w.flush()
    }
}

/// Write a whole traced table: the ray columns, the passed-through columns, then the
/// results (see [`TableWriter`]).
pub fn write_table(
    w: &mut dyn Write,
    format: TableFormat,
    table: &RayTable,
    results: &[RayResult],
) -> io::Result<()> {
    let mut out = TableWriter::new(format, &table.extra_columns);
    out.rows(w, &table.rows, results)?;
    out.finish(w)
}

#[cfg(test)]
mod tests;
