//! Headless wgpu device setup: adapter choice by `WGPU_BACKEND` / `WGPU_ADAPTER_NAME`,
//! device limits, and error capture (lost device, uncaptured errors).

use std::sync::{Arc, Mutex};

use crate::GpuError;
use crate::pipeline_cache::DiskPipelineCache;

/// An adapter, its device and queue, plus the first uncaptured error or device loss.
#[derive(Debug)]
pub struct GpuContext {
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
    /// Set by wgpu's callbacks when the device is lost or an error escapes a scope.
    fault: Arc<Mutex<Option<String>>>,
    /// Render pipelines compiled on this device, by their pipeline constants: a renderer
    /// built again with the same constants (the next frame of a sequence, the viewer
    /// switching back) reuses them instead of compiling (seconds on lavapipe).
    pipelines: Mutex<std::collections::HashMap<String, RenderPipelines>>,
    /// The driver's pipeline cache, kept on disk, where the adapter supports one.
    pipeline_cache: Option<DiskPipelineCache>,
}

/// The render kernel's pipelines: the whole-frame (or first) pass and, when the frame is
/// split, the medium pass. Both share one bind group layout.
pub(crate) type RenderPipelines = (wgpu::ComputePipeline, Option<wgpu::ComputePipeline>);

/// lavapipe's loop limit: all loops of one shader invocation together stop after this
/// many iterations. The march spends ~3 a step, 9 with dopri, one more per object the
/// step's chord is tested against and more where a step searches for an exit: a ray ends
/// `error` there after ~21,800 rk4 steps through a bare medium, ~10,900 in the Luneburg
/// scene (two planes), ~7,000 dopri steps (docs/accuracy.md).
pub const CPU_ADAPTER_LOOP_ITERATIONS: u32 = 65_535;

/// Pixels that ended `error` after at least this many steps on an adapter with a loop
/// limit are reported as likely cut short by it (the fewest seen, a ray reflecting along
/// the surface with an exit search every step, is ~6,500).
pub const LOOP_LIMIT_SUSPECT_STEPS: f32 = 2_000.0;

/// One line naming an adapter: `llvmpipe (LLVM 19.1.7, 256 bits) (Vulkan, Cpu)`.
pub fn describe_adapter(info: &wgpu::AdapterInfo) -> String {
    format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
}

/// The process's one wgpu instance (of the backends the first caller asked for), kept
/// until the process ends. Dropping the last instance lets the Vulkan loader unload the
/// driver, and with NVIDIA's (580.159, H200) a process that made and dropped a context
/// and then started a child process died of SIGSEGV: under cuda-gdb, in the thread
/// spawning the child, at an address in no loaded library (the driver's were gone from
/// the list), called from libc (tests/gpu.rs and tests/optics.rs, which probe for an
/// adapter and then run `grin`). With the instance kept, both pass there.
fn process_instance(backends: wgpu::Backends) -> &'static wgpu::Instance {
    static INSTANCE: std::sync::OnceLock<wgpu::Instance> = std::sync::OnceLock::new();
    INSTANCE.get_or_init(|| {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = backends;
        wgpu::Instance::new(desc)
    })
}

/// The process's wgpu instance, of the backends `WGPU_BACKEND` names (all by default): a
/// window's surface must come from it to share its device with the renderer.
pub fn instance() -> &'static wgpu::Instance {
    process_instance(wgpu::Backends::from_env().unwrap_or(wgpu::Backends::all()))
}

impl GpuContext {
    /// A headless device. `WGPU_BACKEND` (e.g. `vulkan`) restricts the backends,
    /// `WGPU_ADAPTER_NAME` picks the first adapter whose name contains it
    /// (case-insensitive); otherwise wgpu's default adapter (high performance preferred).
    /// The driver's pipeline cache is kept in the user's cache directory
    /// ([`crate::pipeline_cache::user_default_dir`]) where the adapter supports one.
    pub fn new_headless() -> Result<Self, GpuError> {
        Self::new_headless_in(crate::pipeline_cache::user_default_dir().as_deref())
    }

    /// [`Self::new_headless`] with the pipeline cache kept in `pipeline_dir` (`None`: no
    /// pipeline cache, every pipeline compiled from scratch).
    pub fn new_headless_in(pipeline_dir: Option<&std::path::Path>) -> Result<Self, GpuError> {
        Self::new_in(None, pipeline_dir)
    }

    /// A device that can also draw into `surface` (made by [`instance`]): the viewer's
    /// renderer and window share it, so frames reach the window without leaving the
    /// device. Adapters are chosen as by [`Self::new_headless`], among those that can
    /// present to the surface.
    pub fn new_for_surface(
        surface: &wgpu::Surface<'_>,
        pipeline_dir: Option<&std::path::Path>,
    ) -> Result<Self, GpuError> {
        Self::new_in(Some(surface), pipeline_dir)
    }

