//! Fitness on the device: many kernels on many scenes in few submissions.
//! A fitness kernel writes every pixel's relMSE terms and output luminance
//! for each of its members; the reduction kernel (`jit::reduce`) sums them
//! per workgroup; only the partial sums come back.

use std::collections::HashMap;
use std::sync::Arc;

use wgpu::util::DeviceExt;

use super::buffers::SceneBuffers;
use super::filter::{rows_per_dispatch, uniform_bytes};
use super::{Gpu, GpuError, Pipeline};
use crate::jit::interface::{own_params, Element};
use crate::jit::{BuiltIn, Input, KernelKind, Params, ReduceParams, Role, ValidatedKernel, WORKGROUP};
use crate::lang::Feature;
use crate::pipeline::FilterPipeline;
use crate::scene::Scene;

/// Dispatches per submission: small enough to keep each submission short.
const DISPATCHES_PER_SUBMISSION: usize = 64;

/// A scene with its reference on the device, and room for the per-pixel
/// terms of the largest fitness kernel it has scored (reused by every kernel).
pub struct FitnessScene {
    buffers: SceneBuffers,
    reference: wgpu::Buffer,
    width: u32,
    height: u32,
    /// Per-pixel terms and flags, and how many members they have room for.
    terms: Option<(wgpu::Buffer, wgpu::Buffer, u32)>,
    /// The pixels whose errors count (all when `None`): the interiors of
    /// fitness tiles, disjoint, whose halo only feeds the filter.
    counted: Option<Vec<Region>>,
}

/// A rectangle of pixels whose sides lie on workgroup boundaries, so that it
/// is a set of whole reduction partials.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Region {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

impl Region {
    /// How many pixels it holds.
    pub fn pixels(&self) -> u32 {
        self.width * self.height
    }

    /// Whether every side lies on a workgroup boundary.
    pub fn is_aligned(&self) -> bool {
        [self.x, self.width].iter().all(|v| v % WORKGROUP[0] == 0)
            && [self.y, self.height].iter().all(|v| v % WORKGROUP[1] == 0)
    }

    /// The reduction partials (workgroup indices) of an image `width` pixels across that the region covers.
    fn partials(&self, width: u32) -> impl Iterator<Item = usize> {
        let across = width.div_ceil(WORKGROUP[0]);
        let (x0, y0) = (self.x / WORKGROUP[0], self.y / WORKGROUP[1]);
        let (w, h) = (self.width / WORKGROUP[0], self.height / WORKGROUP[1]);
        (y0..y0 + h).flat_map(move |gy| (x0..x0 + w).map(move |gx| (gy * across + gx) as usize))
    }
}

/// What one kernel scored on one scene: its error, light and domain flags
/// (a measurement; a scene that cannot be read is a `scene::SceneError`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneScore {
    /// relMSE (equation 3.5 without the m/2 factor) of the filtered image.
    pub relmse: f64,
    /// The filtered image's mean luminance (`pipeline::luminance`) over the
    /// same pixels: what the fitness rule's light is measured from.
    pub luminance: f64,
    /// Union of the domain-error bits of every pixel.
    pub flags: u32,
    /// Whether the reduced error was finite.
    pub finite: bool,
}

impl FitnessScene {
    /// A scene for the thesis's filter (no pre-pass, one window).
    pub fn new(gpu: &Gpu, scene: &Scene) -> Result<Self, GpuError> {
        Self::for_pipeline(gpu, scene, &FilterPipeline::WINDOW)
    }

