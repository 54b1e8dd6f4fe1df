//! The sparse `.grinf` file (version 2): the same magic and checksum as the dense layout
//! (version 1), a header, the brick table, the brick records and the voxel pool, all
//! little-endian. docs/grinf.md documents it byte by byte.
//!
//! ```text
//! 0    magic "GRINF\0\0\0"
//! 8    u32 version = 2, u32 table offset (a multiple of 16)
//! 16   u32 bricks per axis x3, u32 active bricks, u32 storage (0 f32, 1 i16),
//!      u32 interp (0 trilinear, 1 tricubic Catmull-Rom: bricks with an apron, 2 the same
//!      with the gradient the derivative of the interpolated delta_n: a bake on its
//!      source's own lattice)
//! 40   f64 ambient index, f64 origin x3, f64 brick edge
//! 80   u32 bounds kind (0 sphere, 1 box), u32 0, f64 x6 (centre, radius, 0, 0 | min, max)
//! 136  f64 max and RMS |n error|, max and RMS |grad n error|
//! 168  u32 description bytes, u32 0; the description (UTF-8) follows at 176
//! table offset: u32 per top brick (x fastest): the active brick's number, 0xFFFFFFFF empty
//! then, at a multiple of 16: 16 bytes per active brick: u32 level, f32 scale of delta_n,
//!   f32 scale of the gradient (1, 1 for f32), u32 0
//! then, at a multiple of 16: the voxels of brick 0, 1, ... in order, each brick
//!   (cells + 1)^3 voxels x fastest ((cells + 3)^3 with interp 1 or 2: one node beyond each
//!   face), cells = LEVEL_CELLS[level] (4, 5, 6, 8, 10, 12, 16, 20, 24, 32, 40, 48, 64,
//!   80, 96, 128, 160, 192, 256), a voxel 4 f32 or 4 i16
//! last 4 bytes: CRC-32 of everything before them
//! ```
//!
//! A brick's position is where the table names it; its voxels start where the previous
//! brick's end.

use super::{Brick, EMPTY, MAX_LEVEL, Pool, SparseField, TopGrid, cells_of, nodes_of};
use crate::baked::{BakeProvenance, Storage};
use crate::field::IndexField;
use crate::grinf::{CRC_BYTES, DATA_ALIGN, GrinfError, MAGIC, MAX_DESCRIPTION_BYTES, Reader};

/// The sparse layout's version word.
pub const VERSION: u32 = 2;
/// Bytes of the fixed header (the description follows).
pub const FIXED_HEADER_BYTES: usize = 176;
/// Bytes of a brick record.
const RECORD_BYTES: usize = 16;
/// Most bricks a file's top grid may have (1024^3 table entries, 4 GiB).
const MAX_TABLE_ENTRIES: u64 = 1 << 30;

fn align(n: usize) -> usize {
    n.div_ceil(DATA_ALIGN) * DATA_ALIGN
}

/// A writer that keeps the CRC-32 of what passed through it.
struct Crc<W> {
    w: W,
    crc: crc32fast::Hasher,
    written: usize,
}

impl<W: std::io::Write> std::io::Write for Crc<W> {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        let n = self.w.write(b)?;
        self.crc.update(&b[..n]);
        self.written += n;
        Ok(n)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.w.flush()
    }
}

