//! A content-addressed cache of the GPU's field bakes, so a second `grin render` or
//! `grin view` of the same medium uploads a grid from disk instead of baking it again.
//!
//! The key is a SHA-256 over everything the bake depends on: the `[medium]` table as the
//! scene states it (bounds, ambient index, field kind and every parameter, `t`), the
//! bytes of every file it names (a VDB cache, a `.grinf`), the GPU bake policy (its
//! resolution cap and error budget) and this crate's version. Entries are `.grinf` files
//! with a small JSON beside them (the key they were stored under, the grid's size and
//! checksum, the format version, the bake's warnings), written through grin-output (no
//! partial file is ever visible), in `$GRIN_CACHE_DIR`, else `$XDG_CACHE_HOME/grin/bakes`,
//! else `$HOME/.cache/grin/bakes`. Past [`CACHE_CAP_BYTES`] the least recently used
//! entries are removed.
//!
//! The cache trusts nothing it reads: an entry is used only when its JSON names the key
//! asked for, the grid's own checksum verifies and equals the one the JSON recorded, and
//! the grid's bounds and ambient index are the medium's. Anything else (a corrupt file,
//! another scene's bake put in its place, two writers that crossed) is a miss that bakes
//! again and replaces the entry, with a warning saying why.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use grin_field::IndexField;
use grin_field::baked::Interp;
use grin_field::sparse::SparseField;
use grin_scene::MediumSpec;
use sha2::{Digest, Sha256};

use crate::GpuError;
use crate::field::{
    DEFAULT_GPU_BAKE_RESOLUTION, FIELD_TEXEL_BYTES, GpuGrid, bake_for_gpu_auto, bake_warning,
};

/// Total size of the cache's entries kept on disk.
pub const CACHE_CAP_BYTES: u64 = 4 << 30;

/// What an entry's JSON records beside its grid.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
struct EntryMeta {
    /// The key the entry was stored under.
    key: String,
    /// The grid file's size and its CRC-32 (the one in its own trailer).
    bytes: u64,
    crc32: u32,
    /// The .grinf format version of the grid.
    grinf_version: u32,
    /// The bake's warnings.
    warnings: Vec<String>,
}

/// What the cache did for one field.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, strum::IntoStaticStr)]
#[serde(rename_all = "kebab-case")]
#[strum(serialize_all = "kebab-case")]
pub enum CacheUse {
    /// Read from the cache: no bake.
    Hit,
    /// Baked and stored.
    Stored,
    /// Baked; the cache was off (or could not be written: a warning says why).
    Off,
}

/// A directory of cached GPU bakes.
#[derive(Debug, Clone)]
pub struct BakeCache {
    dir: PathBuf,
}

