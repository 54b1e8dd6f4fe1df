//! `grin._grin`: the native half of the Python package (python/grin holds the other).
//! Scenes load and render through grin-pipeline, as `grin render` does, so a render's
//! channels are the EXR's, bit for bit; ray arrays trace through the same plan as
//! `grin trace`; fields bake and read as `grin bake` writes them. The GIL is released
//! while grin works; errors are `grin.GrinError` with grin's own message.
//!
//! Over 600 lines: one concept, the module's bindings, each a thin call into grin-pipeline
//! or grin-field.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::DVec3;
use grin_field::IndexField;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use strum::VariantNames;

pyo3::create_exception!(
    _grin,
    GrinError,
    PyException,
    "An error grin reports: a bad scene, field or ray array, a failed render or bake."
);

fn err(e: anyhow::Error) -> PyErr {
    GrinError::new_err(format!("{e:#}"))
}

/// A scene: the TOML file's contents, where relative paths in it are resolved from, and
/// the name errors give it.
#[pyclass(module = "grin._grin", frozen)]
#[derive(Clone)]
struct Scene {
    scene: grin_scene::Scene,
    dir: PathBuf,
    label: String,
}

#[pymethods]
impl Scene {
    /// Load a scene file (TOML).
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        let scene = grin_scene::load_scene(&path).map_err(|e| err(e.into()))?;
        Ok(Self {
            scene,
            dir: path
                .parent()
                .map(Path::to_path_buf)
                .unwrap_or_else(|| ".".into()),
            label: path.display().to_string(),
        })
    }

    /// A scene from TOML text; relative paths in it are resolved from `base_dir`.
    #[staticmethod]
    #[pyo3(signature = (text, base_dir = None, name = None))]
    fn from_toml(text: &str, base_dir: Option<PathBuf>, name: Option<String>) -> PyResult<Self> {
        let label = name.unwrap_or_else(|| "<scene>".into());
        let scene = grin_scene::parse_scene(text, Path::new(&label)).map_err(|e| err(e.into()))?;
        Ok(Self {
            scene,
            dir: base_dir.unwrap_or_else(|| ".".into()),
            label,
        })
    }

    /// A scene from a JSON object of the scene file's tables (`json.dumps` of the dict a
    /// TOML reader gives); relative paths in it are resolved from `base_dir`.
    #[staticmethod]
    #[pyo3(signature = (text, base_dir = None, name = None))]
    fn from_json(text: &str, base_dir: Option<PathBuf>, name: Option<String>) -> PyResult<Self> {
        let label = name.unwrap_or_else(|| "<scene>".into());
        let value: serde_json::Value = serde_json::from_str(text)
            .map_err(|e| GrinError::new_err(format!("{label}: not a JSON object: {e}")))?;
        if !value.is_object() {
            return Err(GrinError::new_err(format!(
                "{label}: a scene is a table of tables (a dict), got {value}"
            )));
        }
        let toml = toml::to_string(&value).map_err(|e| {
            GrinError::new_err(format!(
                "{label}: not expressible in TOML (None values have no TOML form): {e}"
            ))
        })?;
        Self::from_toml(&toml, base_dir, Some(label))
    }

    /// The same scene at another image size and samples per pixel (None keeps them).
    #[pyo3(signature = (width = None, height = None, spp = None))]
    fn with_render(&self, width: Option<u32>, height: Option<u32>, spp: Option<u32>) -> Self {
        let mut s = self.clone();
        if let Some(w) = width {
            s.scene.render.width = w;
        }
        if let Some(h) = height {
            s.scene.render.height = h;
        }
        if let Some(n) = spp {
            s.scene.render.spp = n;
        }
        s
    }

    /// The scene at frame `frame` of its sequence (noise and expression time t + frame /
    /// fps, a frame token in the medium's path, the sensor's noise seed).
    #[pyo3(signature = (frame, fps = None))]
    fn at_frame(&self, frame: i64, fps: Option<f64>) -> PyResult<Self> {
        let fps = fps.unwrap_or_else(|| self.scene.fps());
        if !(fps.is_finite() && fps > 0.0) {
            return Err(GrinError::new_err(format!(
                "fps must be a positive number of frames per second, got {fps}"
            )));
        }
        let mut s = self.clone();
        s.scene = self.scene.at_frame(frame, fps);
        Ok(s)
    }

    #[getter]
    fn width(&self) -> u32 {
        self.scene.render.width
    }

    #[getter]
    fn height(&self) -> u32 {
        self.scene.render.height
    }

    #[getter]
    fn spp(&self) -> u32 {
        self.scene.render.spp
    }

    #[getter]
    fn name(&self) -> &str {
        &self.label
    }

    /// The `[optics]` mode (`displacement`, `schlieren`, ...), or None for a beauty render.
    #[getter]
    fn optics(&self) -> Option<&'static str> {
        self.scene
            .optics
            .as_ref()
            .map(|o| grin_pipeline::optics::mode_name(o.mode))
    }

    fn __repr__(&self) -> String {
        format!(
            "Scene({:?}, {}x{}, spp {}{})",
            self.label,
            self.scene.render.width,
            self.scene.render.height,
            self.scene.render.spp,
            self.optics()
                .map(|m| format!(", optics {m}"))
                .unwrap_or_default()
        )
    }
}

