//! Everything that talks to wgpu: the device, the pipeline cache, scene
//! buffers and filter dispatches. Only validated kernels come in.

pub mod adapter;
mod anchor;
mod buffers;
mod clock;
mod filter;
mod fitness;
mod guide;
mod host_memory;
mod pixel_filter;
mod planefit;
mod prepass;
mod profile;
mod raw;
mod sampled;
mod temporal;
mod trace;

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

pub use crate::jit::builtin::PATHTRACE_WGSL;
pub use buffers::SceneBuffers;
pub use clock::Span;
pub use filter::{Filtered, MAX_WEIGHTS_PER_DISPATCH};
pub use fitness::{FitnessScene, Region, SceneScore};
pub use profile::TimedPass;
pub use raw::{RawBuffer, RawKernel};
pub use temporal::TemporalState;
pub use trace::{TraceBand, TraceInputs, TraceScene};

use crate::jit::interface::{Resource, TexelFormat};
use crate::jit::{
    Access, BindingInterface, BuiltIn, KernelKey, OutputFormat, PassRole, Role, Slot, ValidatedKernel, ValidatedModule,
};

#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter with compute shaders was found (backends tried: {backends}).\n\
         On Linux without a GPU, install Mesa's software drivers:\n  \
         apt-get install -y mesa-vulkan-drivers   # lavapipe, Vulkan\n  \
         apt-get install -y libegl1 libegl-mesa0 libgl1-mesa-dri   # llvmpipe, OpenGL through EGL\n\
         To force a backend set FILTERJIT_BACKEND=vulkan|gl|metal|dx12."
    )]
    NoAdapter { backends: String },
    #[error("FILTERJIT_ADAPTER={wanted} matches no adapter; found: {}", found.join("; "))]
    NoMatchingAdapter { wanted: String, found: Vec<String> },
    #[error("FILTERJIT_BACKEND={0} is not a backend; use vulkan, gl, metal or dx12")]
    BadBackend(String),
    #[error("cannot open the GPU device {adapter}: {message}")]
    Device { adapter: String, message: String },
    #[error(
        "the kernel for `{expression}` needs {needed} storage buffers, but {adapter} allows {limit} per shader stage"
    )]
    TooManyBindings { expression: String, needed: u32, limit: u32, adapter: String },
    #[error("wgpu refused the pipeline for `{expression}`: {message}\n--- WGSL ---\n{wgsl}")]
    Pipeline { expression: String, message: String, wgsl: String },
    #[error("the GPU failed while {during}: {message}")]
    Runtime { during: &'static str, message: String },
    /// The user's data lacks an input: not the device's failure.
    #[error(transparent)]
    MissingInput(#[from] crate::scene::MissingInput),
    #[error("scene `{scene}` has no reference image, which scoring compares with")]
    MissingReference { scene: String },
    #[error("the kernel for `{expression}` has shape {shape:?}, but the scene was prepared for pipeline `{pipeline}`")]
    Shape { expression: String, shape: crate::jit::Shape, pipeline: crate::pipeline::FilterPipeline },
    #[error("scoring `planefit` needs an à-trous form before it; pipeline `{pipeline}` has a window")]
    PlaneFitAfterWindow { pipeline: crate::pipeline::FilterPipeline },
    #[error(
        "pipeline `{pipeline}`: `pixelfilter` is not scored in a search: it models how a render sampled its \
         pixels, which `filter` adds by itself for frames sampled at one point (leave it out of the search's pipeline)"
    )]
    PixelFilterScored { pipeline: crate::pipeline::FilterPipeline },
    #[error(
        "pipeline `{pipeline}`: `anchor` is not scored in a search: it corrects the light of whatever the search's \
         filter leaves, so a weight would be chosen for what the anchor hides (leave it out of the search's pipeline \
         and add it to the result's)"
    )]
    AnchorScored { pipeline: crate::pipeline::FilterPipeline },
    #[error(
        "scene `{scene}` is {width}x{height} pixels; pipeline `{pipeline}` reads its images as textures, which {adapter} \
         allows at most {limit} pixels a side (a `window` form without a pre-pass reads storage buffers instead)"
    )]
    ImageTooLarge {
        scene: String,
        width: u32,
        height: u32,
        /// Boxed: the error's other variants are small.
        pipeline: Box<crate::pipeline::FilterPipeline>,
        limit: u32,
        adapter: String,
    },
    #[error("the kernel for `{expression}` stages tiles for radius {tiled}; it cannot filter with radius {radius}")]
    TileRadius { expression: String, tiled: u32, radius: u32 },
}

