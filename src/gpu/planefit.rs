//! `planefit` on the device (`jit::planefit`): one pipeline per device, one
//! dispatch after the form's last pass; `cpu::planefit` is its reference.

use std::sync::Arc;

use super::buffers::SceneBuffers;
use super::{Gpu, GpuError, Pipeline};
use crate::jit::interface::Element;
use crate::jit::{BindingInterface, BuiltIn, Input, PlaneFitParams, Role, WORKGROUP};
use crate::lang::Feature;
use crate::pipeline::PlaneFit;

impl Gpu {
    /// The kernel's pipeline for a form that did (a window) or did not (à
    /// trous) multiply the modulation back. Callers make it before their GL
    /// turn, since creating a pipeline takes the turn itself and turns never nest.
    pub(super) fn planefit_pipeline(&self, remodulated: bool) -> Result<Arc<Pipeline>, GpuError> {
        self.built_in(BuiltIn::PlaneFit, u32::from(remodulated))
    }

    /// The fitness kernel's pipeline (made before the GL turn, as above).
    pub(super) fn planefit_terms_pipeline(&self) -> Result<Arc<Pipeline>, GpuError> {
        self.built_in(BuiltIn::PlaneFitTerms, 0)
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
        let normal = buffers.inputs.get(&Input::Feature(Feature::Normal)).expect("the normals are uploaded first");
        // Without demodulation the modulation is not read: the reference stands in.
        let modulation = buffers.modulation.as_ref().unwrap_or(reference);
        let images = Images {
            image,
            normal: normal.as_entire_binding(),
            modulation: modulation.as_entire_binding(),
            output: terms,
        };
        self.record_planefit(encoder, &kernel, &interface, buffers, fit, images, Some(reference));
        Ok(())
    }

    /// Record `fit` of the form's output `image` into `encoder`, returning the
    /// buffer it writes. The kernel samples its images: `image` is blitted
    /// into a texture first, the normals and modulation where they are not on
    /// one yet. The scene's normals are on the device already
    /// (`SceneBuffers::ensure`); callers hold the GL turn and made the blit's
    /// pipelines before it.
    pub(super) fn planefit(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        buffers: &mut SceneBuffers,
        fit: PlaneFit,
        image: &wgpu::Buffer,
    ) -> Result<wgpu::Buffer, GpuError> {
        let kernel = self.planefit_pipeline(!buffers.pipeline.is_atrous())?;
        let interface = BindingInterface::planefit(None);
        let size = (buffers.width, buffers.height);
        let fitted = self.device().create_buffer(&wgpu::BufferDescriptor {
            label: Some("planefit"),
            size: (size.0 * size.1) as u64 * 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let colour = self.blitted(encoder, image, Element::Vec4F32, size)?.create_view(&Default::default());
        let normal = Role::Input(Input::Feature(Feature::Normal));
        let roles: &[Role] = if buffers.modulation.is_some() { &[normal, Role::Modulation] } else { &[normal] };
        let views = buffers.sampled_views(self, encoder, roles, 0, None)?;
        // Without demodulation the modulation is not read: the image stands in.
        let modulation = views.get(&Role::Modulation).unwrap_or(&colour);
        let images = Images {
            image: wgpu::BindingResource::TextureView(&colour),
            normal: wgpu::BindingResource::TextureView(&views[&normal]),
            modulation: wgpu::BindingResource::TextureView(modulation),
            output: &fitted,
        };
        self.record_planefit(encoder, &kernel, &interface, buffers, fit, images, None);
        Ok(fitted)
    }

    /// One dispatch of a `planefit` kernel over the whole image, its
    /// bindings filled by role from `images` and, for the fitness kernel,
    /// `reference`.
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
        let bind_group = self.bind_group(kernel, interface, |role| match role {
            Role::Params => uniform.as_entire_binding(),
            Role::Color => images.image.clone(),
            Role::Input(_) => images.normal.clone(),
            Role::Modulation => images.modulation.clone(),
            Role::Reference => reference.expect("the fitness kernel is given the reference").as_entire_binding(),
            Role::Output => images.output.as_entire_binding(),
            other => unreachable!("planefit has no {other:?} binding"),
        });
        let mut pass = self.compute_pass(encoder, "planefit");
        pass.set_pipeline(&kernel.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(buffers.width.div_ceil(WORKGROUP[0]), buffers.height.div_ceil(WORKGROUP[1]), 1);
    }
}

/// What a `planefit` dispatch reads and writes.
struct Images<'a> {
    image: wgpu::BindingResource<'a>,
    normal: wgpu::BindingResource<'a>,
    modulation: wgpu::BindingResource<'a>,
    output: &'a wgpu::Buffer,
}