/// Renders scenes on one backend, keeping the GPU device and its pipelines.
#[pyclass(module = "grin._grin", frozen)]
struct Renderer {
    inner: grin_pipeline::Renderer,
}

#[pymethods]
impl Renderer {
    #[new]
    /// `aovs`: the AOVs a beauty render returns beside R, G, B, as `grin render --aovs`
    /// takes them (`"all"`, `"none"`, or names separated by commas); on the GPU only
    /// those channels are read back.
    #[pyo3(signature = (backend = "cpu", cache = true, aovs = "all"))]
    fn new(backend: &str, cache: bool, aovs: &str) -> PyResult<Self> {
        let backend = backend
            .parse::<grin_pipeline::Backend>()
            .map_err(GrinError::new_err)?;
        let aovs = grin_pipeline::parse_aovs(aovs).map_err(GrinError::new_err)?;
        Ok(Self {
            inner: grin_pipeline::Renderer::new(backend, cache).with_aovs(aovs),
        })
    }

    #[getter]
    fn backend(&self) -> &'static str {
        self.inner.backend().name()
    }

    /// Render `scene`: (channels, report JSON). Channels map the EXR's channel names to
    /// float32 arrays of shape (height, width), row 0 at the top.
    fn render<'py>(
        &self,
        py: Python<'py>,
        scene: &Scene,
    ) -> PyResult<(Bound<'py, PyDict>, String)> {
        let rendered = py
            .detach(|| {
                self.inner.render(
                    scene.scene.clone(),
                    &scene.dir,
                    &scene.label,
                    &grin_pipeline::Quiet,
                )
            })
            .map_err(err)?;
        let image = rendered.image;
        let shape = [image.height as usize, image.width as usize];
        let channels = PyDict::new(py);
        for (name, data) in image.channels {
            let array = PyArray1::from_vec(py, data).reshape(shape)?;
            channels.set_item(name, array)?;
        }
        let report = serde_json::to_string(&rendered.report).map_err(|e| err(e.into()))?;
        Ok((channels, report))
    }
}

/// Parse the trace overrides the CLI takes as flags.
fn overrides(
    integrator: Option<&str>,
    step: Option<&str>,
    max_steps: Option<u32>,
    f32: bool,
) -> PyResult<grin_pipeline::trace::TraceOverrides> {
    Ok(grin_pipeline::trace::TraceOverrides {
        integrator: integrator
            .map(grin_pipeline::trace::parse_integrator)
            .transpose()
            .map_err(GrinError::new_err)?,
        step: step
            .map(grin_pipeline::trace::parse_step)
            .transpose()
            .map_err(GrinError::new_err)?,
        max_steps,
        exit: None,
        f32,
    })
}