/// A tiled kernel runs only with the radius its tiles were made for.
pub(crate) fn check_radius(kernel: &ValidatedKernel, radius: u32) -> Result<(), GpuError> {
    match kernel.source().tile_radius {
        Some(tiled) if tiled != radius => {
            Err(GpuError::TileRadius { expression: kernel.source().canonical.clone(), tiled, radius })
        }
        _ => Ok(()),
    }
}

/// An open device with its pipeline cache.
pub struct Gpu {
    device: wgpu::Device,
    queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    limits: wgpu::Limits,
    /// Kernels' pipelines, one per role where the kernel specialises its passes.
    pipelines: Mutex<HashMap<(KernelKey, PassRole), Arc<Pipeline>>>,
    /// The built-in kernels' pipelines ([`Gpu::built_in`]), one per value of
    /// the constant a kernel overrides (0 for the others).
    built_ins: Mutex<HashMap<(BuiltIn, u32), Arc<Pipeline>>>,
    /// Whether kernels keep wgpu's run-time checks ([`Gpu::set_kernel_runtime_checks`]).
    kernel_checks: std::sync::atomic::AtomicBool,
    /// wgpu's GL backend shares one context per device and panics when a
    /// thread waits more than a second for it (as it does while another
    /// thread waits for a long dispatch or links a large program). On GL,
    /// filterjit's own threads therefore take turns here, without a timeout.
    gl_turns: Option<Mutex<()>>,
    /// Timestamps on the device's clock not in use ([`Gpu::stopwatch`]).
    stopwatches: Mutex<Vec<clock::Timestamps>>,
    /// Each compute pass's time, where profiling is on ([`Gpu::set_profiling`]).
    profile: Mutex<Option<profile::PassProfile>>,
}

/// Timings of getting a pipeline.
#[derive(Clone, Copy, Debug, Default)]
pub struct PipelineTiming {
    /// Time in wgpu's pipeline creation (zero on a cache hit).
    pub create: Duration,
    pub cache_hit: bool,
}

