//! The `.grinf` baked-field file: a versioned, little-endian, CRC-32-checksummed header
//! (transform, ambient index, storage, scale, bounds, source, measured error) followed by
//! the voxels. The layout is documented in docs/grinf.md (with a numpy loader).
//!
//! One concept, one file: the dense layout's writer and its reader, which refuses what the
//! writer cannot have written.

use std::path::Path;

use glam::DVec3;

use crate::baked::{BakeProvenance, BakedField, GridGeometry, Interp, Outside, Storage, Voxels};
use crate::bounds::Bounds;
use crate::field::FieldError;

/// First 8 bytes of every .grinf file.
pub const MAGIC: [u8; 8] = *b"GRINF\0\0\0";
/// The format version this code writes and reads.
pub const VERSION: u32 = 1;
/// Bytes of the fixed part of the header (the description follows it).
pub const FIXED_HEADER_BYTES: usize = 208;
/// The voxel data starts at a multiple of this (so numpy/GPU views are aligned).
pub(crate) const DATA_ALIGN: usize = 16;
/// Bytes of the trailing CRC-32.
pub(crate) const CRC_BYTES: usize = 4;
/// Longest source description kept in the header.
pub(crate) const MAX_DESCRIPTION_BYTES: usize = 4096;

/// Why a .grinf file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum GrinfError {
    #[error("{path}: {}", grin_output::plain(err))]
    Io { path: String, err: std::io::Error },
    #[error(transparent)]
    Write(#[from] grin_output::OutputError),
    #[error("{path}: not a .grinf file (bad magic {found:?}, expected {MAGIC:?})")]
    Magic { path: String, found: Vec<u8> },
    #[error(
        "{path}: unsupported .grinf version {found} (this grin reads version {VERSION}, dense, and {}, sparse)",
        crate::sparse::file::VERSION
    )]
    Version { path: String, found: u32 },
    #[error("{path}: file is {actual} bytes but its header says {expected} (truncated or padded)")]
    Size {
        path: String,
        expected: u64,
        actual: u64,
    },
    #[error(
        "{path}: checksum mismatch (stored {stored:#010x}, computed {computed:#010x}): the file is corrupt"
    )]
    Checksum {
        path: String,
        stored: u32,
        computed: u32,
    },
    #[error(
        "{path}: a sparse .grinf (version 2), where only a dense grid is read here (renders and traces on both backends; `grin info`, `grin export` and Python's `grin.read_field` read it)"
    )]
    Sparse { path: String },
    #[error("{path}: bad header: {message}")]
    Header { path: String, message: String },
}

impl From<GrinfError> for FieldError {
    fn from(e: GrinfError) -> Self {
        match e {
            GrinfError::Io { path, err } => FieldError::File {
                path,
                message: grin_output::plain(&err),
            },
            other => FieldError::Other(other.to_string()),
        }
    }
}

/// The header of a .grinf file (everything but the voxels).
#[derive(Debug, Clone, PartialEq)]
pub struct GrinfHeader {
    pub version: u32,
    pub data_offset: usize,
    pub geometry: GridGeometry,
    pub storage: Storage,
    pub interp: Interp,
    pub outside: Outside,
    pub ambient: f64,
    pub scale: [f32; 4],
    pub bounds: Bounds,
    pub provenance: BakeProvenance,
    pub file_bytes: u64,
    pub crc32: u32,
}