    /// A scene prepared for `pipeline`: its pre-pass runs here, once.
    pub fn for_pipeline(gpu: &Gpu, scene: &Scene, pipeline: &FilterPipeline) -> Result<Self, GpuError> {
        // The fit reads the form's last image, which only an à-trous fitness kernel writes.
        if pipeline.planefit.is_some() && !pipeline.is_atrous() {
            return Err(GpuError::PlaneFitAfterWindow { pipeline: *pipeline });
        }
        if pipeline.pixel_filter.is_some() {
            return Err(GpuError::PixelFilterScored { pipeline: *pipeline });
        }
        if pipeline.anchor.is_some() {
            return Err(GpuError::AnchorScored { pipeline: *pipeline });
        }
        let reference =
            scene.reference.as_ref().ok_or_else(|| GpuError::MissingReference { scene: scene.name.clone() })?;
        let rgba: Vec<[f32; 4]> = reference.iter().map(|c| [c[0], c[1], c[2], 1.0]).collect();
        let reference = gpu.device().create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("reference"),
            contents: bytemuck::cast_slice(&rgba),
            usage: wgpu::BufferUsages::STORAGE,
        });
        Ok(FitnessScene {
            buffers: SceneBuffers::for_pipeline(gpu, scene, pipeline)?,
            reference,
            width: scene.width as u32,
            height: scene.height as u32,
            terms: None,
            counted: None,
        })
    }

    /// Count only the errors in `regions` (disjoint, their sides on workgroup
    /// boundaries, inside the scene).
    pub fn counting(mut self, regions: Vec<Region>) -> Self {
        for region in &regions {
            assert!(region.is_aligned(), "a counted region lies on workgroup boundaries: {region:?}");
            assert!(
                region.x + region.width <= self.width && region.y + region.height <= self.height,
                "{region:?} inside"
            );
        }
        assert!(!regions.is_empty(), "a scene counts some pixels");
        self.counted = Some(regions);
        self
    }

    fn groups(&self) -> u64 {
        self.width.div_ceil(WORKGROUP[0]) as u64 * self.height.div_ceil(WORKGROUP[1]) as u64
    }

    /// Make room for the terms of kernels with up to `members` members.
    fn ensure_terms(&mut self, gpu: &Gpu, members: u32) {
        if self.terms.as_ref().is_some_and(|(_, _, room)| *room >= members) {
            return;
        }
        let pixels = (self.width as u64 * self.height as u64 * members as u64).max(1);
        let make = |label, bytes| {
            gpu.device().create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: pixels * bytes,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            })
        };
        // Each pixel's pair (relMSE terms, luminance), and its flags.
        self.terms = Some((make("fitness terms", 8), make("fitness pixel flags", 4), members));
    }
}

/// A full evaluation, or one workgroup per kernel to make the driver compile.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Pass {
    Prime,
    Full,
}

impl Gpu {
    fn reduce_pipeline(&self) -> Result<Arc<Pipeline>, GpuError> {
        self.built_in(BuiltIn::Reduce, 0)
    }

    /// Create the pipelines of `kernels` on up to `threads` threads (cache hits are free).
    pub fn prepare_pipelines(&self, kernels: &[&ValidatedKernel], threads: usize) -> Result<(), GpuError> {
        crate::parallel::map(kernels, threads, |k| self.pipeline(k).map(|_| ())).into_iter().collect()
    }

    /// Keep only the cached pipelines for which `keep` holds.
    pub fn prune_pipelines(&self, keep: impl Fn(&crate::jit::KernelKey) -> bool) {
        self.pipelines.lock().expect("pipeline cache lock").retain(|(k, _), _| keep(k));
    }

    /// Evaluate every fitness kernel on every scene. `result[m][s]` is member
    /// m on scene s, members in kernel order (one per kernel unless fused).
    pub fn evaluate_fitness(
        &self,
        kernels: &[&ValidatedKernel],
        scenes: &mut [FitnessScene],
        data: &[&Scene],
        radius: u32,
    ) -> Result<Vec<Vec<SceneScore>>, GpuError> {
        self.run_fitness(kernels, scenes, data, radius, Pass::Full)
    }