    fn new_in(
        surface: Option<&wgpu::Surface<'_>>,
        pipeline_dir: Option<&std::path::Path>,
    ) -> Result<Self, GpuError> {
        let backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::all());
        let instance = process_instance(backends);
        let adapters: Vec<wgpu::Adapter> =
            pollster::block_on(instance.enumerate_adapters(backends))
                .into_iter()
                .filter(|a| surface.is_none_or(|s| a.is_surface_supported(s)))
                .collect();
        let seen = if adapters.is_empty() {
            "none".to_owned()
        } else {
            adapters
                .iter()
                .map(|a| describe_adapter(&a.get_info()))
                .collect::<Vec<_>>()
                .join("; ")
        };
        let wanted = std::env::var("WGPU_ADAPTER_NAME")
            .ok()
            .filter(|s| !s.is_empty());
        let adapter = match &wanted {
            Some(name) => {
                let lower = name.to_lowercase();
                adapters
                    .into_iter()
                    .find(|a| a.get_info().name.to_lowercase().contains(&lower))
            }
            None => pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                compatible_surface: surface,
                ..Default::default()
            }))
            .ok(),
        };
        let Some(adapter) = adapter else {
            let mut filter = String::new();
            if let Ok(b) = std::env::var("WGPU_BACKEND") {
                filter.push_str(&format!(" for WGPU_BACKEND={b}"));
            }
            if let Some(n) = &wanted {
                filter.push_str(&format!(" matching WGPU_ADAPTER_NAME={n}"));
            }
            if surface.is_some() {
                filter.push_str(" that can draw into the window");
            }
            return Err(GpuError::NoAdapter { filter, seen });
        };
        let info = adapter.get_info();
        // Ask for the adapter's own limits: big 3D textures and storage buffers are the
        // point of this crate, and we check every size against them before creating.
        let limits = adapter.limits();
        let cache_features = match pipeline_dir {
            Some(_) => adapter.features() & wgpu::Features::PIPELINE_CACHE,
            None => wgpu::Features::empty(),
        };
        // Timestamps around the render passes, where the adapter has them: the device's
        // own time per frame ([`crate::GpuRenderer::last_device_seconds`]).
        let timestamp_features = adapter.features() & wgpu::Features::TIMESTAMP_QUERY;
        // rgba16snorm texels for i16 fields (half the memory of f32), where the adapter
        // has them ([`GpuContext::has_snorm16`]).
        let snorm_features = adapter.features() & wgpu::Features::TEXTURE_FORMAT_16BIT_NORM;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("grin"),
            required_features: cache_features | timestamp_features | snorm_features,
            required_limits: limits,
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| GpuError::Device {
            adapter: describe_adapter(&info),
            message: e.to_string(),
        })?;
        let fault = Arc::new(Mutex::new(None::<String>));
        let f = fault.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut slot) = f.lock() {
                slot.get_or_insert_with(|| e.to_string());
            }
        }));
        let f = fault.clone();
        device.set_device_lost_callback(move |reason, message| {
            if let Ok(mut slot) = f.lock() {
                slot.get_or_insert_with(|| format!("device lost ({reason:?}): {message}"));
            }
        });
        let pipeline_cache = pipeline_dir
            .filter(|_| !cache_features.is_empty())
            .and_then(|dir| DiskPipelineCache::open(&device, &info, dir));
        Ok(GpuContext {
            adapter,
            device,
            queue,
            info,
            fault,
            pipelines: Mutex::new(std::collections::HashMap::new()),
            pipeline_cache,
        })
    }

    /// Whether the device writes timestamps around compute passes.
    pub fn has_timestamps(&self) -> bool {
        self.device
            .features()
            .contains(wgpu::Features::TIMESTAMP_QUERY)
    }

    /// Whether i16 fields can stay 16-bit on the device (rgba16snorm textures,
    /// `Features::TEXTURE_FORMAT_16BIT_NORM`); without it they are decoded to f32 on upload.
    /// `GRIN_GPU_F32_FIELDS=1` decodes them anyway (to compare the two).
    pub fn has_snorm16(&self) -> bool {
        self.device
            .features()
            .contains(wgpu::Features::TEXTURE_FORMAT_16BIT_NORM)
            && std::env::var_os("GRIN_GPU_F32_FIELDS").is_none_or(|v| v.is_empty() || v == "0")
    }

    /// The pipelines under `key`, compiled by `compile` the first time (and kept only
    /// when it succeeds).
    pub(crate) fn render_pipelines(
        &self,
        key: &str,
        compile: impl FnOnce() -> Result<RenderPipelines, GpuError>,
    ) -> Result<RenderPipelines, GpuError> {
        if let Ok(map) = self.pipelines.lock()
            && let Some(p) = map.get(key)
        {
            return Ok(p.clone());
        }
        let p = compile()?;
        self.persist_pipeline_cache();
        if let Ok(mut map) = self.pipelines.lock() {
            map.insert(key.to_owned(), p.clone());
        }
        Ok(p)
    }

    /// The driver's pipeline cache, to pass when creating a pipeline.
    pub(crate) fn pipeline_cache(&self) -> Option<&wgpu::PipelineCache> {
        self.pipeline_cache.as_ref().map(DiskPipelineCache::cache)
    }

    /// The pipeline cache's file and the bytes it held at start, where there is one.
    pub fn pipeline_cache_file(&self) -> Option<(&std::path::Path, usize)> {
        self.pipeline_cache
            .as_ref()
            .map(|c| (c.path(), c.loaded_bytes))
    }

    /// Write the pipeline cache to disk after a compile (when it grew).
    pub(crate) fn persist_pipeline_cache(&self) {
        if let Some(c) = &self.pipeline_cache {
            c.persist();
        }
    }

    /// Render pipelines compiled on this device so far.
    pub fn pipelines_compiled(&self) -> usize {
        self.pipelines.lock().map_or(0, |m| m.len())
    }

    /// The loop iterations one shader invocation may run in all on this adapter, where it
    /// has such a limit: lavapipe (Mesa's gallivm, the CPU adapter) ends every loop of an
    /// invocation after [`CPU_ADAPTER_LOOP_ITERATIONS`] (`LP_MAX_TGSI_LOOP_ITERATIONS`,
    /// shared by all its loops). A GPU has none.
    pub fn loop_limit(&self) -> Option<u32> {
        (self.info.device_type == wgpu::DeviceType::Cpu).then_some(CPU_ADAPTER_LOOP_ITERATIONS)
    }

    /// Whether the adapter is a CPU one (lavapipe where a machine has no GPU).
    pub fn is_cpu_adapter(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// `name (backend, device type)` of the adapter in use.
    pub fn adapter_name(&self) -> String {
        describe_adapter(&self.info)
    }

    pub fn limits(&self) -> wgpu::Limits {
        self.device.limits()
    }

    /// The first device loss or uncaptured error since the device was created, if any.
    pub fn check_fault(&self) -> Result<(), GpuError> {
        let slot = self
            .fault
            .lock()
            .map_err(|_| GpuError::DeviceLost("error slot poisoned".into()))?;
        match slot.as_ref() {
            Some(m) if m.contains("device lost") => Err(GpuError::DeviceLost(m.clone())),
            Some(m) => Err(GpuError::Wgpu {
                during: "rendering".into(),
                message: m.clone(),
            }),
            None => Ok(()),
        }
    }

    /// Run `f` inside out-of-memory and validation error scopes; a captured error
    /// becomes a [`GpuError`] that names `during`.
    pub fn scoped<T>(&self, during: &str, f: impl FnOnce() -> T) -> Result<T, GpuError> {
        let oom = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let out = f();
        let v = pollster::block_on(validation.pop());
        let o = pollster::block_on(oom.pop());
        if let Some(e) = o {
            return Err(GpuError::OutOfMemory {
                during: during.into(),
                message: e.to_string(),
            });
        }
        if let Some(e) = v {
            return Err(GpuError::Wgpu {
                during: during.into(),
                message: e.to_string(),
            });
        }
        self.check_fault()?;
        Ok(out)
    }

    /// Wait for the work submitted so far on this thread's queue, without holding the
    /// device while waiting: wgpu's blocking poll keeps a device lock for the whole wait,
    /// so a window sharing the device (the viewer) could not submit or present meanwhile.
    /// Polls without blocking ([`Self::wait_until`]).
    pub fn wait_submitted(&self) -> Result<(), GpuError> {
        let (tx, rx) = std::sync::mpsc::channel();
        self.queue.on_submitted_work_done(move || {
            let _ = tx.send(());
        });
        self.wait_until(&rx)
    }

    /// Poll the device without blocking until `rx` holds a value (a callback of the
    /// device's fired), then return it; a lost device or a captured error ends the wait.
    /// The pauses grow to 1 ms on a CPU adapter (its cores render) and 250 us on a GPU
    /// (a frame of ~1 ms is not held much past its end).
    pub fn wait_until<T>(&self, rx: &std::sync::mpsc::Receiver<T>) -> Result<T, GpuError> {
        let longest =
            std::time::Duration::from_micros(if self.is_cpu_adapter() { 1000 } else { 250 });
        let mut pause = std::time::Duration::from_micros(20);
        loop {
            self.device
                .poll(wgpu::PollType::Poll)
                .map_err(|e| GpuError::DeviceLost(e.to_string()))?;
            match rx.try_recv() {
                Ok(v) => {
                    self.check_fault()?;
                    return Ok(v);
                }
                Err(std::sync::mpsc::TryRecvError::Disconnected) => {
                    self.check_fault()?;
                    return Err(GpuError::DeviceLost("a device callback was dropped".into()));
                }
                Err(std::sync::mpsc::TryRecvError::Empty) => {}
            }
            self.check_fault()?;
            std::thread::sleep(pause);
            pause = (pause * 2).min(longest);
        }
    }

    /// Wait for all submitted work.
    pub fn wait(&self) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::DeviceLost(e.to_string()))?;
        self.check_fault()
    }
}