/// Serialize a baked field to bytes.
pub fn to_bytes(field: &BakedField) -> Vec<u8> {
    let g = field.geometry();
    let prov = field.provenance();
    let mut desc = prov.source.as_bytes().to_vec();
    desc.truncate(MAX_DESCRIPTION_BYTES);
    let data_offset = (FIXED_HEADER_BYTES + desc.len()).div_ceil(DATA_ALIGN) * DATA_ALIGN;
    let mut b = Vec::with_capacity(data_offset + field.data_bytes() + CRC_BYTES);
    b.extend_from_slice(&MAGIC);
    let u32s =
        |b: &mut Vec<u8>, v: &[u32]| v.iter().for_each(|x| b.extend_from_slice(&x.to_le_bytes()));
    let f64s =
        |b: &mut Vec<u8>, v: &[f64]| v.iter().for_each(|x| b.extend_from_slice(&x.to_le_bytes()));
    u32s(&mut b, &[VERSION, data_offset as u32]);
    u32s(&mut b, &g.dims.map(|d| d as u32));
    let storage = match field.storage() {
        Storage::F32 => 0,
        Storage::I16 => 1,
    };
    let interp = match field.interp() {
        Interp::Trilinear => 0,
        Interp::Tricubic => 1,
    };
    let outside = match field.outside() {
        Outside::Clamp => 0,
        Outside::Ambient => 1,
    };
    u32s(&mut b, &[storage, interp, outside]);
    f64s(&mut b, &[crate::field::IndexField::ambient_index(field)]);
    f64s(&mut b, &g.origin.to_array());
    f64s(&mut b, &g.spacing.to_array());
    for s in field.voxels().scale() {
        b.extend_from_slice(&s.to_le_bytes());
    }
    put_bounds_and_errors(&mut b, crate::field::IndexField::bounds(field), prov);
    u32s(&mut b, &[desc.len() as u32, 0]);
    debug_assert_eq!(b.len(), FIXED_HEADER_BYTES);
    b.extend_from_slice(&desc);
    b.resize(data_offset, 0);
    match field.voxels() {
        Voxels::F32(v) => v
            .iter()
            .flatten()
            .for_each(|x| b.extend_from_slice(&x.to_le_bytes())),
        Voxels::I16 { data, .. } => data
            .iter()
            .flatten()
            .for_each(|x| b.extend_from_slice(&x.to_le_bytes())),
    }
    let crc = crc32fast::hash(&b);
    b.extend_from_slice(&crc.to_le_bytes());
    b
}

/// The header's bounds (kind, reserved word, 6 f64) and measured errors (4 f64), as both
/// layouts store them.
pub(crate) fn put_bounds_and_errors(b: &mut Vec<u8>, bounds: Bounds, prov: &BakeProvenance) {
    let (kind, v) = match bounds {
        Bounds::Sphere { center, radius } => {
            (0u32, [center.x, center.y, center.z, radius, 0.0, 0.0])
        }
        Bounds::Box { min, max } => (1, [min.x, min.y, min.z, max.x, max.y, max.z]),
    };
    b.extend_from_slice(&kind.to_le_bytes());
    b.extend_from_slice(&0u32.to_le_bytes());
    let errors = [
        prov.max_err_n,
        prov.rms_err_n,
        prov.max_err_grad,
        prov.rms_err_grad,
    ];
    for x in v.iter().chain(&errors) {
        b.extend_from_slice(&x.to_le_bytes());
    }
}

/// Write `field` to `path` through grin-output: staged, synced and renamed into place, so
/// an interrupted or failed write leaves no partial file.
pub fn save(field: &BakedField, path: &Path) -> Result<(), GrinfError> {
    let bytes = to_bytes(field);
    Ok(grin_output::write_file(path, |w| w.write_all(&bytes))?)
}

/// Read a .grinf file.
pub fn load(path: &Path) -> Result<BakedField, GrinfError> {
    let bytes = std::fs::read(path).map_err(|source| GrinfError::Io {
        path: path.display().to_string(),
        err: source,
    })?;
    from_bytes(&bytes, &path.display().to_string())
}