    /// One workgroup of every kernel on the first scene, results discarded:
    /// drivers that compile a pipeline at its first dispatch (Mesa's
    /// lavapipe and llvmpipe) do it here, so that the time of this call is
    /// the driver's compile and [`Gpu::evaluate_fitness`] afterwards is the
    /// evaluation alone. It changes no result.
    pub fn prime_fitness(
        &self,
        kernels: &[&ValidatedKernel],
        scenes: &mut [FitnessScene],
        data: &[&Scene],
        radius: u32,
    ) -> Result<(), GpuError> {
        let first = scenes.len().min(1);
        self.run_fitness(kernels, &mut scenes[..first], &data[..first], radius, Pass::Prime).map(|_| ())
    }

    fn run_fitness(
        &self,
        kernels: &[&ValidatedKernel],
        scenes: &mut [FitnessScene],
        data: &[&Scene],
        radius: u32,
        run: Pass,
    ) -> Result<Vec<Vec<SceneScore>>, GpuError> {
        assert_eq!(scenes.len(), data.len(), "one FitnessScene per Scene");
        for k in kernels {
            assert_eq!(k.source().kind, KernelKind::Fitness, "evaluate_fitness runs fitness kernels");
            super::check_radius(k, radius)?;
            for fs in scenes.iter() {
                fs.buffers.check_shape(k)?;
            }
        }
        let device = self.device();
        let mut pipelines = Vec::with_capacity(kernels.len());
        for k in kernels {
            pipelines.push(self.pipeline(k)?.0);
            self.prepare_guide_for(k)?;
        }
        let reduce = self.reduce_pipeline()?;
        if scenes.iter().any(|fs| fs.buffers.pipeline.planefit.is_some()) {
            self.planefit_terms_pipeline()?;
        }
        let sampled: Vec<Vec<Role>> = kernels.iter().map(|k| super::sampled::sampled_roles(k)).collect();
        if sampled.iter().any(|roles| !roles.is_empty()) {
            self.blit_pipeline(Element::Vec4F32)?;
            self.blit_pipeline(Element::F32)?;
        }
        let reduce_interface = crate::jit::BindingInterface::reduce();
        let _turn = self.gl_turn();
        let members: Vec<u32> = kernels.iter().map(|k| k.source().exprs.len() as u32).collect();
        let most = members.iter().copied().max().unwrap_or(1);
        for k in kernels {
            for (fs, scene) in scenes.iter_mut().zip(data) {
                fs.buffers.check_inputs(k, scene)?;
                for (_, input) in k.source().interface.inputs() {
                    fs.buffers.ensure(self, scene, input)?;
                }
                if fs.buffers.pipeline.planefit.is_some() {
                    fs.buffers.ensure(self, scene, Input::Feature(Feature::Normal))?;
                }
            }
        }
        for fs in scenes.iter_mut() {
            fs.ensure_terms(self, most);
        }

        // One region of the partials buffers per (member, scene), aligned for binding offsets.
        let align = (self.limits.min_storage_buffer_offset_alignment as u64 / 4).max(1);
        let mut offsets = Vec::new();
        let mut total = 0u64;
        for _ in 0..members.iter().sum::<u32>() {
            for fs in scenes.iter() {
                offsets.push(total);
                total += fs.groups().div_ceil(align) * align;
            }
        }
        let total = total.max(1);
        let make = |label, bytes| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: total * bytes,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        };
        // A partial is a pair (relMSE terms, luminance); its flags one word.
        let partials = make("partials", 8);
        let partial_flags = make("partial flags", 4);

