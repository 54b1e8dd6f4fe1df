//! Writing a `.vdb` file ([`VdbWriter`]): float and vec3 grids with their metadata.

use std::ffi::{CString, c_char};
use std::path::Path;
use std::ptr::NonNull;

use crate::{
    DenseGrid, ERR_LEN, IndexBox, MetaValue, Transform, VdbError, c_path, err_text, ffi, loaded,
};

/// How a grid is written.
#[derive(Debug, Clone, PartialEq)]
pub struct WriteOptions {
    /// Background value (inactive voxels); also each component's background for vec3.
    pub background: f32,
    /// Voxels within this of the background become inactive.
    pub tolerance: f32,
    /// Store as 16-bit floats.
    pub half_float: bool,
    /// Grid metadata.
    pub metadata: Vec<(String, MetaValue)>,
}

impl Default for WriteOptions {
    fn default() -> Self {
        WriteOptions {
            background: 0.0,
            tolerance: 0.0,
            half_float: false,
            metadata: Vec::new(),
        }
    }
}

/// Collects grids and file metadata, then writes one `.vdb` file.
#[derive(Debug)]
pub struct VdbWriter {
    raw: NonNull<ffi::GrinVdbWriter>,
}

// SAFETY: the writer owns its grids exclusively.
unsafe impl Send for VdbWriter {}

impl Drop for VdbWriter {
    fn drop(&mut self) {
        // SAFETY: `raw` came from grin_vdb_writer_new and is freed exactly once.
        unsafe { ffi::grin_vdb_writer_free(self.raw.as_ptr()) };
    }
}

/// The shim's status of a call adding to grid `name`, as a result.
fn grid_status(status: i32, name: &str, err: &[c_char]) -> Result<(), VdbError> {
    if status == ffi::GRIN_VDB_OK {
        return Ok(());
    }
    Err(VdbError::Write {
        path: String::new(),
        message: format!("grid `{name}`: {}", err_text(err)),
    })
}

fn cstring(s: &str, what: &str) -> Result<CString, VdbError> {
    CString::new(s).map_err(|_| VdbError::Write {
        path: String::new(),
        message: format!("{what} `{s}` contains a NUL byte"),
    })
}

impl VdbWriter {
    pub fn new() -> Result<Self, VdbError> {
        loaded()?;
        // SAFETY: no arguments; null means the shim could not allocate.
        let raw = unsafe { ffi::grin_vdb_writer_new() };
        NonNull::new(raw)
            .map(|raw| VdbWriter { raw })
            .ok_or_else(|| VdbError::Write {
                path: String::new(),
                message: "cannot create an OpenVDB writer".into(),
            })
    }

    fn add(
        &mut self,
        name: &str,
        components: i32,
        bbox: IndexBox,
        world_from_index: Transform,
        data: &[f32],
        opts: &WriteOptions,
    ) -> Result<(), VdbError> {
        let cname = cstring(name, "grid name")?;
        let mut str_keys = Vec::new();
        let mut str_vals = Vec::new();
        let mut num_keys = Vec::new();
        let mut num_vals = Vec::new();
        for (k, v) in &opts.metadata {
            match v {
                MetaValue::Number(x) => {
                    num_keys.push(cstring(k, "metadata key")?);
                    num_vals.push(*x);
                }
                MetaValue::Text(s) | MetaValue::Other(s) => {
                    str_keys.push(cstring(k, "metadata key")?);
                    str_vals.push(cstring(s, "metadata value")?);
                }
            }
        }
        let str_key_ptrs: Vec<*const c_char> = str_keys.iter().map(|c| c.as_ptr()).collect();
        let str_val_ptrs: Vec<*const c_char> = str_vals.iter().map(|c| c.as_ptr()).collect();
        let num_key_ptrs: Vec<*const c_char> = num_keys.iter().map(|c| c.as_ptr()).collect();
        let dims = bbox.dims();
        let flat = world_from_index.to_flat();
        let mut err = [0 as c_char; ERR_LEN];
        // SAFETY: every pointer refers to a live local of the stated length; the shim
        // checks `data.len()` against `dims` and `components`.
        let status = unsafe {
            ffi::grin_vdb_writer_add_grid(
                self.raw.as_ptr(),
                cname.as_ptr(),
                components,
                bbox.min.as_ptr(),
                dims.as_ptr(),
                data.as_ptr(),
                data.len(),
                flat.as_ptr(),
                opts.background,
                opts.tolerance,
                i32::from(opts.half_float),
                str_key_ptrs.as_ptr(),
                str_val_ptrs.as_ptr(),
                str_key_ptrs.len(),
                num_key_ptrs.as_ptr(),
                num_vals.as_ptr(),
                num_key_ptrs.len(),
                err.as_mut_ptr(),
                ERR_LEN,
            )
        };
        grid_status(status, name, &err)
    }