/// The field of a scene's `field = { kind = "baked", path }`: `path` is resolved against
/// `scene_dir`; the file's bounds and ambient index must match the scene's medium.
pub fn load_for_medium(
    path: &str,
    scene_dir: &Path,
    bounds: Bounds,
    ambient: f64,
) -> Result<Grinf, FieldError> {
    let full = scene_dir.join(path);
    let file = open(&full)?;
    let field: &dyn crate::field::IndexField = match &file {
        Grinf::Dense(f) => f,
        Grinf::Sparse(f) => f,
    };
    let name = full.display().to_string();
    let file_ambient = field.ambient_index();
    if (file_ambient - ambient).abs() > 1e-12 * ambient {
        return Err(FieldError::File {
            path: name,
            message: format!(
                "baked with ambient index {file_ambient}, but the scene's medium has {ambient}"
            ),
        });
    }
    let file_bounds = field.bounds();
    if file_bounds != bounds {
        return Err(FieldError::File {
            path: name,
            message: format!(
                "baked for bounds {file_bounds:?}, but the scene's medium has {bounds:?}"
            ),
        });
    }
    Ok(file)
}

/// The version word of a .grinf image (after its magic; at least 12 bytes).
pub(crate) fn version_of(b: &[u8]) -> u32 {
    u32::from_le_bytes([b[8], b[9], b[10], b[11]])
}

/// A `.grinf` file of either layout.
#[derive(Debug, Clone)]
pub enum Grinf {
    Dense(BakedField),
    Sparse(crate::sparse::SparseField),
}

impl Grinf {
    /// The field, to trace.
    pub fn into_field(self) -> std::sync::Arc<dyn crate::field::IndexField> {
        match self {
            Grinf::Dense(f) => std::sync::Arc::new(f),
            Grinf::Sparse(f) => std::sync::Arc::new(f),
        }
    }
}

/// Read a .grinf file, dense (version 1) or sparse (version 2).
pub fn open(path: &Path) -> Result<Grinf, GrinfError> {
    let bytes = std::fs::read(path).map_err(|source| GrinfError::Io {
        path: path.display().to_string(),
        err: source,
    })?;
    let name = path.display().to_string();
    if bytes.len() >= MAGIC.len() + 4
        && bytes[..MAGIC.len()] == MAGIC
        && version_of(&bytes) == crate::sparse::file::VERSION
    {
        return crate::sparse::file::from_bytes(&bytes, &name).map(Grinf::Sparse);
    }
    from_bytes(&bytes, &name).map(Grinf::Dense)
}

/// Both layouts' last checks before parsing: the file is `expected` bytes long and its
/// trailing CRC-32 is that of everything before it. Returns the stored checksum.
pub(crate) fn check_size_and_checksum(
    b: &[u8],
    path: &str,
    expected: u64,
) -> Result<u32, GrinfError> {
    if expected != b.len() as u64 {
        return Err(GrinfError::Size {
            path: path.into(),
            expected,
            actual: b.len() as u64,
        });
    }
    let body = b.len() - CRC_BYTES;
    let stored = u32::from_le_bytes([b[body], b[body + 1], b[body + 2], b[body + 3]]);
    let computed = crc32fast::hash(&b[..body]);
    if stored != computed {
        return Err(GrinfError::Checksum {
            path: path.into(),
            stored,
            computed,
        });
    }
    Ok(stored)
}

/// Read only the header of a .grinf file (still checks size and checksum).
pub fn read_header(path: &Path) -> Result<GrinfHeader, GrinfError> {
    let bytes = std::fs::read(path).map_err(|source| GrinfError::Io {
        path: path.display().to_string(),
        err: source,
    })?;
    parse_header(&bytes, &path.display().to_string())
}

/// Little-endian reader over the header.
pub(crate) struct Reader<'a> {
    pub(crate) b: &'a [u8],
    pub(crate) at: usize,
}