        // Parameters per scene, pass and band, shared by every kernel: (uniform, level, rows).
        let bands: Vec<Vec<(wgpu::Buffer, u32, u32)>> = scenes
            .iter()
            .map(|fs| {
                let pipeline = fs.buffers.pipeline;
                let atrous = pipeline.is_atrous();
                let passes = pipeline.passes();
                let rows = rows_per_dispatch(fs.width, pipeline.pass_radius(radius));
                // One pass computes only the rows whose errors count; a cascade
                // needs every pixel of each pass but the last.
                let (first, end) = match &fs.counted {
                    Some(regions) if passes == 1 => (
                        regions.iter().map(|r| r.y).min().unwrap_or(0),
                        regions.iter().map(|r| r.y + r.height).max().unwrap_or(fs.height),
                    ),
                    _ => (0, fs.height),
                };
                (0..passes)
                    .flat_map(|level| (first..end).step_by(rows as usize).map(move |row| (level, row)))
                    .map(|(level, row)| {
                        let base = Params { width: fs.width, height: fs.height, radius, row_offset: row };
                        let bytes = uniform_bytes(atrous, base, level, passes, true);
                        let buffer = self.params_buffer(own_params(), "params", &bytes);
                        (buffer, level, rows.min(end - row))
                    })
                    .collect()
            })
            .collect();