/// Trace rays (an (N, 6) float64 array of origin and direction) through the scene's
/// medium: (columns, summary JSON).
#[pyfunction]
#[pyo3(signature = (scene, rays, integrator = None, step = None, max_steps = None, f32 = false))]
fn trace<'py>(
    py: Python<'py>,
    scene: &Scene,
    rays: PyReadonlyArray2<'py, f64>,
    integrator: Option<&str>,
    step: Option<&str>,
    max_steps: Option<u32>,
    f32: bool,
) -> PyResult<(Bound<'py, PyDict>, String)> {
    let shape = rays.shape();
    if shape[1] != 6 {
        return Err(GrinError::new_err(format!(
            "rays must be an (N, 6) array of ox, oy, oz, dx, dy, dz; got shape ({}, {})",
            shape[0], shape[1]
        )));
    }
    let view = rays.as_array();
    let rows = grin_pipeline::trace::rows(
        view.rows()
            .into_iter()
            .map(|r| (DVec3::new(r[0], r[1], r[2]), DVec3::new(r[3], r[4], r[5]))),
    );
    let o = overrides(integrator, step, max_steps, f32)?;
    let (plan, results, seconds) = py
        .detach(|| -> anyhow::Result<_> {
            let plan = grin_pipeline::trace::TracePlan::new(
                &scene.scene,
                &scene.dir,
                &scene.label,
                &o,
                &rows,
            )?;
            let start = std::time::Instant::now();
            let results = plan.trace(&rows);
            Ok((plan, results, start.elapsed().as_secs_f64()))
        })
        .map_err(err)?;
    let n = results.len();
    let out = PyDict::new(py);
    let vec3 = |f: &dyn Fn(&grin_trace::RayResult) -> DVec3| {
        let flat: Vec<f64> = results.iter().flat_map(|r| f(r).to_array()).collect();
        PyArray1::from_vec(py, flat).reshape([n, 3])
    };
    let scalar = |f: &dyn Fn(&grin_trace::RayResult) -> f64| {
        PyArray1::from_vec(py, results.iter().map(f).collect::<Vec<f64>>())
    };
    out.set_item(
        "status",
        PyArray1::from_vec(
            py,
            results.iter().map(|r| r.status as u8).collect::<Vec<u8>>(),
        ),
    )?;
    out.set_item("position", vec3(&|r| r.position)?)?;
    out.set_item("direction", vec3(&|r| r.direction)?)?;
    out.set_item("opl", scalar(&|r| r.opl))?;
    out.set_item("length", scalar(&|r| r.length))?;
    out.set_item(
        "steps",
        PyArray1::from_vec(py, results.iter().map(|r| r.steps).collect::<Vec<u32>>()),
    )?;
    out.set_item(
        "evals",
        PyArray1::from_vec(py, results.iter().map(|r| r.evals).collect::<Vec<u64>>()),
    )?;
    out.set_item("error_estimate", scalar(&|r| r.error_estimate))?;
    let summary = serde_json::json!({
        "rays": n,
        "field": plan.field.describe(),
        "integrator": plan.settings.integrator.name(),
        "step": plan.settings.step,
        "precision": if f32 { "f32" } else { "f64" },
        "accuracy": plan.settings.accuracy,
        "estimate_limit": plan.settings.estimate_limit,
        "seconds": seconds,
        "status_names": grin_trace::RayStatus::ALL.map(|s| s.name()),
        "auto": plan.auto,
        "auto_note": plan.auto_note,
        "warnings": plan.field.warnings(),
    });
    Ok((out, summary.to_string()))
}

/// A baked field's arrays: delta_n (nz, ny, nx) and grad (nz, ny, nx, 3), both float32,
/// and its description (JSON).
fn field_arrays<'py>(
    py: Python<'py>,
    field: &grin_field::baked::BakedField,
) -> PyResult<(Bound<'py, PyDict>, String)> {
    let [nx, ny, nz] = field.dims();
    let voxels = field.voxels().to_f32();
    let count = voxels.len();
    let (delta, grad) = channels(voxels, count);
    let out = PyDict::new(py);
    out.set_item(
        "delta_n",
        PyArray1::from_vec(py, delta).reshape([nz, ny, nx])?,
    )?;
    out.set_item(
        "grad",
        PyArray1::from_vec(py, grad).reshape([nz, ny, nx, 3])?,
    )?;
    let g = field.geometry();
    let info = description(
        field,
        field.interp().name(),
        field.storage(),
        field.provenance(),
        serde_json::json!({
            "dims": [nx, ny, nz],
            "origin": g.origin.to_array(),
            "spacing": g.spacing.to_array(),
        }),
    );
    Ok((out, info))
}