impl Gpu {
    /// This thread's turn on a GL device (see `gl_turns`); nothing elsewhere.
    /// Held around whole submit–wait–read sequences and pipeline creation,
    /// never nested.
    pub(crate) fn gl_turn(&self) -> Option<std::sync::MutexGuard<'_, ()>> {
        self.gl_turns.as_ref().map(|m| m.lock().unwrap_or_else(|poisoned| poisoned.into_inner()))
    }

    /// Open the adapter [`adapter::choose`] picks for `request`.
    pub fn open(request: &adapter::Request) -> Result<Gpu, GpuError> {
        Self::from_chosen(adapter::choose(request)?, request)
    }

    /// Open the adapter for the `index`-th process on this machine ([`adapter::choose_for`]).
    pub fn open_for(request: &adapter::Request, index: usize) -> Result<Gpu, GpuError> {
        Self::from_chosen(adapter::choose_for(request, index)?, request)
    }

    fn from_chosen(adapter: wgpu::Adapter, request: &adapter::Request) -> Result<Gpu, GpuError> {
        if request.keep_freed_images && adapter.get_info().device_type == wgpu::DeviceType::Cpu {
            host_memory::keep_freed_images();
        }
        Self::from_adapter(adapter)
    }

    fn from_adapter(adapter: wgpu::Adapter) -> Result<Gpu, GpuError> {
        let info = adapter.get_info();
        let limits = adapter.limits();
        let descriptor = wgpu::DeviceDescriptor {
            label: Some("filterjit"),
            // The device's clock where offered: `filterjit bench` times kernels by it.
            required_features: adapter.features() & clock::CLOCK_FEATURES,
            required_limits: limits.clone(),
            ..Default::default()
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&descriptor))
            .map_err(|e| GpuError::Device { adapter: info.name.clone(), message: e.to_string() })?;
        let gl_turns = (info.backend == wgpu::Backend::Gl).then(|| Mutex::new(()));
        Ok(Gpu {
            device,
            queue,
            info,
            limits,
            pipelines: Mutex::new(HashMap::new()),
            built_ins: Mutex::new(HashMap::new()),
            kernel_checks: std::sync::atomic::AtomicBool::new(false),
            gl_turns,
            stopwatches: Mutex::new(Vec::new()),
            profile: Mutex::new(None),
        })
    }

    /// Another device on the same adapter as `other` (its own queue and pipelines).
    pub fn open_like(other: &Gpu) -> Result<Gpu, GpuError> {
        let wanted = other.info.clone();
        let adapter = adapter::available(wgpu::Backends::from(wanted.backend), true)
            .into_iter()
            .find(|a| {
                let info = a.get_info();
                info.name == wanted.name && info.device == wanted.device && info.backend == wanted.backend
            })
            .ok_or(GpuError::NoMatchingAdapter { wanted: wanted.name.clone(), found: Vec::new() })?;
        Self::from_adapter(adapter)
    }

    /// One line naming the adapter and backend.
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?}, driver {})",
            self.info.name, self.info.backend, self.info.device_type, self.info.driver_info
        )
    }

    pub fn info(&self) -> &wgpu::AdapterInfo {
        &self.info
    }

    /// Whether this is a software rasteriser (lavapipe, llvmpipe).
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    pub(crate) fn device(&self) -> &wgpu::Device {
        &self.device
    }
    pub(crate) fn queue(&self) -> &wgpu::Queue {
        &self.queue
    }

    /// Number of pipelines in the cache.
    pub fn cached_pipelines(&self) -> usize {
        self.pipelines.lock().expect("pipeline cache lock").len()
    }

    /// The longest side of a texture on this device: the largest image a
    /// pipeline whose kernels sample their images can filter.
    pub fn max_image_side(&self) -> u32 {
        self.limits.max_texture_dimension_2d
    }

    /// Storage buffers a kernel may bind on this device.
    pub fn storage_buffer_limit(&self) -> u32 {
        self.limits.max_storage_buffers_per_shader_stage
    }

    pub fn check_bindings(&self, kernel: &ValidatedKernel) -> Result<(), GpuError> {
        let source = kernel.source();
        let needed = source.interface.storage_buffers();
        let limit = self.limits.max_storage_buffers_per_shader_stage;
        if needed > limit {
            return Err(GpuError::TooManyBindings {
                expression: source.canonical.clone(),
                needed,
                limit,
                adapter: self.info.name.clone(),
            });
        }
        Ok(())
    }

    /// Get the pipeline of a kernel: from the cache, or created and cached.
    pub fn pipeline(&self, kernel: &ValidatedKernel) -> Result<(Arc<Pipeline>, PipelineTiming), GpuError> {
        self.pipeline_for(kernel, PassRole::First)
    }

    /// The pipeline of a kernel that runs passes of `role`: one of its own
    /// where the kernel declares [`crate::jit::FIRST_PASS`], else its only one.
    pub fn pipeline_for(
        &self,
        kernel: &ValidatedKernel,
        role: PassRole,
    ) -> Result<(Arc<Pipeline>, PipelineTiming), GpuError> {
        let specialised = kernel.source().first_pass_override;
        let role = if specialised { role } else { PassRole::First };
        if let Some(p) = self.pipelines.lock().expect("pipeline cache lock").get(&(kernel.key(), role)) {
            return Ok((p.clone(), PipelineTiming { create: Duration::ZERO, cache_hit: true }));
        }
        self.check_bindings(kernel)?;
        let start = Instant::now();
        let checks = if self.kernel_checks.load(std::sync::atomic::Ordering::Relaxed) {
            RuntimeChecks::Full
        } else {
            RuntimeChecks::InBoundsByConstruction
        };
        let first = if role == PassRole::First { 1.0 } else { 0.0 };
        let constants: &[(&str, f64)] = if specialised { &[(crate::jit::FIRST_PASS, first)] } else { &[] };
        let pipeline = self.create_pipeline_with(kernel.validated(), "filterjit kernel", checks, constants).map_err(
            |message| GpuError::Pipeline {
                expression: kernel.source().canonical.clone(),
                message,
                wgsl: kernel.wgsl().to_string(),
            },
        )?;
        let pipeline = Arc::new(pipeline);
        let create = start.elapsed();
        self.pipelines.lock().expect("pipeline cache lock").insert((kernel.key(), role), pipeline.clone());
        Ok((pipeline, PipelineTiming { create, cache_hit: false }))
    }

    /// The pipeline of a built-in kernel, with its pipeline-overridable
    /// constant (if it has one, [`BuiltIn::overridable`]) set to `value`:
    /// got or made here, and only here. Its module is validated once per
    /// process, its pipeline made once per device and value; a kernel that
    /// does not validate, or that the driver refuses, is an error carrying
    /// its WGSL. Callers make the pipelines a frame needs before their GL
    /// turn, since creating one takes the turn itself.
    pub(crate) fn built_in(&self, kernel: BuiltIn, value: u32) -> Result<Arc<Pipeline>, GpuError> {
        let value = if kernel.overridable().is_some() { value } else { 0 };
        if let Some(p) = self.built_ins.lock().expect("pipeline cache lock").get(&(kernel, value)) {
            return Ok(p.clone());
        }
        let failed =
            |message: String| GpuError::Pipeline { expression: kernel.name().into(), message, wgsl: kernel.wgsl() };
        let validated = built_in_module(kernel).map_err(|message| failed(message.to_string()))?;
        let name = kernel.name().trim_matches(|c| c == '<' || c == '>');
        let (label, constants) = match kernel.overridable() {
            Some(constant) => (format!("filterjit {name} {constant}={value}"), vec![(constant, value as f64)]),
            None => (format!("filterjit {name}"), Vec::new()),
        };
        let pipeline =
            self.create_pipeline_with(&validated, &label, RuntimeChecks::Full, &constants).map_err(failed)?;
        let mut cache = self.built_ins.lock().expect("pipeline cache lock");
        Ok(cache.entry((kernel, value)).or_insert_with(|| Arc::new(pipeline)).clone())
    }

    /// A compute pipeline (entry point `main`) from a validated module, with
    /// an explicit layout made from the module's slots, inside a validation
    /// error scope; the error's text on failure.
    pub(crate) fn create_pipeline(&self, validated: &ValidatedModule, label: &str) -> Result<Pipeline, String> {
        self.create_pipeline_with(validated, label, RuntimeChecks::Full, &[])
    }

    /// Whether kernels keep wgpu's run-time bounds checks and loop bounding
    /// (on) or are created as trusted modules without them (off, the
    /// default): see [`RuntimeChecks::InBoundsByConstruction`]. Changing it
    /// empties the pipeline cache. Results are the same either way.
    pub fn set_kernel_runtime_checks(&self, on: bool) {
        self.kernel_checks.store(on, std::sync::atomic::Ordering::Relaxed);
        self.pipelines.lock().expect("pipeline cache lock").clear();
    }

    fn create_pipeline_with(
        &self,
        validated: &ValidatedModule,
        label: &str,
        checks: RuntimeChecks,
        constants: &[(&str, f64)],
    ) -> Result<Pipeline, String> {
        let _turn = self.gl_turn();
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let entries: Vec<wgpu::BindGroupLayoutEntry> = validated.slots().iter().map(layout_entry).collect();
        let layout = self
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries: &entries });
        let pipeline_layout = self.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let descriptor = wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Naga(std::borrow::Cow::Owned(validated.module().clone())),
        };
        let shader = match checks {
            RuntimeChecks::Full => self.device.create_shader_module(descriptor),
            // SAFETY: only filterjit's generated kernels come here, and every
            // access they make is in bounds by construction (see the variant);
            // every loop they run is bounded by the window, the stencil or the
            // workgroup size. The module was validated by naga.
            RuntimeChecks::InBoundsByConstruction => unsafe {
                self.device.create_shader_module_trusted(descriptor, wgpu::ShaderRuntimeChecks::unchecked())
            },
        };
        let pipeline = self.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: Some(&pipeline_layout),
            module: &shader,
            entry_point: Some("main"),
            compilation_options: wgpu::PipelineCompilationOptions { constants, ..Default::default() },
            cache: None,
        });
        match pollster::block_on(scope.pop()) {
            Some(error) => Err(error.to_string()),
            None => Ok(Pipeline { pipeline, layout, slots: validated.slots().iter().map(|s| s.slot).collect() }),
        }
    }

    /// The bind group of one dispatch of a kernel: every binding of its
    /// interface, filled by role.
    pub(crate) fn bind_group<'b>(
        &self,
        pipeline: &Pipeline,
        interface: &BindingInterface,
        resource: impl Fn(Role) -> wgpu::BindingResource<'b>,
    ) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = interface
            .bindings
            .iter()
            .map(|b| wgpu::BindGroupEntry { binding: b.slot, resource: resource(b.role) })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &pipeline.layout,
            entries: &entries,
        })
    }

    /// A buffer holding a dispatch's `Params`, of the kind a kernel binds
    /// them in (`BindingInterface::params`: a uniform buffer, or a read-only
    /// storage buffer for filterjit's own kernels, `jit::interface::own_params`).
    pub(crate) fn params_buffer(&self, params: Resource, label: &str, bytes: &[u8]) -> wgpu::Buffer {
        let usage = match params {
            Resource::Uniform => wgpu::BufferUsages::UNIFORM,
            Resource::ParamsStorage => wgpu::BufferUsages::STORAGE,
            other => panic!("Params are never bound as {other:?}"),
        };
        wgpu::util::DeviceExt::create_buffer_init(
            &self.device,
            &wgpu::util::BufferInitDescriptor { label: Some(label), contents: bytes, usage },
        )
    }

    /// The bind group of a module that is not a filterjit kernel (path
    /// tracer, interpreter): `resources` in the order of its slots.
    pub(crate) fn bind_in_slot_order(
        &self,
        pipeline: &Pipeline,
        resources: Vec<wgpu::BindingResource<'_>>,
    ) -> wgpu::BindGroup {
        assert_eq!(resources.len(), pipeline.slots.len(), "one resource per binding of the module");
        let entries: Vec<wgpu::BindGroupEntry> = pipeline
            .slots
            .iter()
            .zip(resources)
            .map(|(slot, resource)| wgpu::BindGroupEntry { binding: *slot, resource })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &pipeline.layout,
            entries: &entries,
        })
    }
}