impl BakeCache {
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        BakeCache { dir: dir.into() }
    }

    /// The user's cache: `$GRIN_CACHE_DIR`, `$XDG_CACHE_HOME/grin/bakes` or
    /// `$HOME/.cache/grin/bakes`; `None` when none of them is set.
    pub fn user_default() -> Option<Self> {
        let env = |k: &str| {
            std::env::var_os(k)
                .filter(|v| !v.is_empty())
                .map(PathBuf::from)
        };
        env("GRIN_CACHE_DIR")
            .or_else(|| env("XDG_CACHE_HOME").map(|d| d.join("grin").join("bakes")))
            .or_else(|| env("HOME").map(|d| d.join(".cache").join("grin").join("bakes")))
            .map(Self::new)
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Where the driver's pipeline caches are kept beside the bakes
    /// ([`crate::pipeline_cache`]).
    pub fn pipeline_dir(&self) -> PathBuf {
        self.dir.join("pipelines")
    }

    /// The key of the GPU bake of `medium` (files resolved against `scene_dir`): 64 hex
    /// digits. Errors when a file the medium names cannot be read.
    pub fn key(medium: &MediumSpec, scene_dir: &Path) -> Result<String, GpuError> {
        let mut h = Sha256::new();
        h.update(b"grin-gpu bake cache v8\0");
        h.update(env!("CARGO_PKG_VERSION").as_bytes());
        h.update(format!("\0res={DEFAULT_GPU_BAKE_RESOLUTION}\0").as_bytes());
        h.update(format!("budget={}\0", grin_field::bake::DEFAULT_ERROR_BUDGET).as_bytes());
        let spec = serde_json::to_string(medium)
            .map_err(|e| GpuError::Bake(format!("the medium's cache key: {e}")))?;
        h.update(spec.as_bytes());
        if let Some(f) = medium.field.file() {
            let path = scene_dir.join(f);
            let bytes = std::fs::read(&path).map_err(|e| {
                GpuError::Bake(format!(
                    "{}: reading it for the bake cache: {e}",
                    path.display()
                ))
            })?;
            h.update(b"\0file\0");
            h.update((bytes.len() as u64).to_le_bytes());
            h.update(&bytes);
        }
        Ok(h.finalize().iter().map(|b| format!("{b:02x}")).collect())
    }

    fn grid_path(&self, key: &str) -> PathBuf {
        self.dir.join(format!("{key}.grinf"))
    }

    fn warnings_path(&self, key: &str) -> PathBuf {
        self.dir.join(format!("{key}.json"))
    }

    /// The cached bake under `key` (its warnings with it): `Ok(None)` when there is no
    /// entry, `Err(why)` when there is one that cannot be trusted (see the module's
    /// notes); the caller bakes again either way.
    pub fn get(&self, key: &str) -> Result<Option<(GpuGrid, Vec<String>)>, String> {
        let grid = self.grid_path(key);
        let meta_path = self.warnings_path(key);
        if !grid.is_file() && !meta_path.is_file() {
            return Ok(None);
        }
        let bad = |why: String| format!("the cached bake {} {why}", grid.display());
        let meta: EntryMeta = std::fs::read(&meta_path)
            .map_err(|e| e.to_string())
            .and_then(|b| serde_json::from_slice(&b).map_err(|e| e.to_string()))
            .map_err(|e| bad(format!("has no readable record ({e})")))?;
        if meta.key != key {
            return Err(bad(format!("was stored under another key ({})", meta.key)));
        }
        // One read of the grid, checked and parsed from the same bytes: a writer that
        // replaces the file between a check and a second read would pair this record with
        // another bake (a test with two writers caught exactly that).
        let name = grid.display().to_string();
        let bytes = std::fs::read(&grid).map_err(|e| bad(e.to_string()))?;
        let (crc32, file_bytes, version) = identity(&bytes);
        if (crc32, file_bytes, version) != (meta.crc32, meta.bytes, meta.grinf_version) {
            return Err(bad(format!(
                "is not the grid its record names (checksum {crc32:#010x} of {file_bytes} \
                 bytes, recorded {:#010x} of {} bytes)",
                meta.crc32, meta.bytes
            )));
        }
        // Either layout; each parser checks the checksum and every count itself.
        let baked = if version == grin_field::sparse::file::VERSION {
            GpuGrid::Sparse(Arc::new(
                grin_field::sparse::file::from_bytes(&bytes, &name)
                    .map_err(|e| bad(e.to_string()))?,
            ))
        } else {
            GpuGrid::Dense(Arc::new(
                grin_field::grinf::from_bytes(&bytes, &name).map_err(|e| bad(e.to_string()))?,
            ))
        };
        // Touch for least-recently-used eviction.
        let _ = std::fs::File::options()
            .append(true)
            .open(&grid)
            .and_then(|f| f.set_modified(std::time::SystemTime::now()));
        Ok(Some((baked, meta.warnings)))
    }

    /// Store a bake under `key`, then trim the cache to [`CACHE_CAP_BYTES`]. The grid is
    /// written first, its record last: a record names the checksum of the grid it was
    /// written with, so writers that cross leave an entry [`BakeCache::get`] refuses, never
    /// one that mixes two bakes.
    pub fn put(&self, key: &str, grid: &GpuGrid, warnings: &[String]) -> Result<(), String> {
        std::fs::create_dir_all(&self.dir)
            .map_err(|e| format!("{}: cannot create the bake cache: {e}", self.dir.display()))?;
        let bytes = match grid {
            GpuGrid::Dense(b) => grin_field::grinf::to_bytes(b),
            GpuGrid::Sparse(s) => grin_field::sparse::file::to_bytes(s),
        };
        let (crc32, file_bytes, version) = identity(&bytes);
        let meta = EntryMeta {
            key: key.to_owned(),
            bytes: file_bytes,
            crc32,
            grinf_version: version,
            warnings: warnings.to_vec(),
        };
        let json = serde_json::to_vec(&meta).map_err(|e| e.to_string())?;
        grin_output::write_file(&self.grid_path(key), |w| w.write_all(&bytes))
            .map_err(|e| e.to_string())?;
        grin_output::write_file(&self.warnings_path(key), |w| w.write_all(&json))
            .map_err(|e| e.to_string())?;
        self.trim(CACHE_CAP_BYTES);
        Ok(())
    }

    /// Remove the least recently used entries until the grids total at most `cap` bytes.
    pub fn trim(&self, cap: u64) {
        let Ok(dir) = std::fs::read_dir(&self.dir) else {
            return;
        };
        let mut grids: Vec<(std::time::SystemTime, u64, PathBuf)> = dir
            .filter_map(|e| e.ok())
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|x| x == "grinf"))
            .filter_map(|p| {
                let m = p.metadata().ok()?;
                Some((m.modified().ok()?, m.len(), p))
            })
            .collect();
        grids.sort();
        let mut total: u64 = grids.iter().map(|g| g.1).sum();
        for (_, len, path) in grids {
            if total <= cap {
                break;
            }
            let _ = std::fs::remove_file(path.with_extension("json"));
            if std::fs::remove_file(&path).is_ok() {
                total -= len;
            }
        }
    }
}