    /// Add a float grid from a dense array.
    pub fn add_float(
        &mut self,
        name: &str,
        grid: &DenseGrid<f32>,
        opts: &WriteOptions,
    ) -> Result<(), VdbError> {
        self.add(
            name,
            1,
            grid.bbox,
            grid.world_from_index,
            &grid.values,
            opts,
        )
    }

    /// Add a vec3s grid (vector type covariant, as gradients are) from a dense array.
    pub fn add_vec3(
        &mut self,
        name: &str,
        grid: &DenseGrid<[f32; 3]>,
        opts: &WriteOptions,
    ) -> Result<(), VdbError> {
        let flat: Vec<f32> = grid.values.iter().flat_map(|v| v.iter().copied()).collect();
        self.add(name, 3, grid.bbox, grid.world_from_index, &flat, opts)
    }

    /// Add a float grid written box by box (a sparse grid: only the boxes' voxels, each
    /// box's values dense with x fastest; later boxes overwrite earlier ones where they
    /// overlap).
    pub fn add_float_boxes(
        &mut self,
        name: &str,
        world_from_index: Transform,
        boxes: impl IntoIterator<Item = (IndexBox, Vec<f32>)>,
        opts: &WriteOptions,
    ) -> Result<(), VdbError> {
        self.add_boxes(name, 1, world_from_index, boxes.into_iter(), opts)
    }

    /// [`Self::add_float_boxes`] for a vec3s grid (covariant, as gradients are).
    pub fn add_vec3_boxes(
        &mut self,
        name: &str,
        world_from_index: Transform,
        boxes: impl IntoIterator<Item = (IndexBox, Vec<[f32; 3]>)>,
        opts: &WriteOptions,
    ) -> Result<(), VdbError> {
        let flat = boxes
            .into_iter()
            .map(|(b, v)| (b, v.iter().flat_map(|c| c.iter().copied()).collect()));
        self.add_boxes(name, 3, world_from_index, flat, opts)
    }

    fn add_boxes(
        &mut self,
        name: &str,
        components: i32,
        world_from_index: Transform,
        mut boxes: impl Iterator<Item = (IndexBox, Vec<f32>)>,
        opts: &WriteOptions,
    ) -> Result<(), VdbError> {
        let Some((first, data)) = boxes.next() else {
            return Err(VdbError::Write {
                path: String::new(),
                message: format!("grid `{name}`: no boxes to write"),
            });
        };
        self.add(name, components, first, world_from_index, &data, opts)?;
        for (bbox, data) in boxes {
            let dims = bbox.dims();
            let mut err = [0 as c_char; ERR_LEN];
            // SAFETY: every pointer refers to a live local of the stated length; the shim
            // checks `data.len()` against `dims` and the last grid's kind.
            let status = unsafe {
                ffi::grin_vdb_writer_add_box(
                    self.raw.as_ptr(),
                    bbox.min.as_ptr(),
                    dims.as_ptr(),
                    data.as_ptr(),
                    data.len(),
                    opts.tolerance,
                    err.as_mut_ptr(),
                    ERR_LEN,
                )
            };
            grid_status(status, name, &err)?;
        }
        Ok(())
    }

    /// Add a string entry to the file metadata.
    pub fn add_file_meta(&mut self, key: &str, value: &str) -> Result<(), VdbError> {
        let (k, v) = (
            cstring(key, "metadata key")?,
            cstring(value, "metadata value")?,
        );
        let mut err = [0 as c_char; ERR_LEN];
        // SAFETY: live writer, valid C strings and buffer.
        let status = unsafe {
            ffi::grin_vdb_writer_add_file_meta(
                self.raw.as_ptr(),
                k.as_ptr(),
                v.as_ptr(),
                err.as_mut_ptr(),
                ERR_LEN,
            )
        };
        if status != ffi::GRIN_VDB_OK {
            return Err(VdbError::Write {
                path: String::new(),
                message: err_text(&err),
            });
        }
        Ok(())
    }