/// Which of wgpu's run-time shader checks a module keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum RuntimeChecks {
    /// Bounds checks and loop bounding, as wgpu adds them to any module.
    Full,
    /// None: for filterjit's generated kernels, whose every buffer and
    /// workgroup-array index is in bounds by construction. The pixel index is
    /// y·width + x behind `x < width && y < height`; a neighbour's is inside
    /// the window clipped to the image (or an à-trous tap outside it is
    /// skipped); a tile cell is inside the tile the kernel declares; a
    /// workgroup's partial sum is at its index among the scene's workgroups,
    /// inside the region bound for that scene. Loops run over the window, the
    /// stencil or the reduction's strides. Other modules (path tracer,
    /// interpreter, pre-pass) keep the checks.
    InBoundsByConstruction,
}

/// A compute pipeline and the layout of its bind group 0.
#[derive(Debug)]
pub struct Pipeline {
    pub(crate) pipeline: wgpu::ComputePipeline,
    pub(crate) layout: wgpu::BindGroupLayout,
    /// The module's binding slots, ascending.
    slots: Vec<u32>,
}

/// A built-in kernel's module, validated once per process (the validation
/// error's text, which holds the WGSL, where it fails).
fn built_in_module(kernel: BuiltIn) -> Result<Arc<ValidatedModule>, Arc<str>> {
    type Modules = Mutex<HashMap<BuiltIn, Result<Arc<ValidatedModule>, Arc<str>>>>;
    static MODULES: OnceLock<Modules> = OnceLock::new();
    let modules = MODULES.get_or_init(Default::default);
    if let Some(module) = modules.lock().expect("module cache lock").get(&kernel) {
        return module.clone();
    }
    // Validated outside the lock: naga takes a while, and other kernels need not wait.
    let module = kernel.module().map(Arc::new).map_err(|e| Arc::from(e.to_string()));
    modules.lock().expect("module cache lock").entry(kernel).or_insert(module).clone()
}