impl Reader<'_> {
    pub(crate) fn take<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0u8; N];
        out.copy_from_slice(&self.b[self.at..self.at + N]);
        self.at += N;
        out
    }
    pub(crate) fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take())
    }
    pub(crate) fn f32(&mut self) -> f32 {
        f32::from_le_bytes(self.take())
    }
    pub(crate) fn f64(&mut self) -> f64 {
        f64::from_le_bytes(self.take())
    }
    pub(crate) fn dvec3(&mut self) -> DVec3 {
        DVec3::new(self.f64(), self.f64(), self.f64())
    }
    /// A storage code (0 f32, 1 i16); an unknown code is the message's error.
    pub(crate) fn storage(&mut self) -> Result<Storage, String> {
        match self.u32() {
            0 => Ok(Storage::F32),
            1 => Ok(Storage::I16),
            s => Err(format!("unknown storage code {s}")),
        }
    }
    /// The bounds as [`put_bounds_and_errors`] wrote them (kind, reserved word, 6 f64),
    /// with the six stored values; an unknown kind is the message's error.
    pub(crate) fn bounds(&mut self) -> Result<(Bounds, [f64; 6]), String> {
        let kind = self.u32();
        let _reserved = self.u32();
        let v = [0; 6].map(|_| self.f64());
        match kind {
            0 => Ok((
                Bounds::Sphere {
                    center: DVec3::new(v[0], v[1], v[2]),
                    radius: v[3],
                },
                v,
            )),
            1 => Ok((
                Bounds::Box {
                    min: DVec3::new(v[0], v[1], v[2]),
                    max: DVec3::new(v[3], v[4], v[5]),
                },
                v,
            )),
            s => Err(format!("unknown bounds code {s}")),
        }
    }

    /// The measured errors as [`put_bounds_and_errors`] wrote them (max and RMS |n error|,
    /// max and RMS |grad n error|): each finite and not negative, else the message's error
    /// (a field's n uncertainty comes from them).
    pub(crate) fn errors(&mut self) -> Result<(f64, f64, f64, f64), String> {
        let e = [0; 4].map(|_| self.f64());
        if e.iter().all(|v| v.is_finite() && *v >= 0.0) {
            Ok((e[0], e[1], e[2], e[3]))
        } else {
            Err(format!(
                "measured errors {e:?} (max and RMS of n, then of grad n) must be finite and not negative"
            ))
        }
    }
}