/// Write `field` to `w` in the version-2 layout, a part at a time (the voxels are never
/// copied into one buffer: a 10^8-voxel bake writes in its own memory).
pub fn write_to(field: &SparseField, w: &mut dyn std::io::Write) -> std::io::Result<()> {
    let top = field.top();
    let prov = field.provenance();
    let mut desc = prov.source.as_bytes().to_vec();
    desc.truncate(MAX_DESCRIPTION_BYTES);
    let table_offset = align(FIXED_HEADER_BYTES + desc.len());
    let records_offset = align(table_offset + 4 * field.table().len());
    let pool_offset = align(records_offset + RECORD_BYTES * field.bricks().len());
    let mut out = Crc {
        w: std::io::BufWriter::with_capacity(1 << 20, w),
        crc: crc32fast::Hasher::new(),
        written: 0,
    };
    let pad = |out: &mut Crc<_>, to: usize| -> std::io::Result<()> {
        let n = to - out.written;
        std::io::Write::write_all(out, &vec![0u8; n])
    };
    let mut b = Vec::with_capacity(FIXED_HEADER_BYTES);
    let u32s =
        |b: &mut Vec<u8>, v: &[u32]| v.iter().for_each(|x| b.extend_from_slice(&x.to_le_bytes()));
    let f64s =
        |b: &mut Vec<u8>, v: &[f64]| v.iter().for_each(|x| b.extend_from_slice(&x.to_le_bytes()));
    b.extend_from_slice(&MAGIC);
    u32s(&mut b, &[VERSION, table_offset as u32]);
    u32s(&mut b, &top.dims.map(|d| d as u32));
    let storage = match field.storage() {
        Storage::F32 => 0,
        Storage::I16 => 1,
    };
    let interp = u32::from(field.apron()) + u32::from(field.gradient_of_n());
    u32s(&mut b, &[field.bricks().len() as u32, storage, interp]);
    f64s(&mut b, &[field.ambient_index()]);
    f64s(&mut b, &top.origin.to_array());
    f64s(&mut b, &[top.edge]);
    crate::grinf::put_bounds_and_errors(&mut b, field.bounds(), prov);
    u32s(&mut b, &[desc.len() as u32, 0]);
    debug_assert_eq!(b.len(), FIXED_HEADER_BYTES);
    b.extend_from_slice(&desc);
    std::io::Write::write_all(&mut out, &b)?;
    pad(&mut out, table_offset)?;
    let mut table = Vec::with_capacity(4 * field.table().len());
    u32s(&mut table, field.table());
    std::io::Write::write_all(&mut out, &table)?;
    pad(&mut out, records_offset)?;
    for brick in field.bricks() {
        let mut r = Vec::with_capacity(RECORD_BYTES);
        u32s(&mut r, &[u32::from(brick.level)]);
        r.extend_from_slice(&brick.scale[0].to_le_bytes());
        r.extend_from_slice(&brick.scale[1].to_le_bytes());
        u32s(&mut r, &[0]);
        std::io::Write::write_all(&mut out, &r)?;
    }
    pad(&mut out, pool_offset)?;
    let mut chunk = Vec::with_capacity(1 << 16);
    match field.pool() {
        Pool::F32(v) => {
            for part in v.chunks(4096) {
                chunk.clear();
                part.iter()
                    .flatten()
                    .for_each(|x| chunk.extend_from_slice(&x.to_le_bytes()));
                std::io::Write::write_all(&mut out, &chunk)?;
            }
        }
        Pool::I16(v) => {
            for part in v.chunks(8192) {
                chunk.clear();
                part.iter()
                    .flatten()
                    .for_each(|x| chunk.extend_from_slice(&x.to_le_bytes()));
                std::io::Write::write_all(&mut out, &chunk)?;
            }
        }
    }
    let crc = out.crc.clone().finalize();
    std::io::Write::write_all(&mut out.w, &crc.to_le_bytes())?;
    std::io::Write::flush(&mut out.w)
}

/// Serialize a sparse field into memory ([`write_to`]).
pub fn to_bytes(field: &SparseField) -> Vec<u8> {
    let mut b = Vec::new();
    write_to(field, &mut b).expect("writing to memory cannot fail");
    b
}

/// Write `field` to `path`, staged and renamed into place (no partial file on failure).
pub fn save(field: &SparseField, path: &std::path::Path) -> Result<(), GrinfError> {
    Ok(grin_output::write_file(path, |w| write_to(field, w))?)
}

