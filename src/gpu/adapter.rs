//! The one place that chooses a wgpu adapter.
//!
//! Order: a hardware GPU (discrete, then integrated, then virtual), then
//! software: lavapipe (Vulkan), then llvmpipe (GL through EGL).
//! A [`Request`] (from `FILTERJIT_BACKEND=vulkan|gl|metal|dx12` and
//! `FILTERJIT_ADAPTER=text`, read by [`crate::environment`]) restricts the
//! search to some backends, or picks the first adapter whose name contains `text`.
//! MPI ranks on one node take the node's best adapters in turn ([`choose_for`]).

use super::GpuError;

/// Which adapters the user allows: the backends to search and, optionally,
/// text the adapter's name must contain. Read from the environment at the
/// edge ([`crate::environment`]); the default is every native backend.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Request {
    pub backends: wgpu::Backends,
    pub name: Option<String>,
    /// On a software device, ask the C library to keep freed images for the
    /// next frame's (`gpu::host_memory`); false where the user set one of its
    /// own knobs (`environment::MALLOC_KNOBS`).
    pub keep_freed_images: bool,
}

impl Default for Request {
    fn default() -> Self {
        Request { backends: ALL_NATIVE, name: None, keep_freed_images: true }
    }
}

const ALL_NATIVE: wgpu::Backends =
    wgpu::Backends::VULKAN.union(wgpu::Backends::GL).union(wgpu::Backends::METAL).union(wgpu::Backends::DX12);

/// The backends a backend name (`FILTERJIT_BACKEND`'s value) stands for.
pub fn backends_named(value: &str) -> Result<wgpu::Backends, GpuError> {
    match value.to_ascii_lowercase().as_str() {
        "" | "any" | "auto" => Ok(ALL_NATIVE),
        "vulkan" | "vk" => Ok(wgpu::Backends::VULKAN),
        "gl" | "gles" | "opengl" | "egl" => Ok(wgpu::Backends::GL),
        "metal" => Ok(wgpu::Backends::METAL),
        "dx12" | "d3d12" => Ok(wgpu::Backends::DX12),
        other => Err(GpuError::BadBackend(other.to_string())),
    }
}

/// Lower is better.
fn rank(info: &wgpu::AdapterInfo) -> (u8, u8) {
    let device = match info.device_type {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    };
    let backend = match info.backend {
        wgpu::Backend::Vulkan | wgpu::Backend::Metal | wgpu::Backend::Dx12 => 0,
        wgpu::Backend::Gl => 1,
        _ => 2,
    };
    (device, backend)
}

/// Every adapter the requested backends offer, best first.
fn candidates(instance: &wgpu::Instance, backends: wgpu::Backends) -> Vec<wgpu::Adapter> {
    let mut adapters = pollster::block_on(instance.enumerate_adapters(backends));
    adapters.retain(|a| a.get_downlevel_capabilities().flags.contains(wgpu::DownlevelFlags::COMPUTE_SHADERS));
    adapters.sort_by_key(|a| rank(&a.get_info()));
    adapters
}

/// An instance restricted to `backends`.
pub fn new_instance(backends: wgpu::Backends) -> wgpu::Instance {
    let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle();
    descriptor.backends = backends;
    wgpu::Instance::new(descriptor)
}

/// Every adapter on offer, best first. Native backends are asked first; GL
/// (and the start-up noise of EGL) only when they offer nothing, unless `all`.
pub fn available(backends: wgpu::Backends, all: bool) -> Vec<wgpu::Adapter> {
    let native = backends & !wgpu::Backends::GL;
    let mut adapters = candidates(&new_instance(native), native);
    if (adapters.is_empty() || all) && backends.contains(wgpu::Backends::GL) {
        adapters.extend(candidates(&new_instance(wgpu::Backends::GL), wgpu::Backends::GL));
    }
    adapters
}

/// Choose the adapter `request` allows.
pub fn choose(request: &Request) -> Result<wgpu::Adapter, GpuError> {
    choose_for(request, 0)
}

/// Choose the adapter for the `index`-th process on a machine (an MPI rank's
/// place on its node): the `index mod n`-th of the n best adapters of the
/// same kind, so that ranks spread over a node's GPUs. A name in `request`,
/// when given, wins for every process.
pub fn choose_for(request: &Request, index: usize) -> Result<wgpu::Adapter, GpuError> {
    let backends = request.backends;
    match &request.name {
        Some(text) if !text.is_empty() => {
            let adapters = available(backends, true);
            let names: Vec<String> = adapters.iter().map(|a| a.get_info().name).collect();
            adapters
                .into_iter()
                .find(|a| a.get_info().name.to_lowercase().contains(&text.to_lowercase()))
                .ok_or(GpuError::NoMatchingAdapter { wanted: text.clone(), found: names })
        }
        _ => {
            let mut adapters = available(backends, false);
            let best = adapters.first().map(|a| rank(&a.get_info()));
            adapters.retain(|a| Some(rank(&a.get_info())) == best);
            match adapters.len() {
                0 => Err(GpuError::NoAdapter { backends: format!("{backends:?}") }),
                n => Ok(adapters.swap_remove(index % n)),
            }
        }
    }
}