/// `count` voxels (delta_n, grad n) split into delta_n and grad n (x, y, z a voxel).
fn channels(voxels: impl IntoIterator<Item = [f32; 4]>, count: usize) -> (Vec<f32>, Vec<f32>) {
    let (mut delta, mut grad) = (Vec::with_capacity(count), Vec::with_capacity(3 * count));
    for v in voxels {
        delta.push(v[0]);
        grad.extend_from_slice(&v[1..]);
    }
    (delta, grad)
}

/// A baked field's description (JSON): `layout`'s keys and what both layouts have.
fn description(
    field: &dyn IndexField,
    interp: &str,
    storage: grin_field::baked::Storage,
    provenance: &grin_field::baked::BakeProvenance,
    layout: serde_json::Value,
) -> String {
    let (lo, hi) = field.bounds().aabb();
    let mut info = serde_json::json!({
        "ambient": field.ambient_index(),
        "interp": interp,
        "storage": storage.name(),
        "bounds_min": lo.to_array(),
        "bounds_max": hi.to_array(),
        "source": provenance.source,
        "max_err_n": provenance.max_err_n,
    });
    if let (Some(all), serde_json::Value::Object(own)) = (info.as_object_mut(), layout) {
        all.extend(own);
    }
    info.to_string()
}

/// A sparse bake's arrays: every active brick's nodes decoded to float32, one brick after
/// another (`delta_n` (N,), `grad` (N, 3); brick b's nodes from `brick_offset[b]`, x fastest,
/// `brick_cells[b] + 1 + 2 apron` a side), each brick's top-grid position `brick_at` (B, 3), and the
/// description (JSON, `"sparse": true`, the top grid's origin, edge and dims).
fn sparse_arrays<'py>(
    py: Python<'py>,
    field: &grin_field::sparse::SparseField,
) -> PyResult<(Bound<'py, PyDict>, String)> {
    let bricks = field.bricks();
    let voxels = field.pool().len();
    let (delta, grad) = channels(
        bricks
            .iter()
            .flat_map(|b| (b.offset..b.offset + b.voxel_count()).map(|v| field.voxel_f32(b, v))),
        voxels,
    );
    let at: Vec<u32> = bricks.iter().flat_map(|b| b.at).collect();
    let cells: Vec<u32> = bricks.iter().map(|b| b.cells() as u32).collect();
    let offset: Vec<u64> = bricks.iter().map(|b| b.offset as u64).collect();
    let out = PyDict::new(py);
    out.set_item("delta_n", PyArray1::from_vec(py, delta))?;
    out.set_item("grad", PyArray1::from_vec(py, grad).reshape([voxels, 3])?)?;
    out.set_item(
        "brick_at",
        PyArray1::from_vec(py, at).reshape([bricks.len(), 3])?,
    )?;
    out.set_item("brick_cells", PyArray1::from_vec(py, cells))?;
    out.set_item("brick_offset", PyArray1::from_vec(py, offset))?;
    let top = field.top();
    let info = description(
        field,
        field.interp().name(),
        field.storage(),
        field.provenance(),
        serde_json::json!({
            "sparse": true,
            "apron": field.apron(),
            "gradient_of_n": field.gradient_of_n(),
            "top_origin": top.origin.to_array(),
            "brick_edge": top.edge,
            "top_dims": top.dims,
        }),
    );
    Ok((out, info))
}

/// Read a `.grinf` file, dense or sparse: (arrays, description JSON).
#[pyfunction]
fn read_field<'py>(py: Python<'py>, path: PathBuf) -> PyResult<(Bound<'py, PyDict>, String)> {
    let field = py
        .detach(|| grin_field::grinf::open(&path))
        .map_err(|e| err(e.into()))?;
    match field {
        grin_field::grinf::Grinf::Dense(f) => field_arrays(py, &f),
        grin_field::grinf::Grinf::Sparse(f) => sparse_arrays(py, &f),
    }
}