/// Parse and validate the header: magic, version, size, checksum, then the fields.
pub fn parse_header(b: &[u8], path: &str) -> Result<GrinfHeader, GrinfError> {
    let header_err = |message: String| GrinfError::Header {
        path: path.into(),
        message,
    };
    if b.len() < MAGIC.len() || b[..MAGIC.len()] != MAGIC {
        return Err(GrinfError::Magic {
            path: path.into(),
            found: b[..b.len().min(MAGIC.len())].to_vec(),
        });
    }
    if b.len() >= MAGIC.len() + 4 && version_of(b) == crate::sparse::file::VERSION {
        return Err(GrinfError::Sparse { path: path.into() });
    }
    if b.len() < FIXED_HEADER_BYTES + CRC_BYTES {
        return Err(GrinfError::Size {
            path: path.into(),
            expected: (FIXED_HEADER_BYTES + CRC_BYTES) as u64,
            actual: b.len() as u64,
        });
    }
    let mut r = Reader { b, at: MAGIC.len() };
    let version = r.u32();
    if version != VERSION {
        return Err(GrinfError::Version {
            path: path.into(),
            found: version,
        });
    }
    let data_offset = r.u32() as usize;
    let dims = [r.u32() as usize, r.u32() as usize, r.u32() as usize];
    let storage = r.storage().map_err(header_err)?;
    let voxel_count = dims.iter().try_fold(1u64, |a, &d| a.checked_mul(d as u64));
    let expected = voxel_count
        .and_then(|n| n.checked_mul(storage.bytes_per_voxel() as u64))
        .and_then(|n| n.checked_add((data_offset + CRC_BYTES) as u64));
    let Some(expected) = expected else {
        return Err(header_err(format!("grid {dims:?} is too large")));
    };
    let stored = check_size_and_checksum(b, path, expected)?;
    let interp = match r.u32() {
        0 => Interp::Trilinear,
        1 => Interp::Tricubic,
        s => return Err(header_err(format!("unknown interpolation code {s}"))),
    };
    let outside = match r.u32() {
        0 => Outside::Clamp,
        1 => Outside::Ambient,
        s => return Err(header_err(format!("unknown outside code {s}"))),
    };
    let ambient = r.f64();
    let origin = r.dvec3();
    let spacing = r.dvec3();
    let scale = [r.f32(), r.f32(), r.f32(), r.f32()];
    let (bounds, _) = r.bounds().map_err(header_err)?;
    let (max_err_n, rms_err_n, max_err_grad, rms_err_grad) = r.errors().map_err(header_err)?;
    let desc_len = r.u32() as usize;
    if FIXED_HEADER_BYTES + desc_len > data_offset || !data_offset.is_multiple_of(DATA_ALIGN) {
        return Err(header_err(format!(
            "description of {desc_len} bytes does not fit before the data at {data_offset}"
        )));
    }
    let source =
        String::from_utf8_lossy(&b[FIXED_HEADER_BYTES..FIXED_HEADER_BYTES + desc_len]).into_owned();
    if !(ambient.is_finite() && ambient > 0.0) {
        return Err(header_err(format!(
            "ambient index {ambient} must be positive"
        )));
    }
    if !scale.iter().all(|s| s.is_finite() && *s > 0.0) {
        return Err(header_err(format!("scale {scale:?} must be positive")));
    }
    Ok(GrinfHeader {
        version,
        data_offset,
        geometry: GridGeometry {
            dims,
            origin,
            spacing,
        },
        storage,
        interp,
        outside,
        ambient,
        scale,
        bounds,
        provenance: BakeProvenance {
            source,
            max_err_n,
            rms_err_n,
            max_err_grad,
            rms_err_grad,
        },
        file_bytes: b.len() as u64,
        crc32: stored,
    })
}

/// Parse a whole .grinf image.
pub fn from_bytes(b: &[u8], path: &str) -> Result<BakedField, GrinfError> {
    let h = parse_header(b, path)?;
    let data = &b[h.data_offset..b.len() - CRC_BYTES];
    let voxels = match h.storage {
        Storage::F32 => Voxels::F32(
            data.chunks_exact(16)
                .map(|v| {
                    std::array::from_fn(|c| {
                        f32::from_le_bytes([v[4 * c], v[4 * c + 1], v[4 * c + 2], v[4 * c + 3]])
                    })
                })
                .collect(),
        ),
        Storage::I16 => Voxels::I16 {
            data: data
                .chunks_exact(8)
                .map(|v| {
                    std::array::from_fn(|c| {
                        i16::from_le_bytes([v[2 * c], v[2 * c + 1]]).max(-i16::MAX)
                    })
                })
                .collect(),
            scale: h.scale,
        },
    };
    let field = BakedField::new(
        h.geometry,
        voxels,
        h.interp,
        h.outside,
        h.bounds,
        h.ambient,
        h.provenance,
    )
    .map_err(|e| GrinfError::Header {
        path: path.into(),
        message: e.to_string(),
    })?;
    check_whole(&field).map_err(|message| GrinfError::Header {
        path: path.into(),
        message,
    })?;
    Ok(field)
}

/// Correlation above which the stored gradient and the differences of the stored index
/// are taken to be the same field, so their ratio measures the grid's spacing.
const SAME_FIELD_CORRELATION: f64 = 0.9;
/// How far that ratio may stray from 1 (a resolved bake: within a few percent).
const SPACING_RATIO_LIMIT: f64 = 1.25;
/// A grid whose measured RMS gradient error is at most this fraction of its gradient's
/// RMS claims to resolve its field.
const RESOLVED_GRAD_ERROR: f64 = 0.1;
/// Most interior nodes sampled for the spacing check.
const SPACING_SAMPLES: usize = 1 << 20;

