//! `planefit` on the device (`jit::planefit`): one pipeline per device, one
//! dispatch after the form's last pass; `cpu::planefit` is its reference.

use std::sync::OnceLock;

use super::filter::SceneBuffers;
use super::{Gpu, GpuError, Pipeline};
use crate::jit::{BindingInterface, Input, PlaneFitParams, Role, ValidatedModule, WORKGROUP};
use crate::lang::Feature;
use crate::pipeline::PlaneFit;

impl Gpu {
    /// The kernel's pipeline. Callers make it before their GL turn, since
    /// creating a pipeline takes the turn itself and turns never nest.
    pub(super) fn planefit_pipeline(&self) -> Result<&Pipeline, GpuError> {
        static MODULE: OnceLock<Result<ValidatedModule, String>> = OnceLock::new();
        let validate = || crate::jit::planefit_module(None).map_err(|e| e.to_string());
        self.built_in(&self.planefit, &MODULE, "<planefit>", validate, || crate::jit::planefit_wgsl(None))
    }

    /// The fitness kernel's pipeline (made before the GL turn, as above).
    pub(super) fn planefit_terms_pipeline(&self) -> Result<&Pipeline, GpuError> {
        static MODULE: OnceLock<Result<ValidatedModule, String>> = OnceLock::new();
        let validate = || crate::jit::planefit_terms_module().map_err(|e| e.to_string());
        self.built_in(&self.planefit_terms, &MODULE, "<planefit terms>", validate, crate::jit::planefit_terms_wgsl)
    }

    /// Record into `encoder` the fitness kernel: `fit` of the form's last
    /// image before remodulation (`image`), its relMSE terms against
    /// `reference` and luminance written over `terms` (member 0's).
    pub(super) fn planefit_terms(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        buffers: &SceneBuffers,
        fit: PlaneFit,
        image: wgpu::BindingResource<'_>,
        reference: &wgpu::Buffer,
        terms: &wgpu::Buffer,
    ) -> Result<(), GpuError> {
        let kernel = self.planefit_terms_pipeline()?;
        let interface = BindingInterface::planefit_terms();
        // Without demodulation the modulation is not read: the reference stands in.
        let images = Images { image, modulation: buffers.modulation.as_ref().unwrap_or(reference), output: terms };
        self.record_planefit(encoder, kernel, &interface, buffers, fit, images, Some(reference));
        Ok(())
    }

    /// Record `fit` of the form's output `image` into `encoder`, returning the
    /// buffer it writes. The scene's normals are on the device already
    /// (`SceneBuffers::ensure`); callers hold the GL turn.
    pub(super) fn planefit(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        buffers: &SceneBuffers,
        fit: PlaneFit,
        image: &wgpu::Buffer,
    ) -> Result<wgpu::Buffer, GpuError> {
        let kernel = self.planefit_pipeline()?;
        let interface = BindingInterface::planefit(None);
        let fitted = self.device().create_buffer(&wgpu::BufferDescriptor {
            label: Some("planefit"),
            size: (buffers.width * buffers.height) as u64 * 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        // Without demodulation the modulation is not read: the image stands in.
        let modulation = buffers.modulation.as_ref().unwrap_or(image);
        let images = Images { image: image.as_entire_binding(), modulation, output: &fitted };
        self.record_planefit(encoder, kernel, &interface, buffers, fit, images, None);
        Ok(fitted)
    }

    /// One dispatch of a `planefit` kernel over the whole image, its
    /// bindings filled by role from `images`, the scene's normals and, for
    /// the fitness kernel, `reference`.
    #[allow(clippy::too_many_arguments)]
    fn record_planefit(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        kernel: &Pipeline,
        interface: &BindingInterface,
        buffers: &SceneBuffers,
        fit: PlaneFit,
        images: Images<'_>,
        reference: Option<&wgpu::Buffer>,
    ) {
        let params = PlaneFitParams::of(&buffers.pipeline, fit, buffers.width, buffers.height);
        let uniform = self.params_buffer(interface.params(), "planefit params", bytemuck::bytes_of(&params));
        let normal = buffers.inputs.get(&Input::Feature(Feature::Normal)).expect("the normals are uploaded first");
        let bind_group = self.bind_group(kernel, interface, |role| match role {
            Role::Params => uniform.as_entire_binding(),
            Role::Color => images.image.clone(),
            Role::Input(_) => normal.as_entire_binding(),
            Role::Modulation => images.modulation.as_entire_binding(),
            Role::Reference => reference.expect("the fitness kernel is given the reference").as_entire_binding(),
            Role::Output => images.output.as_entire_binding(),
            other => unreachable!("planefit has no {other:?} binding"),
        });
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&kernel.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(buffers.width.div_ceil(WORKGROUP[0]), buffers.height.div_ceil(WORKGROUP[1]), 1);
    }
}

/// What a `planefit` dispatch reads and writes besides its normals.
struct Images<'a> {
    image: wgpu::BindingResource<'a>,
    modulation: &'a wgpu::Buffer,
    output: &'a wgpu::Buffer,
}