/// A .grinf image's checksum (its last 4 bytes), length and version word (0 for an image
/// too short to hold them): what a cache record names its grid by.
fn identity(bytes: &[u8]) -> (u32, u64, u32) {
    let n = bytes.len();
    if n < 16 {
        return (0, n as u64, 0);
    }
    let crc = u32::from_le_bytes([bytes[n - 4], bytes[n - 3], bytes[n - 2], bytes[n - 1]]);
    let version = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]);
    (crc, n as u64, version)
}

/// A dense GPU grid that misses the budget is followed by a sparse bake only where at least
/// this share of its macro cells is homogeneous: a medium mostly ambient (plumes in a large
/// box), where sparse bricks pay; noise filling its bounds would only spend the time.
pub const SPARSE_WHEN_HOMOGENEOUS: f64 = 0.5;

/// The GPU's grid for `field`. Data on an axis-aligned lattice (a VDB grid): Catmull-Rom
/// bricks on that lattice, which interpolate what the source interpolates at about its own
/// voxel count, if they meet the default budget within the cap. Else the coarsest dense
/// grid meeting the budget ([`bake_for_gpu_auto`]); where the best dense grid within the
/// GPU's cap misses it (not because it reached a grid source's own voxels) and is mostly
/// homogeneous ([`SPARSE_WHEN_HOMOGENEOUS`]), a sparse bake at the default budget whose
/// f32 upload fits the same cap, if it meets the budget. The warnings are the kept dense
/// bake's.
pub fn bake_for_gpu_grid(field: &dyn IndexField) -> Result<(GpuGrid, Vec<String>), GpuError> {
    if field.source_lattice().is_some()
        && let Some(sparse) = sparse_for_gpu(field, Interp::Tricubic)
    {
        return Ok((GpuGrid::Sparse(Arc::new(sparse)), Vec::new()));
    }
    let (baked, report) = bake_for_gpu_auto(field).map_err(|e| GpuError::Bake(e.to_string()))?;
    if report.relative_error > grin_field::bake::DEFAULT_ERROR_BUDGET
        && !report.source_limited
        && report.homogeneous_cells >= SPARSE_WHEN_HOMOGENEOUS
    {
        // Trilinear first (8 reads a sample); where that misses the budget or the cap,
        // Catmull-Rom (64 reads, third order: far fewer nodes on smooth content).
        for interp in [Interp::Trilinear, Interp::Tricubic] {
            if let Some(sparse) = sparse_for_gpu(field, interp) {
                return Ok((GpuGrid::Sparse(Arc::new(sparse)), Vec::new()));
            }
        }
    }
    Ok((
        GpuGrid::Dense(Arc::new(baked)),
        bake_warning(&report).into_iter().collect(),
    ))
}

/// A sparse bake of `field` (`interp`) at the default budget, if it meets the budget and
/// its f32 upload fits the GPU's bake cap.
fn sparse_for_gpu(field: &dyn IndexField, interp: Interp) -> Option<SparseField> {
    let opts = grin_field::sparse::bake::SparseOptions {
        // i16 on the host; on the device f32 texels where it lacks rgba16snorm: half the
        // cap on the host.
        max_memory: grin_field::bake::device::GPU_BAKE_MAX_BYTES / 2,
        interp,
        ..Default::default()
    };
    let (sparse, r) = grin_field::sparse::bake::bake_sparse(field, &opts, &|_, _, _| {}).ok()?;
    let bytes = (sparse.pool().len() + sparse.table().len()) as u64 * FIELD_TEXEL_BYTES;
    (r.meets_budget && bytes <= grin_field::bake::device::GPU_BAKE_MAX_BYTES).then_some(sparse)
}

