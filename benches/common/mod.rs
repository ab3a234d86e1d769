//! What the device benches share: the adapter wgpu picks (`WGPU_BACKEND`
//! narrows it), a compute pipeline from WGSL, and the median time of a
//! recorded dispatch.

use std::time::Instant;

/// The device and queue of the adapter wgpu picks; prints which it is, after `title`.
pub fn device(title: &str) -> (wgpu::Device, wgpu::Queue) {
    let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle();
    descriptor.backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::all());
    let instance = wgpu::Instance::new(descriptor);
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))
        .expect("a GPU adapter (on Linux without a GPU: apt-get install -y mesa-vulkan-drivers)");
    println!("{title} on {} ({:?})", adapter.get_info().name, adapter.get_info().backend);
    pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor::default())).expect("a device")
}

/// The compute pipeline of `source`'s `main`, its layout read from the shader.
pub fn pipeline(device: &wgpu::Device, source: String) -> wgpu::ComputePipeline {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: None,
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: None,
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    })
}

/// The median wall time, ms, of `rounds` submissions of what `record`
/// records, each waited for; the first is left out (software drivers
/// compile at the first dispatch).
pub fn median_ms(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    rounds: usize,
    record: impl Fn(&mut wgpu::CommandEncoder),
) -> f64 {
    let mut times: Vec<f64> = (0..rounds)
        .map(|_| {
            let mut encoder = device.create_command_encoder(&Default::default());
            record(&mut encoder);
            let start = Instant::now();
            queue.submit([encoder.finish()]);
            device.poll(wgpu::PollType::wait_indefinitely()).expect("the dispatch finishes");
            start.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    times.remove(0);
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

/// Record one dispatch of `pipeline` with `group` over `groups` workgroups.
pub fn dispatch(
    encoder: &mut wgpu::CommandEncoder,
    pipeline: &wgpu::ComputePipeline,
    group: &wgpu::BindGroup,
    groups: (u32, u32),
) {
    let mut pass = encoder.begin_compute_pass(&Default::default());
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, group, &[]);
    pass.dispatch_workgroups(groups.0, groups.1, 1);
}