        // The reduction's parameters per scene and member.
        let reduce_params: Vec<Vec<wgpu::Buffer>> = scenes
            .iter()
            .map(|fs| {
                (0..most)
                    .map(|member| {
                        let params = ReduceParams { width: fs.width, height: fs.height, member, _pad: 0 };
                        self.params_buffer(own_params(), "reduce params", bytemuck::bytes_of(&params))
                    })
                    .collect()
            })
            .collect();

        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        let mut pending = 0;
        let mut first_member = 0usize;
        for (k, (kernel, pipeline)) in kernels.iter().zip(&pipelines).enumerate() {
            let scene_count = scenes.len();
            let carried = kernel.source().interface.carried_variance();
            for (s, fs) in scenes.iter_mut().enumerate() {
                let (terms, pixel_flags, _) = fs.terms.as_ref().expect("terms are made before dispatching");
                // The textures a pass samples, blitted as its first band is recorded.
                let (mut views, mut views_level) = (HashMap::new(), None);
                for (params, level, rows) in bands[s].iter().take(if run == Pass::Prime { 1 } else { usize::MAX }) {
                    if !sampled[k].is_empty() && views_level != Some(*level) {
                        views = fs.buffers.sampled_views(self, &mut encoder, &sampled[k], *level, carried)?;
                        views_level = Some(*level);
                    }
                    let buffers = &fs.buffers;
                    let bind_group = self.bind_group(pipeline, &kernel.source().interface, |role| match role {
                        Role::Params => params.as_entire_binding(),
                        Role::Output => terms.as_entire_binding(),
                        Role::Flags => pixel_flags.as_entire_binding(),
                        Role::Reference => fs.reference.as_entire_binding(),
                        role if views.contains_key(&role) => wgpu::BindingResource::TextureView(&views[&role]),
                        role => {
                            buffers.pass_resource(role, *level, carried).expect("inputs are uploaded before binding")
                        }
                    });
                    let groups = match run {
                        Pass::Prime => (1, 1),
                        Pass::Full => (fs.width.div_ceil(WORKGROUP[0]), rows.div_ceil(WORKGROUP[1])),
                    };
                    dispatch(&mut encoder, &pipeline.pipeline, &bind_group, groups);
                    pending += 1;
                }
                // `planefit`: the fit of the last pass's image replaces its terms.
                if let (Some(fit), Pass::Full) = (fs.buffers.pipeline.planefit, run) {
                    assert_eq!(members[k], 1, "an à-trous fitness kernel scores one member");
                    let last = fs.buffers.pipeline.passes() - 1;
                    let image = fs.buffers.pass_resource(Role::Image, last, None).expect("an à-trous form's images");
                    self.planefit_terms(&mut encoder, &fs.buffers, fit, image, &fs.reference, terms)?;
                    pending += 1;
                }
                // The member's terms are complete once every band (and pass) has run.
                for member in 0..members[k] as usize {
                    let at = offsets[(first_member + member) * scene_count + s];
                    let partial = |buffer, bytes| {
                        let (offset, size) = (at * bytes, std::num::NonZeroU64::new(fs.groups() * bytes));
                        wgpu::BindingResource::Buffer(wgpu::BufferBinding { buffer, offset, size })
                    };
                    let bind_group = self.bind_in_slot_order(
                        &reduce,
                        reduce_interface
                            .bindings
                            .iter()
                            .map(|b| match b.role {
                                Role::Params => reduce_params[s][member].as_entire_binding(),
                                Role::Terms => terms.as_entire_binding(),
                                Role::PixelFlags => pixel_flags.as_entire_binding(),
                                Role::Output => partial(&partials, 8),
                                Role::Flags => partial(&partial_flags, 4),
                                other => unreachable!("the reduction has no {other:?} binding"),
                            })
                            .collect(),
                    );
                    let groups = match run {
                        Pass::Prime => (1, 1),
                        Pass::Full => (fs.width.div_ceil(WORKGROUP[0]), fs.height.div_ceil(WORKGROUP[1])),
                    };
                    dispatch(&mut encoder, &reduce.pipeline, &bind_group, groups);
                    pending += 1;
                }
                if pending >= DISPATCHES_PER_SUBMISSION {
                    let full = std::mem::replace(&mut encoder, device.create_command_encoder(&Default::default()));
                    self.queue().submit([full.finish()]);
                    pending = 0;
                }
            }
            first_member += members[k] as usize;
        }
        if run == Pass::Prime {
            self.queue().submit([encoder.finish()]);
            self.wait("compiling fitness kernels")?;
            if let Some(error) = pollster::block_on(scope.pop()) {
                return Err(GpuError::Runtime { during: "compiling fitness kernels", message: error.to_string() });
            }
            return Ok(Vec::new());
        }
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("fitness readback"),
            size: total * 12,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        encoder.copy_buffer_to_buffer(&partials, 0, &staging, 0, total * 8);
        encoder.copy_buffer_to_buffer(&partial_flags, 0, &staging, total * 8, total * 4);
        let bytes = self.finish_and_read(encoder, scope, "evaluating fitness", &staging)?;
        let sums: Vec<[f32; 2]> = bytemuck::pod_collect_to_vec(&bytes[..(total * 8) as usize]);
        let flags: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes[(total * 8) as usize..]);
        let total_members = members.iter().sum::<u32>() as usize;
        let mut out = Vec::with_capacity(total_members);
        for k in 0..total_members {
            let mut row = Vec::with_capacity(scenes.len());
            for (s, fs) in scenes.iter().enumerate() {
                let start = offsets[k * scenes.len() + s] as usize;
                let add = |(e, l, bits): (f64, f64, u32), w: usize| {
                    (e + sums[w][0] as f64, l + sums[w][1] as f64, bits | flags[w])
                };
                let (sum, luminance, bits) = match &fs.counted {
                    None => (start..start + fs.groups() as usize).fold((0.0, 0.0, 0), add),
                    Some(regions) => {
                        regions.iter().flat_map(|r| r.partials(fs.width)).map(|w| start + w).fold((0.0, 0.0, 0), add)
                    }
                };
                let pixels =
                    fs.counted.as_ref().map_or(fs.width * fs.height, |r| r.iter().map(Region::pixels).sum()) as f64;
                row.push(SceneScore {
                    relmse: sum / pixels,
                    luminance: luminance / pixels,
                    flags: bits,
                    finite: sum.is_finite() && luminance.is_finite(),
                });
            }
            out.push(row);
        }
        Ok(out)
    }
}

fn dispatch(
    encoder: &mut wgpu::CommandEncoder,
    pipeline: &wgpu::ComputePipeline,
    bind_group: &wgpu::BindGroup,
    groups: (u32, u32),
) {
    let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes: None });
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, bind_group, &[]);
    pass.dispatch_workgroups(groups.0, groups.1, 1);
}
