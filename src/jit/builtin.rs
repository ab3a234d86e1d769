//! filterjit's own kernels, the ones no expression is compiled into: the
//! path tracer, the pre-pass and its spreads, `planefit`, `pixelfilter`, the blits, the
//! fitness reduction and the temporal stage. One list, so that the device
//! gets, validates and caches every one of them the same way
//! (`gpu::Gpu::built_in`), and every error carries the kernel's WGSL.

use super::interface::Element;
use super::validate::{validate_module, ValidateError, ValidatedModule};
use crate::pipeline::Keep;

/// A built-in kernel, as filterjit runs it itself (storage buffers out;
/// exported variants are `export`'s).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BuiltIn {
    /// `templates/pathtrace.wgsl`.
    PathTracer,
    /// Outliers and demodulation (`jit::prepass`).
    Prepass,
    /// `keep`'s spread of what the clamp removed, `keep=surface`'s along the
    /// surface (`jit::spread`), one pipeline per [`super::SPREAD_STAGE`].
    Spread(Keep),
    /// `planefit` after the form (`jit::planefit`), one pipeline per
    /// [`super::PLANEFIT_REMODULATED`].
    PlaneFit,
    /// `planefit` as a fitness kernel.
    PlaneFitTerms,
    /// `anchor`, after the form and `planefit` (`jit::anchor`).
    Anchor,
    /// `pixelfilter`, the last stage (`jit::pixel_filter`).
    PixelFilter,
    /// A storage buffer of `Element`s into a texture of the same values (`jit::blit`).
    Blit(Element),
    /// The fitness reduction (`jit::reduce`).
    Reduce,
    /// The temporal stage: reprojection, history and moments (`jit::temporal`).
    Temporal,
    /// The temporal stage's variance, prefiltered (`jit::temporal`).
    TemporalVariance,
}

impl BuiltIn {
    /// How messages name it.
    pub fn name(self) -> &'static str {
        match self {
            BuiltIn::PathTracer => "<path tracer>",
            BuiltIn::Prepass => "<pre-pass>",
            BuiltIn::Spread(Keep::Even) => "<spread>",
            BuiltIn::Spread(Keep::Surface) => "<surface spread>",
            BuiltIn::PlaneFit => "<planefit>",
            BuiltIn::PlaneFitTerms => "<planefit terms>",
            BuiltIn::Anchor => "<anchor>",
            BuiltIn::PixelFilter => "<pixelfilter>",
            BuiltIn::Blit(_) => "<blit>",
            BuiltIn::Reduce => "<fitness reduction>",
            BuiltIn::Temporal => "<temporal>",
            BuiltIn::TemporalVariance => "<temporal variance>",
        }
    }

    /// Its WGSL.
    pub fn wgsl(self) -> String {
        match self {
            BuiltIn::PathTracer => PATHTRACE_WGSL.to_string(),
            BuiltIn::Prepass => super::prepass_wgsl(None),
            BuiltIn::Spread(Keep::Even) => super::spread_wgsl(None),
            BuiltIn::Spread(Keep::Surface) => super::spread_surface_wgsl(None),
            BuiltIn::PlaneFit => super::planefit_wgsl(None),
            BuiltIn::PlaneFitTerms => super::planefit_terms_wgsl(),
            BuiltIn::Anchor => super::anchor_wgsl(None),
            BuiltIn::PixelFilter => super::pixel_filter_wgsl(None),
            BuiltIn::Blit(element) => super::blit_wgsl(element),
            BuiltIn::Reduce => super::reduce_wgsl(),
            BuiltIn::Temporal => super::temporal_wgsl(None),
            BuiltIn::TemporalVariance => super::temporal_variance_wgsl(None),
        }
    }

    /// Its module, validated by naga (and, for the kernels with a binding
    /// interface, checked against it).
    pub fn module(self) -> Result<ValidatedModule, ValidateError> {
        match self {
            BuiltIn::PathTracer => validate_module(PATHTRACE_WGSL, self.name()),
            BuiltIn::Prepass => super::prepass_module(None),
            BuiltIn::Spread(Keep::Even) => super::spread_module(None),
            BuiltIn::Spread(Keep::Surface) => super::spread_surface_module(None),
            BuiltIn::PlaneFit => super::planefit_module(None),
            BuiltIn::PlaneFitTerms => super::planefit_terms_module(),
            BuiltIn::Anchor => super::anchor_module(None),
            BuiltIn::PixelFilter => super::pixel_filter_module(None),
            BuiltIn::Blit(element) => super::blit_module(element),
            BuiltIn::Reduce => super::reduce_module(),
            BuiltIn::Temporal => super::temporal_module(None),
            BuiltIn::TemporalVariance => super::temporal_variance_module(None),
        }
    }

    /// The pipeline-overridable constant a pipeline of it sets, if it has
    /// one: the device makes one pipeline per value.
    pub fn overridable(self) -> Option<&'static str> {
        match self {
            BuiltIn::Spread(_) => Some(super::SPREAD_STAGE),
            BuiltIn::PlaneFit => Some(super::PLANEFIT_REMODULATED),
            _ => None,
        }
    }

    /// Every built-in kernel.
    pub const ALL: [BuiltIn; 13] = [
        BuiltIn::PathTracer,
        BuiltIn::Prepass,
        BuiltIn::Spread(Keep::Even),
        BuiltIn::Spread(Keep::Surface),
        BuiltIn::PlaneFit,
        BuiltIn::PlaneFitTerms,
        BuiltIn::Anchor,
        BuiltIn::PixelFilter,
        BuiltIn::Blit(Element::F32),
        BuiltIn::Blit(Element::Vec4F32),
        BuiltIn::Reduce,
        BuiltIn::Temporal,
        BuiltIn::TemporalVariance,
    ];
}

/// The path tracer's source.
pub const PATHTRACE_WGSL: &str = include_str!("../../templates/pathtrace.wgsl");

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_built_in_kernel_validates() {
        for kernel in BuiltIn::ALL {
            let module = kernel.module().unwrap_or_else(|e| panic!("{}: {e}", kernel.name()));
            assert!(!module.slots().is_empty(), "{} binds something", kernel.name());
            assert!(kernel.wgsl().contains("fn main"), "{}", kernel.name());
        }
    }
}