/// The bind-group layout entry of one slot.
fn layout_entry(slot: &Slot) -> wgpu::BindGroupLayoutEntry {
    let buffer = |ty| wgpu::BindingType::Buffer { ty, has_dynamic_offset: false, min_binding_size: None };
    let ty = match slot.access {
        Access::Uniform => buffer(wgpu::BufferBindingType::Uniform),
        Access::StorageRead => buffer(wgpu::BufferBindingType::Storage { read_only: true }),
        Access::StorageReadWrite => buffer(wgpu::BufferBindingType::Storage { read_only: false }),
        Access::SampledTexture => wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable: false },
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        Access::StorageTexture(format) => wgpu::BindingType::StorageTexture {
            access: wgpu::StorageTextureAccess::WriteOnly,
            format: match format {
                TexelFormat::Color(OutputFormat::Rgba16float) => wgpu::TextureFormat::Rgba16Float,
                TexelFormat::Color(OutputFormat::Rgba32float) => wgpu::TextureFormat::Rgba32Float,
                TexelFormat::R32float => wgpu::TextureFormat::R32Float,
            },
            view_dimension: wgpu::TextureViewDimension::D2,
        },
    };
    wgpu::BindGroupLayoutEntry { binding: slot.slot, visibility: wgpu::ShaderStages::COMPUTE, ty, count: None }
}