/// What a bake is asked.
fn bake_options(
    resolution: Option<usize>,
    error_budget: Option<f64>,
    interp: &str,
    max_memory: Option<u64>,
    gradient: grin_field::bake::GradientMode,
) -> PyResult<grin_field::bake::BakeOptions> {
    let interp = grin_field::baked::Interp::parse(interp).ok_or_else(|| {
        let names = grin_pipeline::one_of(<grin_field::baked::Interp as VariantNames>::VARIANTS);
        GrinError::new_err(format!("unknown interpolation `{interp}` ({names})"))
    })?;
    let defaults = grin_field::bake::BakeOptions::default();
    Ok(grin_field::bake::BakeOptions {
        resolution,
        error_budget: error_budget.unwrap_or(defaults.error_budget),
        max_memory: max_memory.unwrap_or(defaults.max_memory),
        interp,
        gradient,
        ..defaults
    })
}

/// Bake `field` per `opts` to `path` (when given): (arrays, description JSON, report
/// JSON).
fn bake_to<'py>(
    py: Python<'py>,
    field: Arc<dyn grin_field::IndexField>,
    opts: &grin_field::bake::BakeOptions,
    path: Option<PathBuf>,
    label: &str,
) -> PyResult<(Bound<'py, PyDict>, String, String)> {
    let (baked, report) = py
        .detach(|| -> anyhow::Result<_> {
            let (baked, report) = grin_field::bake::bake(field.as_ref(), opts, &|_, _, _| {})
                .map_err(|e| anyhow::anyhow!("{label}: bake failed: {e}"))?;
            if let Some(p) = &path {
                grin_field::grinf::save(&baked, p)?;
            }
            Ok((baked, report))
        })
        .map_err(err)?;
    let (arrays, info) = field_arrays(py, &baked)?;
    let report = serde_json::json!({
        "source": field.describe(),
        "resolution": report.resolution,
        "dims": report.dims,
        "interp": report.interp.name(),
        "storage": report.storage.name(),
        "bytes": report.bytes,
        "relative_error": report.relative_error,
        "budget": report.budget,
        "meets_budget": report.meets_budget,
        "source_limited": report.source_limited,
        "max_err_n": report.errors.max_err_n,
        "max_err_grad": report.errors.max_err_grad,
        "seconds": report.seconds,
        "warnings": field.warnings(),
    });
    Ok((arrays, info, report.to_string()))
}

/// Bake a scene's medium (to `path` when given): (arrays, description, report).
#[pyfunction]
#[pyo3(signature = (scene, path = None, resolution = None, error_budget = None, interp = "trilinear", max_memory = None))]
fn bake<'py>(
    py: Python<'py>,
    scene: &Scene,
    path: Option<PathBuf>,
    resolution: Option<usize>,
    error_budget: Option<f64>,
    interp: &str,
    max_memory: Option<u64>,
) -> PyResult<(Bound<'py, PyDict>, String, String)> {
    let Some(medium) = scene.scene.medium.as_ref() else {
        return Err(GrinError::new_err(format!(
            "{}: the scene has no [medium] to bake",
            scene.label
        )));
    };
    let gradient = grin_field::bake::GradientMode::for_field(&medium.field);
    let opts = bake_options(resolution, error_budget, interp, max_memory, gradient)?;
    // `path` may not replace the scene file or a file the scene reads (for this call).
    let _inputs = grin_output::protect_inputs(
        std::iter::once(PathBuf::from(&scene.label)).chain(scene.scene.files(&scene.dir)),
    );
    let field = py
        .detach(|| grin_field::build_field(medium, &scene.dir))
        .map_err(|e| err(anyhow::Error::from(e).context(format!("{}: [medium]", scene.label))))?;
    bake_to(py, field, &opts, path, &scene.label)
}