/// Parse a whole sparse `.grinf` image; every count is checked against the file's size
/// before anything is allocated, the checksum before anything is parsed.
pub fn from_bytes(b: &[u8], path: &str) -> Result<SparseField, GrinfError> {
    let header_err = |message: String| GrinfError::Header {
        path: path.into(),
        message,
    };
    let short = |expected: usize| GrinfError::Size {
        path: path.into(),
        expected: expected as u64,
        actual: b.len() as u64,
    };
    if b.len() < MAGIC.len() || b[..MAGIC.len()] != MAGIC {
        return Err(GrinfError::Magic {
            path: path.into(),
            found: b[..b.len().min(MAGIC.len())].to_vec(),
        });
    }
    if b.len() < FIXED_HEADER_BYTES + CRC_BYTES {
        return Err(short(FIXED_HEADER_BYTES + CRC_BYTES));
    }
    let mut r = Reader { b, at: MAGIC.len() };
    let version = r.u32();
    if version != VERSION {
        return Err(GrinfError::Version {
            path: path.into(),
            found: version,
        });
    }
    let table_offset = r.u32() as usize;
    let dims = [r.u32() as usize, r.u32() as usize, r.u32() as usize];
    let active = r.u32() as usize;
    let storage = r.storage().map_err(header_err)?;
    let (apron, gradient_of_n) = match r.u32() {
        0 => (0, false),
        1 => (1, false),
        2 => (1, true),
        s => {
            return Err(header_err(format!(
                "unknown interpolation code {s} (0 trilinear, 1 tricubic Catmull-Rom, 2 the same \
                 with the gradient of n)"
            )));
        }
    };
    let entries = dims.iter().map(|&d| d as u64).product::<u64>();
    if dims.contains(&0) || entries > MAX_TABLE_ENTRIES {
        return Err(header_err(format!(
            "a top grid of {dims:?} bricks (each axis at least 1, at most {MAX_TABLE_ENTRIES} in all)"
        )));
    }
    let entries = entries as usize;
    if active > entries {
        return Err(header_err(format!(
            "{active} active bricks in a top grid of {entries}"
        )));
    }
    if table_offset < FIXED_HEADER_BYTES || !table_offset.is_multiple_of(DATA_ALIGN) {
        return Err(header_err(format!("table offset {table_offset}")));
    }
    let records_offset = align(table_offset + 4 * entries);
    let pool_offset = align(records_offset + RECORD_BYTES * active);
    if b.len() < pool_offset + CRC_BYTES {
        return Err(short(pool_offset + CRC_BYTES));
    }
    // The levels give the pool's size.
    let mut levels = Vec::with_capacity(active);
    let mut voxels = 0u64;
    for i in 0..active {
        let at = records_offset + RECORD_BYTES * i;
        let level = u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]);
        if level > u32::from(MAX_LEVEL) {
            return Err(header_err(format!(
                "brick {i} has level {level} (at most {MAX_LEVEL})"
            )));
        }
        levels.push(level as u8);
        voxels += (nodes_of(cells_of(level as u8), apron) as u64).pow(3);
    }
    let expected =
        pool_offset as u64 + voxels * storage.bytes_per_voxel() as u64 + CRC_BYTES as u64;
    crate::grinf::check_size_and_checksum(b, path, expected)?;
    let body = b.len() - CRC_BYTES;
    let ambient = r.f64();
    let origin = r.dvec3();
    let edge = r.f64();
    let top = TopGrid { origin, edge, dims };
    let (bounds, bv) = r.bounds().map_err(header_err)?;
    if !bv.iter().all(|v| v.is_finite()) {
        return Err(header_err(format!("bounds {bv:?} are not finite")));
    }
    let (max_err_n, rms_err_n, max_err_grad, rms_err_grad) = r.errors().map_err(header_err)?;
    let desc_len = r.u32() as usize;
    if FIXED_HEADER_BYTES + desc_len > table_offset {
        return Err(header_err(format!(
            "description of {desc_len} bytes does not fit before the table at {table_offset}"
        )));
    }
    let source =
        String::from_utf8_lossy(&b[FIXED_HEADER_BYTES..FIXED_HEADER_BYTES + desc_len]).into_owned();
    let table: Vec<u32> = b[table_offset..table_offset + 4 * entries]
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    // Each brick's place is where the table names it.
    let mut at = vec![None; active];
    for (idx, &e) in table.iter().enumerate() {
        if e == EMPTY {
            continue;
        }
        let Some(slot) = at.get_mut(e as usize) else {
            return Err(header_err(format!("the table names brick {e} of {active}")));
        };
        if slot.is_some() {
            return Err(header_err(format!("brick {e} appears twice in the table")));
        }
        *slot = Some(top.at(idx).map(|a| a as u32));
    }
    let mut bricks = Vec::with_capacity(active);
    let mut offset = 0usize;
    for (i, (&level, place)) in levels.iter().zip(&at).enumerate() {
        let Some(place) = place else {
            return Err(header_err(format!("brick {i} is not in the table")));
        };
        let rec = records_offset + RECORD_BYTES * i;
        let f = |o: usize| f32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]);
        let brick = Brick {
            at: *place,
            level,
            offset,
            scale: [f(rec + 4), f(rec + 8)],
            apron,
        };
        offset += brick.voxel_count();
        bricks.push(brick);
    }
    let data = &b[pool_offset..body];
    let pool = match storage {
        Storage::F32 => Pool::F32(
            data.chunks_exact(16)
                .map(|v| {
                    std::array::from_fn(|c| {
                        f32::from_le_bytes([v[4 * c], v[4 * c + 1], v[4 * c + 2], v[4 * c + 3]])
                    })
                })
                .collect(),
        ),
        Storage::I16 => Pool::I16(
            data.chunks_exact(8)
                .map(|v| {
                    std::array::from_fn(|c| {
                        i16::from_le_bytes([v[2 * c], v[2 * c + 1]]).max(-i16::MAX)
                    })
                })
                .collect(),
        ),
    };
    SparseField::new(
        top,
        table,
        bricks,
        pool,
        bounds,
        ambient,
        BakeProvenance {
            source,
            max_err_n,
            rms_err_n,
            max_err_grad,
            rms_err_grad,
        },
    )
    .and_then(|f| f.with_apron(apron))
    .and_then(|f| f.with_gradient_of_n(gradient_of_n))
    .map_err(header_err)
}