/// What a CRC cannot catch: a header whose numbers are consistent with the payload's
/// size but not with its content. A grid that clamps beyond its nodes must cover the
/// bounds it claims; and the stored gradient must be the gradient of the stored index at
/// the stored spacing (a wrong spacing, or dims permuted over the same payload, would
/// otherwise give confident, wrong exits). Only a grid that claims to resolve its field
/// is judged (its header's RMS gradient error at most [`RESOLVED_GRAD_ERROR`] of the
/// stored gradient's RMS): an under-resolved bake's node gradients are sharper than its
/// node differences (a VDB fire at 1.35x), and a field too fine for its grid (noise under
/// the spacing) correlates poorly.
fn check_whole(field: &BakedField) -> Result<(), String> {
    let g = field.geometry();
    if field.outside() == Outside::Clamp {
        let (lo, hi) = g.world_box();
        let (b_lo, b_hi) = crate::field::IndexField::bounds(field).aabb();
        let slack = 1e-6 * g.spacing.max_element();
        if !(lo.cmple(b_lo + slack).all() && hi.cmpge(b_hi - slack).all()) {
            return Err(format!(
                "the grid {lo} .. {hi} does not cover the bounds {b_lo} .. {b_hi} it claims \
                 (a clamped grid must)"
            ));
        }
    }
    let [nx, ny, nz] = g.dims;
    if nx < 3 || ny < 3 || nz < 3 {
        return Ok(());
    }
    let interior = (nx - 2) * (ny - 2) * (nz - 2);
    let stride = interior.div_ceil(SPACING_SAMPLES).max(1);
    let v = field.voxels();
    let h = g.spacing.to_array();
    // Per axis: sums of fd*g, g*g, fd*fd.
    let mut sums = [[0.0f64; 3]; 3];
    let mut count = 0usize;
    let mut k = 0usize;
    while k < interior {
        let (i, j, l) = (
            1 + k % (nx - 2),
            1 + (k / (nx - 2)) % (ny - 2),
            1 + k / ((nx - 2) * (ny - 2)),
        );
        let c = v.get(g.index(i, j, l));
        let steps = [[1, 0, 0], [0, 1, 0], [0, 0, 1]];
        for (a, d) in steps.iter().enumerate() {
            let up = v.get(g.index(i + d[0], j + d[1], l + d[2]))[0];
            let down = v.get(g.index(i - d[0], j - d[1], l - d[2]))[0];
            let fd = (f64::from(up) - f64::from(down)) / (2.0 * h[a]);
            let gs = f64::from(c[1 + a]);
            sums[a][0] += fd * gs;
            sums[a][1] += gs * gs;
            sums[a][2] += fd * fd;
        }
        count += 1;
        k += stride;
    }
    let rms_g = (sums.iter().map(|s| s[1]).sum::<f64>() / count.max(1) as f64).sqrt();
    // (A NaN claim claims nothing.)
    let claimed = field.provenance().rms_err_grad;
    if claimed.is_nan() || claimed > RESOLVED_GRAD_ERROR * rms_g {
        return Ok(());
    }
    let energy = sums.iter().map(|s| s[1]).fold(0.0, f64::max);
    for (a, [fg, gg, ff]) in sums.into_iter().enumerate() {
        // An axis along which the index hardly changes says nothing about its spacing.
        if !(gg > 1e-6 * energy && gg > 0.0 && ff > 0.0) {
            continue;
        }
        let correlation = fg / (gg * ff).sqrt();
        let ratio = fg / gg;
        if correlation > SAME_FIELD_CORRELATION
            && !(1.0 / SPACING_RATIO_LIMIT..=SPACING_RATIO_LIMIT).contains(&ratio)
        {
            return Err(format!(
                "the stored gradient along {} is {:.3}x the differences of the stored index at \
                 the grid spacing {}: the spacing or dims do not match the data",
                ["x", "y", "z"][a],
                1.0 / ratio,
                h[a]
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