/// Bake the user's own volume: `values` (nz, ny, nx) at voxel centres `origin + voxel_size
/// * (i, j, k)`, mapped to n by `map_json` (a scene's VDB `map`, as JSON; `background`: the
/// value outside the volume), into a baked
/// field (to `path` when given): (arrays, description, report).
#[pyfunction]
#[pyo3(signature = (values, voxel_size, origin, map_json, background, ambient = None, bounds_min = None, bounds_max = None, path = None, resolution = None, error_budget = None, interp = "trilinear", max_memory = None))]
#[allow(clippy::too_many_arguments)]
fn bake_volume<'py>(
    py: Python<'py>,
    values: PyReadonlyArray3<'py, f32>,
    voxel_size: f64,
    origin: [f64; 3],
    map_json: &str,
    background: f64,
    ambient: Option<f64>,
    bounds_min: Option<[f64; 3]>,
    bounds_max: Option<[f64; 3]>,
    path: Option<PathBuf>,
    resolution: Option<usize>,
    error_budget: Option<f64>,
    interp: &str,
    max_memory: Option<u64>,
) -> PyResult<(Bound<'py, PyDict>, String, String)> {
    let label = "volume".to_owned();
    if !(voxel_size.is_finite() && voxel_size > 0.0) {
        return Err(GrinError::new_err(format!(
            "{label}: voxel_size must be a positive length, got {voxel_size}"
        )));
    }
    if origin.iter().any(|v| !v.is_finite()) {
        return Err(GrinError::new_err(format!(
            "{label}: origin {origin:?} must be finite"
        )));
    }
    let map: grin_scene::VdbMap = serde_json::from_str(map_json)
        .map_err(|e| GrinError::new_err(format!("{label}: map: {e}")))?;
    let shape = values.shape();
    let (nz, ny, nx) = (shape[0], shape[1], shape[2]);
    if nx < 2 || ny < 2 || nz < 2 {
        return Err(GrinError::new_err(format!(
            "{label}: the volume needs at least 2 voxels per axis, got shape ({nz}, {ny}, {nx})"
        )));
    }
    let too_big = |v: usize| i32::try_from(v).is_err();
    if too_big(nx) || too_big(ny) || too_big(nz) {
        return Err(GrinError::new_err(format!(
            "{label}: shape ({nz}, {ny}, {nx}) is too large"
        )));
    }
    // C order (nz, ny, nx): x runs fastest, as the dense grid's offsets do.
    let data: Vec<f32> = values.as_array().iter().copied().collect();
    let far = |n: usize, o: f64| o + voxel_size * (n as f64 - 1.0);
    let box_min = bounds_min.unwrap_or(origin);
    let box_max =
        bounds_max.unwrap_or([far(nx, origin[0]), far(ny, origin[1]), far(nz, origin[2])]);
    let dense = vdb_sys::DenseGrid {
        bbox: vdb_sys::IndexBox {
            min: [0, 0, 0],
            max: [nx as i32 - 1, ny as i32 - 1, nz as i32 - 1],
        },
        world_from_index: vdb_sys::Transform::uniform(voxel_size, origin),
        values: data,
    };
    let params = grin_field::vdb::VdbFieldParams {
        mapping: grin_field::vdb::Mapping::from_spec(&map),
        units: 1.0,
        non_finite: grin_scene::NonFinitePolicy::Reject,
        bounds: grin_field::Bounds::Box {
            min: DVec3::from_array(box_min),
            max: DVec3::from_array(box_max),
        },
        ambient,
        max_bytes: max_memory.unwrap_or(grin_field::vdb::DEFAULT_MAX_DENSE_BYTES),
        placement: grin_field::vdb::IDENTITY,
    };
    let _ = &map;
    let field = py
        .detach(|| {
            grin_field::vdb::VdbField::from_dense(label.clone(), &dense, background, &params)
        })
        .map_err(|e| err(e.into()))?;
    let opts = bake_options(
        resolution,
        error_budget,
        interp,
        max_memory,
        grin_field::bake::GradientMode::CentralDifference,
    )?;
    bake_to(py, Arc::new(field), &opts, path, &label)
}