    /// Write all grids to `path` (overwriting it). Callers that must not leave a partial
    /// file write to a temporary path and rename.
    pub fn write(&mut self, path: impl AsRef<Path>) -> Result<(), VdbError> {
        let path = path.as_ref();
        let shown = path.display().to_string();
        let c = c_path(path).map_err(|e| VdbError::Write {
            path: shown.clone(),
            message: e.to_string(),
        })?;
        let mut err = [0 as c_char; ERR_LEN];
        // SAFETY: live writer, valid C string and buffer.
        let status = unsafe {
            ffi::grin_vdb_writer_write(self.raw.as_ptr(), c.as_ptr(), err.as_mut_ptr(), ERR_LEN)
        };
        if status != ffi::GRIN_VDB_OK {
            return Err(VdbError::Write {
                path: shown,
                message: err_text(&err),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{ValueKind, VdbFile};

    #[test]
    fn write_then_read_roundtrips_values_and_transform() {
        let dir = std::env::temp_dir().join(format!("vdb-sys-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("roundtrip.vdb");
        let bbox = IndexBox {
            min: [-3, 2, -1],
            max: [1, 4, 2],
        };
        let dims = bbox.dims();
        let n = dims.iter().product::<u64>() as usize;
        let xf = Transform::uniform(0.25, [1.0, -2.0, 0.5]);
        let scalar = DenseGrid {
            bbox,
            world_from_index: xf,
            values: (0..n).map(|i| 1.0 + i as f32 * 0.5).collect(),
        };
        let vec = DenseGrid {
            bbox,
            world_from_index: xf,
            values: (0..n).map(|i| [i as f32, -(i as f32), 0.5]).collect(),
        };
        let mut w = VdbWriter::new().expect("writer");
        let opts = WriteOptions {
            metadata: vec![
                ("units".into(), MetaValue::Text("m".into())),
                ("n_ambient".into(), MetaValue::Number(1.000_272)),
            ],
            ..WriteOptions::default()
        };
        w.add_float("delta_n", &scalar, &opts).expect("add float");
        w.add_vec3("grad_n", &vec, &WriteOptions::default())
            .expect("add vec3");
        w.add_file_meta("creator", "grin test").expect("meta");
        w.write(&path).expect("write");

        let f = VdbFile::open(&path).expect("open");
        assert_eq!(f.grids().len(), 2);
        assert!(
            f.metadata()
                .iter()
                .any(|m| m.key == "creator" && m.value == MetaValue::Text("grin test".into()))
        );
        let g = f.grid("delta_n").expect("grid");
        assert_eq!(g.kind, ValueKind::Float);
        assert_eq!(g.active_bbox, Some(bbox));
        assert_eq!(g.active_voxel_count, n as u64);
        assert_eq!(g.voxel_size, [0.25; 3]);
        assert!(
            g.metadata
                .iter()
                .any(|m| m.key == "n_ambient" && m.value == MetaValue::Number(1.000_272))
        );
        let back = f.read_scalar("delta_n", bbox, 1 << 20).expect("read");
        assert_eq!(back.values, scalar.values);
        assert_eq!(back.world_from_index, xf);
        let vback = f.read_vec3("grad_n", bbox, 1 << 20).expect("read vec3");
        assert_eq!(vback.values, vec.values);
        assert_eq!(f.grid("grad_n").expect("grid").kind, ValueKind::Vec3s);

        // Wrong type, missing grid and the memory cap give typed errors.
        assert!(matches!(
            f.read_scalar("grad_n", bbox, 1 << 20),
            Err(VdbError::WrongType { .. })
        ));
        let e = f
            .read_scalar("nope", bbox, 1 << 20)
            .expect_err("missing grid");
        assert!(
            e.to_string().contains("delta_n (float), grad_n (vec3s)"),
            "{e}"
        );
        assert!(matches!(
            f.read_scalar("delta_n", bbox, 16),
            Err(VdbError::TooLarge { .. })
        ));
        std::fs::remove_dir_all(&dir).ok();
    }
}
