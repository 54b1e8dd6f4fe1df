//! A content-addressed cache of the GPU's field bakes, so a second `grin render` or
//! `grin view` of the same medium uploads a grid from disk instead of baking it again.
//!
//! The key is a SHA-256 over everything the bake depends on: the `[medium]` table as the
//! scene states it (bounds, ambient index, field kind and every parameter, `t`), the
//! bytes of every file it names (a VDB cache, a `.grinf`), the GPU bake policy (its
//! resolution cap and error budget) and this crate's version. Entries are `.grinf` files
//! with a small JSON beside them (the bake's warnings), written through grin-output (no
//! partial file is ever visible), in `$GRIN_CACHE_DIR`, else `$XDG_CACHE_HOME/grin/bakes`,
//! else `$HOME/.cache/grin/bakes`. Past [`CACHE_CAP_BYTES`] the least recently used
//! entries are removed. A corrupt entry is baked again and replaced.

use std::path::{Path, PathBuf};

use grin_field::IndexField;
use grin_field::baked::BakedField;
use grin_scene::{FieldSpec, MediumSpec};
use sha2::{Digest, Sha256};

use crate::GpuError;
use crate::field::{DEFAULT_GPU_BAKE_RESOLUTION, bake_for_gpu_auto, bake_warning};

/// Total size of the cache's entries kept on disk.
pub const CACHE_CAP_BYTES: u64 = 4 << 30;

/// What the cache did for one field.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
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
        h.update(b"grin-gpu bake cache v4\0");
        h.update(env!("CARGO_PKG_VERSION").as_bytes());
        h.update(format!("\0res={DEFAULT_GPU_BAKE_RESOLUTION}\0").as_bytes());
        h.update(format!("budget={}\0", grin_field::bake::DEFAULT_ERROR_BUDGET).as_bytes());
        let spec = serde_json::to_string(medium)
            .map_err(|e| GpuError::Bake(format!("the medium's cache key: {e}")))?;
        h.update(spec.as_bytes());
        let file = match &medium.field {
            FieldSpec::Vdb(v) => Some(&v.path),
            FieldSpec::Baked { path, .. } => Some(path),
            _ => None,
        };
        if let Some(f) = file {
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

    /// The cached bake under `key`, if there is a readable one (its warnings with it).
    pub fn get(&self, key: &str) -> Option<(BakedField, Vec<String>)> {
        let grid = self.grid_path(key);
        if !grid.is_file() {
            return None;
        }
        let baked = grin_field::grinf::load(&grid).ok()?;
        let warnings = std::fs::read(self.warnings_path(key))
            .ok()
            .and_then(|b| serde_json::from_slice::<Vec<String>>(&b).ok())?;
        // Touch for least-recently-used eviction.
        let _ = std::fs::File::options()
            .append(true)
            .open(&grid)
            .and_then(|f| f.set_modified(std::time::SystemTime::now()));
        Some((baked, warnings))
    }

    /// Store a bake under `key`, then trim the cache to [`CACHE_CAP_BYTES`].
    pub fn put(&self, key: &str, baked: &BakedField, warnings: &[String]) -> Result<(), String> {
        std::fs::create_dir_all(&self.dir)
            .map_err(|e| format!("{}: cannot create the bake cache: {e}", self.dir.display()))?;
        let json = serde_json::to_vec(warnings).map_err(|e| e.to_string())?;
        // Warnings first: an entry counts once its grid is there.
        grin_output::write_file(&self.warnings_path(key), |w| w.write_all(&json))
            .map_err(|e| e.to_string())?;
        grin_field::grinf::save(baked, &self.grid_path(key)).map_err(|e| e.to_string())?;
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

/// A field baked for the GPU (the coarsest grid meeting the error budget, as
/// [`bake_for_gpu_auto`]), read from `cache` under `key` when it is there, else baked and
/// stored. The warnings are the bake's (an under-resolved grid) plus, when the cache
/// could not be written, why.
pub fn gpu_bake_cached(
    field: &dyn IndexField,
    cache: Option<(&BakeCache, &str)>,
) -> Result<(BakedField, Vec<String>, CacheUse), GpuError> {
    if let Some((c, key)) = cache
        && let Some((baked, warnings)) = c.get(key)
    {
        return Ok((baked, warnings, CacheUse::Hit));
    }
    let (baked, report) = bake_for_gpu_auto(field).map_err(|e| GpuError::Bake(e.to_string()))?;
    let mut warnings: Vec<String> = bake_warning(&report).into_iter().collect();
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
    Ok((baked, warnings, used))
}

/// The grid the GPU marches for `scene`, whose medium is the scene file's `medium`
/// (files resolved against `scene_dir`): `None` when there is no medium or the field is a
/// baked file the renderer marches as it is; else the cached or new bake of the field
/// ([`gpu_bake_cached`]), through `cache` when given. Pass the grid to
/// [`crate::GpuRenderer::new`].
pub fn scene_gpu_field(
    scene: &grin_render::scene::RenderScene,
    medium: Option<&MediumSpec>,
    scene_dir: &Path,
    cache: Option<&BakeCache>,
) -> Result<Option<(BakedField, Vec<String>, CacheUse)>, GpuError> {
    let (Some(m), Some(spec)) = (&scene.medium, medium) else {
        return Ok(None);
    };
    if m.field.as_baked().is_some() {
        return Ok(None);
    }
    let key = cache.map(|_| BakeCache::key(spec, scene_dir)).transpose()?;
    let cache = cache.zip(key.as_deref());
    gpu_bake_cached(m.field.as_ref(), cache).map(Some)
}