/// A dataset from the Python arguments.
fn dataset(
    kind: &str,
    media: &str,
    plates: Vec<PathBuf>,
    textures: Vec<PathBuf>,
    seed: u64,
    width: u32,
    height: u32,
) -> PyResult<grin_pipeline::dataset::Dataset> {
    use clap::ValueEnum;
    let kind = grin_pipeline::dataset::Kind::from_str(kind, false).map_err(|_| {
        let names = grin_pipeline::one_of(<grin_pipeline::dataset::Kind as VariantNames>::VARIANTS);
        GrinError::new_err(format!("unknown dataset kind `{kind}` ({names})"))
    })?;
    let media = grin_pipeline::dataset::Media::parse(media).map_err(GrinError::new_err)?;
    if !(plates.is_empty() && textures.is_empty()) && kind != grin_pipeline::dataset::Kind::Haze {
        return Err(GrinError::new_err(
            "plates, textures: only haze samples have a background image",
        ));
    }
    if let Some(missing) = plates.iter().chain(&textures).find(|p| !p.is_file()) {
        return Err(GrinError::new_err(format!(
            "{}: no such image file",
            missing.display()
        )));
    }
    let mut d = grin_pipeline::dataset::Dataset::new(kind, media, seed, width, height);
    d.plates = plates;
    d.textures = textures;
    Ok(d)
}

/// Render sample `index` of a dataset: (channels, JSON). Channels are the sample EXR's,
/// plus `slice.n` ((64, 64), the index on the plane through the medium's centre).
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn dataset_sample<'py>(
    py: Python<'py>,
    renderer: &Renderer,
    kind: &str,
    media: &str,
    plates: Vec<PathBuf>,
    textures: Vec<PathBuf>,
    index: u64,
    seed: u64,
    width: u32,
    height: u32,
) -> PyResult<(Bound<'py, PyDict>, String)> {
    let dataset = dataset(kind, media, plates, textures, seed, width, height)?;
    let sample = py
        .detach(|| dataset.render_sample(&renderer.inner, Path::new("."), index))
        .map_err(err)?;
    let image = sample.image;
    let shape = [image.height as usize, image.width as usize];
    let channels = PyDict::new(py);
    for (name, data) in image.channels {
        channels.set_item(name, PyArray1::from_vec(py, data).reshape(shape)?)?;
    }
    let side = grin_pipeline::dataset::SLICE;
    channels.set_item(
        "slice.n",
        PyArray1::from_vec(py, sample.slice).reshape([side, side])?,
    )?;
    Ok((channels, sample.meta.to_string()))
}

/// Write samples `indices` of a `count`-sample dataset to `dir`, skipping complete ones,
/// as `grin dataset` does: the run's summary (JSON).
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn dataset_write(
    py: Python<'_>,
    renderer: &Renderer,
    kind: &str,
    media: &str,
    plates: Vec<PathBuf>,
    textures: Vec<PathBuf>,
    dir: PathBuf,
    count: u64,
    indices: Vec<u64>,
    seed: u64,
    width: u32,
    height: u32,
) -> PyResult<String> {
    if let Some(bad) = indices.iter().find(|&&i| i >= count) {
        return Err(GrinError::new_err(format!(
            "sample {bad} is not in a dataset of {count} samples"
        )));
    }
    let dataset = dataset(kind, media, plates, textures, seed, width, height)?;
    let summary = py
        .detach(|| dataset.write(&renderer.inner, &dir, count, &indices, &|_, _| {}))
        .map_err(err)?;
    serde_json::to_string(&summary).map_err(|e| err(e.into()))
}

/// The version of grin this module was built from.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

#[pymodule]
fn _grin(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("GrinError", m.py().get_type::<GrinError>())?;
    m.add_class::<Scene>()?;
    m.add_class::<Renderer>()?;
    m.add_function(wrap_pyfunction!(trace, m)?)?;
    m.add_function(wrap_pyfunction!(read_field, m)?)?;
    m.add_function(wrap_pyfunction!(bake, m)?)?;
    m.add_function(wrap_pyfunction!(bake_volume, m)?)?;
    m.add_function(wrap_pyfunction!(dataset_sample, m)?)?;
    m.add_function(wrap_pyfunction!(dataset_write, m)?)?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    Ok(())
}