/// A field baked for the GPU ([`bake_for_gpu_grid`]), read from `cache` under `key` when
/// it is there, else baked and stored. The warnings are the bake's (an under-resolved
/// grid) plus, when the cache could not be written, why.
pub fn gpu_bake_cached(
    field: &dyn IndexField,
    cache: Option<(&BakeCache, &str)>,
) -> Result<(GpuGrid, Vec<String>, CacheUse), GpuError> {
    let mut distrusted = None;
    if let Some((c, key)) = cache {
        match c.get(key) {
            Ok(Some((baked, warnings))) if same_medium(&baked, field) => {
                return Ok((baked, warnings, CacheUse::Hit));
            }
            Ok(Some(_)) => {
                distrusted = Some(format!(
                    "the cached bake under {key} is of other bounds or another ambient index \
                     than the medium"
                ));
            }
            Ok(None) => {}
            Err(why) => distrusted = Some(why),
        }
    }
    let (baked, mut warnings) = bake_for_gpu_grid(field)?;
    let used = match cache {
        Some((c, key)) => match c.put(key, &baked, &warnings) {
            Ok(()) => CacheUse::Stored,
            Err(why) => {
                warnings.push(format!("the GPU bake was not cached: {why}"));
                CacheUse::Off
            }
        },
        None => CacheUse::Off,
    };
    // Said now, not stored with the entry: the next use of it is a plain hit.
    if let Some(why) = distrusted {
        warnings.push(format!("{why}: baked again and replaced"));
    }
    Ok((baked, warnings, used))
}

/// Whether a cached grid is a bake of `field`'s medium: the same bounds and ambient index.
fn same_medium(grid: &GpuGrid, field: &dyn IndexField) -> bool {
    let baked = grid.field();
    baked.bounds() == field.bounds()
        && (baked.ambient_index() - field.ambient_index()).abs() <= 1e-12 * field.ambient_index()
}

/// The grid the GPU marches for `field`, the medium `spec` of a scene file (files
/// resolved against `scene_dir`): `None` when the field is a baked file (dense or sparse)
/// the renderer marches as it is; else the cached or new bake of the field
/// ([`gpu_bake_cached`]), through `cache` when given. Pass the grid to
/// [`crate::GpuRenderer::new`].
pub fn medium_gpu_grid(
    field: &dyn IndexField,
    spec: &MediumSpec,
    scene_dir: &Path,
    cache: Option<&BakeCache>,
) -> Result<Option<(GpuGrid, Vec<String>, CacheUse)>, GpuError> {
    if field.as_baked().is_some() || field.as_sparse().is_some() {
        return Ok(None);
    }
    let key = cache.map(|_| BakeCache::key(spec, scene_dir)).transpose()?;
    let cache = cache.zip(key.as_deref());
    gpu_bake_cached(field, cache).map(Some)
}

#[cfg(test)]
mod tests {
    use glam::DVec3;
    use grin_field::Bounds;
    use grin_field::analytic::Luneburg;
    use grin_field::bake::{BakeOptions, bake};

    use super::*;

    fn lens(radius: f64) -> Luneburg {
        let bounds = Bounds::Sphere {
            center: DVec3::ZERO,
            radius,
        };
        Luneburg::new(bounds, 1.0, None).expect("lens")
    }

    fn small_bake(field: &dyn IndexField) -> GpuGrid {
        let opts = BakeOptions {
            resolution: Some(10),
            error_points: 50,
            ..Default::default()
        };
        GpuGrid::Dense(Arc::new(
            bake(field, &opts, &|_: &str, _: u64, _: u64| {})
                .expect("bake")
                .0,
        ))
    }

