//! The one place that chooses a wgpu adapter.
//!
//! Order: a hardware GPU (discrete, then integrated, then virtual), then
//! software: lavapipe (Vulkan), then llvmpipe (GL through EGL).
//! `FILTERJIT_BACKEND=vulkan|gl|metal|dx12` restricts the search to one backend;
//! `FILTERJIT_ADAPTER=text` picks the first adapter whose name contains `text`.
//! MPI ranks on one node take the node's best adapters in turn ([`choose_for`]).

use super::GpuError;

/// Environment variable that forces a backend.
pub const BACKEND_ENV: &str = "FILTERJIT_BACKEND";
/// Environment variable that picks an adapter by name.
pub const ADAPTER_ENV: &str = "FILTERJIT_ADAPTER";

/// Backends named by `FILTERJIT_BACKEND`, or every native backend.
pub fn requested_backends() -> Result<wgpu::Backends, GpuError> {
    match std::env::var(BACKEND_ENV) {
        Err(_) => Ok(wgpu::Backends::VULKAN | wgpu::Backends::GL | wgpu::Backends::METAL | wgpu::Backends::DX12),
        Ok(value) => match value.to_ascii_lowercase().as_str() {
            "" | "any" | "auto" => {
                Ok(wgpu::Backends::VULKAN | wgpu::Backends::GL | wgpu::Backends::METAL | wgpu::Backends::DX12)
            }
            "vulkan" | "vk" => Ok(wgpu::Backends::VULKAN),
            "gl" | "gles" | "opengl" | "egl" => Ok(wgpu::Backends::GL),
            "metal" => Ok(wgpu::Backends::METAL),
            "dx12" | "d3d12" => Ok(wgpu::Backends::DX12),
            other => Err(GpuError::BadBackend(other.to_string())),
        },
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

/// Choose the adapter, honouring the environment.
pub fn choose() -> Result<wgpu::Adapter, GpuError> {
    choose_for(0)
}

/// Choose the adapter for the `index`-th process on a machine (an MPI rank's
/// place on its node): the `index mod n`-th of the n best adapters of the
/// same kind, so that ranks spread over a node's GPUs. `FILTERJIT_ADAPTER`,
/// when set, wins for every process.
pub fn choose_for(index: usize) -> Result<wgpu::Adapter, GpuError> {
    let backends = requested_backends()?;
    match std::env::var(ADAPTER_ENV) {
        Ok(text) if !text.is_empty() => {
            let adapters = available(backends, true);
            let names: Vec<String> = adapters.iter().map(|a| a.get_info().name).collect();
            adapters
                .into_iter()
                .find(|a| a.get_info().name.to_lowercase().contains(&text.to_lowercase()))
                .ok_or(GpuError::NoMatchingAdapter { wanted: text, found: names })
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
