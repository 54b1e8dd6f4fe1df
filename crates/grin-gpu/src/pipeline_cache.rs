//! wgpu's pipeline cache, kept on disk between runs where the adapter supports it
//! (`Features::PIPELINE_CACHE`: Vulkan adapters), so a second `grin render` or `grin view`
//! hands the driver what it compiled the first time.
//!
//! One file per adapter (named by `wgpu::util::pipeline_cache_key`: vendor and device) in
//! `pipelines/` of the bake cache's directory ([`crate::cache::BakeCache::user_default`]).
//! The file is grin's own envelope around the bytes `PipelineCache::get_data` returned: a
//! magic, the SHA-256 of those bytes, then the bytes. Only bytes whose checksum matches are
//! handed back to wgpu, so what it reads is exactly what it wrote; wgpu then checks its own
//! header (adapter, driver version) and, with `fallback`, starts an empty cache when the
//! data does not fit this driver. A missing, truncated or foreign file is an empty cache,
//! never an error. Written through grin-output (no partial file is ever visible) after each
//! compile that grew the cache.
//!
//! `wgpu::Device::create_pipeline_cache` is grin-gpu's one `unsafe` call: its
//! contract (the data came from `get_data`) cannot be checked by the type system, only by
//! the checksum above.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use sha2::{Digest, Sha256};

/// The envelope's first bytes.
const MAGIC: &[u8; 8] = b"GRINPLC1";
const HEADER_BYTES: usize = MAGIC.len() + 32;

/// The driver's pipeline cache of one device and the file it is kept in.
#[derive(Debug)]
pub struct DiskPipelineCache {
    cache: wgpu::PipelineCache,
    path: PathBuf,
    /// Length of the data last read or written: a compile that did not grow the cache
    /// does not rewrite the file.
    stored_len: Mutex<usize>,
    /// Bytes handed to wgpu at start (0: the cache started empty).
    pub loaded_bytes: usize,
}

/// The directory of pipeline caches beside the bake cache: `pipelines/` under
/// `$GRIN_CACHE_DIR`, `$XDG_CACHE_HOME/grin/bakes` or `$HOME/.cache/grin/bakes`.
pub fn user_default_dir() -> Option<PathBuf> {
    crate::cache::BakeCache::user_default().map(|c| c.pipeline_dir())
}

/// The envelope of `data` as written to disk.
fn encode(data: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER_BYTES + data.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&Sha256::digest(data));
    out.extend_from_slice(data);
    out
}

/// The data inside an envelope, if the magic and checksum match.
fn decode(file: &[u8]) -> Option<&[u8]> {
    if file.len() < HEADER_BYTES || &file[..MAGIC.len()] != MAGIC {
        return None;
    }
    let (sum, data) = file[MAGIC.len()..].split_at(32);
    (Sha256::digest(data).as_slice() == sum).then_some(data)
}

impl DiskPipelineCache {
    /// The pipeline cache of `device` (created with `Features::PIPELINE_CACHE`), started
    /// from the file for `info`'s adapter in `dir` when there is a valid one. `None` when
    /// the adapter's backend keeps no cache data (wgpu knows no key for it).
    pub fn open(device: &wgpu::Device, info: &wgpu::AdapterInfo, dir: &Path) -> Option<Self> {
        let key = wgpu::util::pipeline_cache_key(info)?;
        let path = dir.join(format!("{key}.bin"));
        let file = std::fs::read(&path).unwrap_or_default();
        let data = decode(&file);
        let cache = create(device, data);
        let loaded_bytes = data.map_or(0, <[u8]>::len);
        Some(DiskPipelineCache {
            cache,
            path,
            stored_len: Mutex::new(loaded_bytes),
            loaded_bytes,
        })
    }

    /// The cache to pass in a pipeline descriptor.
    pub fn cache(&self) -> &wgpu::PipelineCache {
        &self.cache
    }

    /// The file the cache is kept in.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Write the cache's data to its file if it grew since it was read or last written.
    /// Failures are ignored: the cache only saves time.
    pub fn persist(&self) {
        let Some(data) = self.cache.get_data() else {
            return;
        };
        let Ok(mut stored) = self.stored_len.lock() else {
            return;
        };
        if data.len() == *stored {
            return;
        }
        let Some(dir) = self.path.parent() else {
            return;
        };
        let bytes = encode(&data);
        if std::fs::create_dir_all(dir).is_ok()
            && grin_output::write_file(&self.path, |w| w.write_all(&bytes)).is_ok()
        {
            *stored = data.len();
        }
    }
}

/// The pipeline cache of `device`, holding `data` when given.
#[expect(
    unsafe_code,
    reason = "wgpu's only way to seed a pipeline cache; the contract is kept by `decode`"
)]
fn create(device: &wgpu::Device, data: Option<&[u8]>) -> wgpu::PipelineCache {
    // SAFETY: `data` passed `decode`: it is byte for byte what `PipelineCache::get_data`
    // returned when `persist` wrote the file (magic and SHA-256 of the bytes checked), in
    // the file named by this adapter's `pipeline_cache_key`. wgpu validates its own header
    // inside (adapter, driver version, length) and `fallback: true` turns data it cannot
    // use into an empty cache.
    unsafe {
        device.create_pipeline_cache(&wgpu::PipelineCacheDescriptor {
            label: Some("grin pipelines"),
            data,
            fallback: true,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_intact_envelopes_give_back_their_data() {
        let data = b"driver bytes".to_vec();
        let file = encode(&data);
        assert_eq!(decode(&file), Some(&data[..]));
        // Empty data is an intact envelope too.
        assert_eq!(decode(&encode(&[])), Some(&[][..]));
        // One flipped bit anywhere, a cut or an extra byte: nothing reaches wgpu.
        for i in 0..file.len() {
            let mut bad = file.clone();
            bad[i] ^= 1;
            assert_eq!(decode(&bad), None, "bit flipped in byte {i}");
        }
        assert_eq!(decode(&file[..file.len() - 1]), None);
        let mut longer = file.clone();
        longer.push(0);
        assert_eq!(decode(&longer), None);
        assert_eq!(decode(&file[..HEADER_BYTES - 1]), None);
        assert_eq!(decode(b""), None);
    }
}