    /// Two writers storing different bakes under one key while a reader reads it: every
    /// hit the reader gets pairs a grid with its own record (the bake's warnings come from
    /// the record, its bounds from the grid), and every other read is a miss or a refusal,
    /// never a mix.
    #[test]
    fn concurrent_writers_never_mix_an_entry() {
        let dir = tempfile::tempdir().expect("tmp");
        let cache = BakeCache::new(dir.path());
        let (a, b) = (small_bake(&lens(1.0)), small_bake(&lens(2.0)));
        let (mut hits, mut refused, mut reads) = (0, 0, 0);
        let finished = std::sync::atomic::AtomicUsize::new(0);
        std::thread::scope(|s| {
            for (bake, tag) in [(&a, "a"), (&b, "b")] {
                let (cache, finished) = (&cache, &finished);
                s.spawn(move || {
                    for _ in 0..30 {
                        cache.put("k", bake, &[tag.to_owned()]).expect("put");
                    }
                    finished.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                });
            }
            while finished.load(std::sync::atomic::Ordering::SeqCst) < 2 {
                reads += 1;
                match cache.get("k") {
                    Ok(Some((baked, warnings))) => {
                        hits += 1;
                        let want = if warnings == ["a"] { &a } else { &b };
                        assert!(warnings == ["a"] || warnings == ["b"], "{warnings:?}");
                        assert_eq!(
                            baked.field().bounds(),
                            want.field().bounds(),
                            "a grid with another's record"
                        );
                    }
                    Ok(None) => {}
                    Err(_) => refused += 1,
                }
            }
        });
        // (Hits during the race vary with timing, 9 .. 137 in 15 runs here; before `get`
        // read the grid once, 4 runs in 10 paired a record with the other writer's grid.)
        eprintln!("concurrent writers: {hits} hits, {refused} refused of {reads} reads");
        // Whatever the last two writes left, one more put makes the entry whole again.
        cache.put("k", &a, &["a".to_owned()]).expect("put");
        let (_, warnings) = cache.get("k").expect("verifies").expect("hit");
        assert_eq!(warnings, ["a"]);
    }

    /// The cache verifies what it reads: another scene's valid bake put in place of an
    /// entry, or an entry copied under another key, is refused with the reason (and
    /// `gpu_bake_cached` bakes again with a warning); a bake of other bounds under the
    /// right key and checksum is not used either.
    #[test]
    fn entries_that_lie_are_misses_with_a_reason() {
        let dir = tempfile::tempdir().expect("tmp");
        let cache = BakeCache::new(dir.path());
        let (a, b) = (small_bake(&lens(1.0)), small_bake(&lens(2.0)));
        assert!(cache.get("ka").expect("no entry").is_none());
        cache.put("ka", &a, &["wa".into()]).expect("put");
        cache.put("kb", &b, &[]).expect("put");
        let (got, warnings) = cache.get("ka").expect("verifies").expect("hit");
        assert_eq!(got.field().bounds(), a.field().bounds());
        assert_eq!(warnings, ["wa"]);

        // Another scene's valid bake in place of the grid.
        std::fs::copy(dir.path().join("kb.grinf"), dir.path().join("ka.grinf")).expect("cp");
        let e = cache.get("ka").expect_err("lies");
        assert!(e.contains("is not the grid its record names"), "{e}");
        // The whole entry of another key copied under this one.
        std::fs::copy(dir.path().join("kb.json"), dir.path().join("ka.json")).expect("cp");
        let e = cache.get("ka").expect_err("lies");
        assert!(e.contains("was stored under another key (kb)"), "{e}");
        // A record that is not JSON.
        std::fs::write(dir.path().join("ka.json"), b"\0junk").expect("write");
        let e = cache.get("ka").expect_err("junk");
        assert!(e.contains("has no readable record"), "{e}");

        // Through gpu_bake_cached: a verified entry of other bounds is baked again, with
        // a warning, and the entry is replaced so the next call hits.
        let field = lens(1.0);
        cache.put("kc", &b, &[]).expect("put");
        let (baked, warnings, used) = gpu_bake_cached(&field, Some((&cache, "kc"))).expect("bakes");
        assert_eq!(used, CacheUse::Stored);
        assert_eq!(baked.field().bounds(), field.bounds());
        assert!(
            warnings
                .iter()
                .any(|w| w.contains("other bounds") && w.contains("baked again and replaced")),
            "{warnings:?}"
        );
        let (_, warnings, used) = gpu_bake_cached(&field, Some((&cache, "kc"))).expect("hit");
        assert_eq!(used, CacheUse::Hit);
        assert!(
            !warnings.iter().any(|w| w.contains("baked again")),
            "{warnings:?}"
        );
    }
}
