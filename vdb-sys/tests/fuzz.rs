//! A bounded fuzz loop: truncations and bit flips of the fixture files go through the
//! reader (open, list, dense reads); every outcome must be Ok or a typed error with a
//! message: no panic, no crash, no unwinding C++ exception.
//!
//! Runs for [`DEFAULT_FUZZ_SECONDS`] in `cargo test` (CI); set `GRIN_FUZZ_SECONDS` for a
//! longer campaign.

use std::path::Path;
use std::time::{Duration, Instant};

use vdb_sys::VdbFile;

/// Time budget of the loop in the normal test run.
const DEFAULT_FUZZ_SECONDS: f64 = 6.0;
/// Dense reads of mutated files are capped low: a flipped bit may inflate a bounding box.
const FUZZ_CAP_BYTES: u64 = 64 << 20;
/// The header region covered by systematic truncations, and the step between cuts.
const HEADER_BYTES: usize = 512;
const HEADER_STEP: usize = 32;
const FIXTURES: [&str; 4] = [
    "test/aniso.vdb",
    "test/nonfinite.vdb",
    "test/empty_grid.vdb",
    "houdini_pyro.vdb",
];

/// xorshift64*: deterministic, dependency-free.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Everything a user's command could do with a file.
fn exercise(path: &Path) -> Result<usize, String> {
    let f = VdbFile::open(path).map_err(|e| e.to_string())?;
    let mut voxels = 0;
    for g in f.grids() {
        let Some(bbox) = g.active_bbox else { continue };
        if g.kind.is_scalar() {
            match f.read_scalar(&g.name, bbox, FUZZ_CAP_BYTES) {
                Ok(d) => voxels += d.values.len(),
                Err(e) => assert!(!e.to_string().is_empty()),
            }
        } else if g.kind.is_vec3() {
            match f.read_vec3(&g.name, bbox, FUZZ_CAP_BYTES) {
                Ok(d) => voxels += d.values.len(),
                Err(e) => assert!(!e.to_string().is_empty()),
            }
        }
    }
    Ok(voxels)
}

#[test]
fn truncations_and_bit_flips_never_crash_the_reader() {
    let budget = std::env::var("GRIN_FUZZ_SECONDS")
        .ok()
        .and_then(|s| s.parse::<f64>().ok())
        .unwrap_or(DEFAULT_FUZZ_SECONDS);
    let dir = std::env::temp_dir().join(format!("vdb-sys-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/vdb");
    let originals: Vec<Vec<u8>> = FIXTURES
        .iter()
        .map(|f| std::fs::read(data.join(f)).expect("fixture"))
        .collect();
    let start = Instant::now();
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let (mut runs, mut rejected) = (0usize, 0usize);
    let target = dir.join("case.vdb");
    // Truncations through the header first (every HEADER_STEP bytes), then random cases.
    let mut header_cut = 0usize;
    let (mut flips, mut crashes) = (0usize, 0usize);
    while start.elapsed() < Duration::from_secs_f64(budget) {
        let which = rng.below(originals.len());
        let mut bytes = originals[which].clone();
        if header_cut < HEADER_BYTES {
            bytes.truncate(header_cut);
            header_cut += HEADER_STEP;
        } else if rng.below(3) == 0 {
            let len = rng.below(bytes.len());
            bytes.truncate(len);
        } else {
            flips += 1;
            for _ in 0..1 + rng.below(8) {
                let i = rng.below(bytes.len());
                bytes[i] ^= 1 << rng.below(8);
            }
        }
        std::fs::write(&target, &bytes).expect("write case");
        if std::env::var_os("GRIN_FUZZ_KEEP").is_some() {
            eprintln!("case {runs}: fixture {which}, {} bytes", bytes.len());
            std::fs::copy(&target, dir.join(format!("case{runs}.vdb"))).expect("keep case");
        }
        match exercise(&target) {
            Ok(_) => {}
            Err(msg) => {
                assert!(!msg.is_empty());
                crashes += usize::from(msg.contains("crashed"));
                rejected += 1;
            }
        }
        runs += 1;
    }
    std::fs::remove_dir_all(&dir).ok();
    eprintln!(
        "fuzz: {runs} cases ({flips} with bit flips) in {:.1} s, {rejected} rejected, \
         {crashes} contained OpenVDB crashes",
        start.elapsed().as_secs_f64()
    );
    assert!(
        runs >= HEADER_BYTES / HEADER_STEP + 8,
        "the loop must cover the header truncations and some random cases ({runs})"
    );
    assert!(rejected > 0);
}
