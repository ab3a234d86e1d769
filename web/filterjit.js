// filterjit's WebGPU host: runs a filter exported by `filterjit export
// --target wgsl` on the GPUTextures a page already has. No build step, no
// dependencies; the same steps as examples/run_exported/host.rs, read from
// the manifest alone (examples/README.md, "The interface").
//
//   import { loadFilter } from "./filterjit.js";
//   const filter = await loadFilter(device, "denoise.wgsl.json");
//   const output = filter.run({ width, height, textures: { color, albedo, normal } });
//
// Per frame it runs the manifest's `frame`, step by step: each dispatch of
// a shader with the image each binding binds, each copy a sequence keeps for
// the next frame. Which stage runs when is filterjit's to say, not this
// module's. A temporal filter keeps what the `keep` steps copy from one
// `run` to the next: frames of a sequence in order; `reset()` starts a new
// sequence.

/** The manifest layout this module reads (filterjit's `export::MANIFEST_VERSION`). */
export const MANIFEST_VERSION = 8;

/** The shaders a manifest's frame dispatches besides the form's (the manifest's own), by their keys in it. */
const stagesOf = (manifest) => [
  ...new Set((manifest.frame ?? []).filter((step) => step.dispatch && step.dispatch.shader !== "form").map((step) => step.dispatch.shader)),
];

const WRITTEN = GPUTextureUsage.STORAGE_BINDING | GPUTextureUsage.TEXTURE_BINDING | GPUTextureUsage.COPY_SRC;

/** A filter whose manifest or inputs do not fit what is asked of it. */
export class FilterError extends Error {
  constructor(message) {
    super(`filterjit: ${message}`);
    this.name = "FilterError";
  }
}

/**
 * Fetch an export's manifest from `manifestUrl` and the shaders it names
 * beside it (the form's is the manifest's name without `.json`), and build
 * the filter's pipelines on `device`.
 */
export async function loadFilter(device, manifestUrl) {
  const text = async (url) => {
    const response = await fetch(url);
    if (!response.ok) throw new FilterError(`${url}: HTTP ${response.status}`);
    return response.text();
  };
  const manifest = JSON.parse(await text(manifestUrl));
  const beside = (file) => new URL(file, new URL(manifestUrl, location.href)).href;
  const shaders = { form: await text(String(manifestUrl).replace(/\.json$/, "")) };
  for (const stage of stagesOf(manifest)) shaders[stage] = await text(beside(manifest[stage].file));
  return createFilter(device, manifest, shaders);
}

/**
 * Build the filter's pipelines from its manifest and shader texts
 * (`{ form, prepass, spread, … }`: the form's, and every other shader the manifest's `frame` dispatches, by its key).
 * Compilation messages are collected in `filter.messages`.
 */
export async function createFilter(device, manifest, shaders) {
  const filter = new Filter(device, manifest, shaders);
  await filter.compiled;
  return filter;
}

export class Filter {
  constructor(device, manifest, shaders) {
    if (manifest?.version !== MANIFEST_VERSION) {
      throw new FilterError(
        `manifest version ${JSON.stringify(manifest?.version)}: this module reads version ${MANIFEST_VERSION} ` +
          "(export the filter again with this filterjit)",
      );
    }
    if (manifest.target !== "wgsl") throw new FilterError(`a ${manifest.target} export: WebGPU runs WGSL exports only`);
    this.device = device;
    this.manifest = manifest;
    this.workgroup = manifest.workgroup_size;
    this.stages = {};
    this.messages = [];
    const needs = [["form", manifest]];
    for (const name of stagesOf(manifest)) needs.push([name, manifest[name]]);
    const compiled = [];
    for (const [name, stage] of needs) {
      const code = shaders[name];
      if (typeof code !== "string") throw new FilterError(`the manifest has a ${name} stage and no ${name} shader was given`);
      checkLimits(device, name, stage);
      const module = device.createShaderModule({ label: `filterjit ${name}`, code });
      compiled.push(
        module.getCompilationInfo().then((info) => {
          for (const m of info.messages) this.messages.push({ stage: name, type: m.type, line: m.lineNum, text: m.message });
        }),
      );
      const layout = device.createBindGroupLayout({ entries: stage.bindings.map(layoutEntry) });
      const pipeline = device.createComputePipeline({
        label: `filterjit ${name}`,
        layout: device.createPipelineLayout({ bindGroupLayouts: [layout] }),
        compute: { module, entryPoint: stage.entry_point },
      });
      this.stages[name] = { stage, layout, pipeline };
    }
    this.compiled = Promise.all(compiled);
    this.textures = new Map();
    this.uniforms = new Map();
    /** What the frame before kept (`manifest.history`), by image name. */
    this.kept = new Map();
    /** Frames run since the sequence started. */
    this.frames = 0;
  }

  /** Forget the history: the next `run` is a sequence's first frame. */
  reset() {
    this.frames = 0;
  }

  /** Every image the caller provides, by the name its bindings read it by (the manifest's `inputs`). */
  get inputs() {
    return this.manifest.inputs.map((input) => input.image);
  }

  /**
   * Record one frame into `encoder` (a new one, submitted, when not given).
   * `frame`: `{ width, height, textures: { role: GPUTexture }, scales: { role: number }, radius }`;
   * scales default to 1 (the texture holds normalised values), the radius to
   * the manifest's. Returns the GPUTexture holding the filtered frame (in
   * `manifest.output_format`; it is reused by the next frame of the same size).
   */
  run(frame, encoder) {
    const { width, height } = frame;
    const own = !encoder;
    encoder ??= this.device.createCommandEncoder({ label: "filterjit" });
    // Every image by name, its texture beside its view (what a sequence keeps is copied from the texture).
    const sources = new Map(Object.entries(frame.textures));
    const images = new Map([...sources].map(([role, texture]) => [role, texture.createView()]));
    for (const role of this.inputs) {
      if (!images.has(role)) {
        throw new FilterError(`the filter reads \`${role}\` and no texture was given for it (inputs: ${this.inputs.join(", ")})`);
      }
    }
    // What the frame before kept; a sequence's first frame (or one of another size) binds
    // stand-ins, which the blend does not read. Every other image is made once per size.
    const first = this.frames === 0 || this.keptSize !== `${width}x${height}`;
    for (const image of this.manifest.images) {
      if (image.kept_from !== undefined) {
        const kept = first ? this.texture("unread", "rgba32float", width, height) : this.kept.get(image.name);
        images.set(image.name, kept.createView());
      } else {
        const texture = this.texture(image.name, image.format, width, height);
        sources.set(image.name, texture);
        images.set(image.name, texture.createView());
      }
    }
    const workgroups = [Math.ceil(width / this.workgroup[0]), Math.ceil(height / this.workgroup[1])];
    let dispatches = 0;
    // The frame, step by step, as the manifest's `frame` says.
    for (const step of this.manifest.frame) {
      if (step.keep) {
        this.keep(encoder, sources, step.keep, width, height);
        continue;
      }
      const { shader, values, first_frame, images: bound } = step.dispatch;
      const { stage, layout, pipeline } = this.stages[shader];
      // A sequence's first frame replaces some values (the temporal stage's `history`); a
      // window form's radius may be the caller's.
      const radius = shader === "form" && frame.radius !== undefined ? { radius: frame.radius } : {};
      const uniform = this.uniform(dispatches++, stage, frame, { ...values, ...(first ? first_frame : {}), ...radius });
      const entries = stage.bindings.map((b) => {
        if (b.kind === "uniform") return { binding: b.binding, resource: { buffer: uniform } };
        const view = images.get(bound[b.role]);
        if (!view) throw new FilterError(`${shader}: binding ${b.binding} (\`${b.role}\`) needs the image \`${bound[b.role]}\`, which nothing made`);
        return { binding: b.binding, resource: view };
      });
      const pass = encoder.beginComputePass({ label: `filterjit ${shader}` });
      pass.setPipeline(pipeline);
      pass.setBindGroup(0, this.device.createBindGroup({ layout, entries }));
      pass.dispatchWorkgroups(workgroups[0], workgroups[1], 1);
      pass.end();
    }
    if (this.manifest.frame.some((step) => step.keep)) {
      this.frames = first ? 1 : this.frames + 1;
      this.keptSize = `${width}x${height}`;
    }
    if (own) this.device.queue.submit([encoder.finish()]);
    return sources.get(this.manifest.output);
  }

  /** Record a `keep` step: copy `from` into the texture the next frame binds as `into`. */
  keep(encoder, sources, { from, into }, width, height) {
    const source = sources.get(from);
    if (!source) throw new FilterError(`the history keeps \`${from}\`, which nothing made and no texture was given for`);
    const key = `${into}/${source.format}`;
    let texture = this.kept.get(key);
    if (texture?.width !== width || texture?.height !== height) {
      texture?.destroy();
      texture = this.device.createTexture({
        label: `filterjit kept ${into}`,
        size: [width, height],
        format: source.format,
        usage: GPUTextureUsage.TEXTURE_BINDING | GPUTextureUsage.COPY_DST,
      });
      this.kept.set(key, texture);
    }
    this.kept.set(into, texture);
    encoder.copyTextureToTexture({ texture: source }, { texture }, [width, height]);
  }

  /**
   * The typed-array convenience: `frame.color` and `frame.inputs[role]` are
   * Float32Arrays of width × height RGBA texels, top row first. Uploads
   * them, runs the filter and resolves to the filtered frame as a
   * Float32Array of RGBA texels.
   */
  async filterArrays(frame) {
    const { width, height } = frame;
    const textures = {};
    const upload = (role, texels) => {
      if (!(texels instanceof Float32Array) || texels.length !== 4 * width * height) {
        throw new FilterError(`\`${role}\` must be a Float32Array of ${4 * width * height} values (RGBA, ${width}x${height})`);
      }
      const texture = this.device.createTexture({
        label: role,
        size: [width, height],
        format: "rgba32float",
        // COPY_SRC: a sequence keeps its albedo and geometry for the next frame.
        usage: GPUTextureUsage.TEXTURE_BINDING | GPUTextureUsage.COPY_DST | GPUTextureUsage.COPY_SRC,
      });
      this.device.queue.writeTexture({ texture }, texels, { bytesPerRow: 16 * width, rowsPerImage: height }, [width, height]);
      textures[role] = texture;
    };
    upload("color", frame.color);
    for (const [role, texels] of Object.entries(frame.inputs ?? {})) upload(role, texels);
    const encoder = this.device.createCommandEncoder({ label: "filterjit" });
    const output = this.run({ ...frame, textures }, encoder);
    const texel = this.manifest.output_format === "rgba16float" ? 8 : 16;
    const bytesPerRow = Math.ceil((width * texel) / 256) * 256;
    const staging = this.device.createBuffer({ size: bytesPerRow * height, usage: GPUBufferUsage.MAP_READ | GPUBufferUsage.COPY_DST });
    encoder.copyTextureToBuffer({ texture: output }, { buffer: staging, bytesPerRow }, [width, height]);
    this.device.pushErrorScope("validation");
    this.device.queue.submit([encoder.finish()]);
    const error = await this.device.popErrorScope();
    if (error) throw new FilterError(error.message);
    await staging.mapAsync(GPUMapMode.READ);
    const bytes = staging.getMappedRange();
    const result = new Float32Array(4 * width * height);
    for (let y = 0; y < height; y++) {
      if (texel === 16) {
        result.set(new Float32Array(bytes, y * bytesPerRow, 4 * width), 4 * width * y);
      } else {
        const halves = new Uint16Array(bytes, y * bytesPerRow, 4 * width);
        for (let i = 0; i < 4 * width; i++) result[4 * width * y + i] = halfToFloat(halves[i]);
      }
    }
    staging.unmap();
    staging.destroy();
    for (const texture of Object.values(textures)) texture.destroy();
    return result;
  }

  /** A texture this filter writes, made once per name, format and size. */
  texture(name, format, width, height) {
    const key = `${name}/${format}/${width}x${height}`;
    let texture = this.textures.get(key);
    if (!texture) {
      texture = this.device.createTexture({ label: `filterjit ${name}`, size: [width, height], format, usage: WRITTEN });
      this.textures.set(key, texture);
    }
    return texture;
  }

  /**
   * The uniform of a frame's `n`th dispatch: width, height, the dispatch's
   * values and the inputs' scales. One buffer per dispatch, kept for the
   * next frame: writes land before the frame's commands run, so a frame's
   * dispatches cannot share one.
   */
  uniform(n, stage, frame, values) {
    const bytes = new ArrayBuffer(stage.uniform.size_bytes);
    const view = new DataView(bytes);
    for (const f of stage.uniform.fields) {
      let value;
      const scale = /^scale\[(\d+)\]$/.exec(f.name);
      if (f.name === "width") value = frame.width;
      else if (f.name === "height") value = frame.height;
      else if (scale) {
        const binding = stage.bindings.find((b) => b.scale_index === Number(scale[1]));
        value = frame.scales?.[binding.role] ?? 1;
      } else value = values[f.name] ?? 0;
      if (f.type === "u32") view.setUint32(f.offset, value, true);
      else if (f.type === "f32" || f.type === "vec4<f32>") view.setFloat32(f.offset, value, true);
      else throw new FilterError(`uniform field ${f.name} has type ${f.type}`);
    }
    let buffer = this.uniforms.get(n);
    if (buffer?.size !== bytes.byteLength) {
      buffer = this.device.createBuffer({ size: bytes.byteLength, usage: GPUBufferUsage.UNIFORM | GPUBufferUsage.COPY_DST });
      this.uniforms.set(n, buffer);
    }
    this.device.queue.writeBuffer(buffer, 0, bytes);
    return buffer;
  }

  /** Free the textures and buffers this filter made. */
  destroy() {
    for (const texture of new Set(this.kept.values())) texture.destroy();
    this.kept.clear();
    for (const texture of this.textures.values()) texture.destroy();
    for (const buffer of this.uniforms.values()) buffer.destroy();
    this.textures.clear();
    this.uniforms.clear();
  }
}

/** A manifest binding as a bind group layout entry. */
function layoutEntry(b) {
  const entry = { binding: b.binding, visibility: GPUShaderStage.COMPUTE };
  switch (b.kind) {
    case "uniform":
      return { ...entry, buffer: { type: "uniform" } };
    // Read with textureLoad only: any float format, no sampler.
    case "sampled_texture":
      return { ...entry, texture: { sampleType: "unfilterable-float", viewDimension: "2d" } };
    case "storage_texture":
      return { ...entry, storageTexture: { access: "write-only", format: b.format, viewDimension: "2d" } };
    default:
      throw new FilterError(`binding ${b.binding} has an unknown kind \`${b.kind}\``);
  }
}

/** Refuse a stage the device cannot bind, naming the limit. */
function checkLimits(device, name, stage) {
  const count = (kind) => stage.bindings.filter((b) => b.kind === kind).length;
  const limits = [
    ["maxSampledTexturesPerShaderStage", count("sampled_texture")],
    ["maxStorageTexturesPerShaderStage", count("storage_texture")],
    ["maxUniformBuffersPerShaderStage", count("uniform")],
  ];
  for (const [limit, needed] of limits) {
    if (needed > device.limits[limit]) {
      throw new FilterError(`the ${name} shader needs ${limit} = ${needed}; this device allows ${device.limits[limit]}`);
    }
  }
}

/** An IEEE half (its 16 bits) as a number. */
function halfToFloat(h) {
  const sign = h & 0x8000 ? -1 : 1;
  const exponent = (h >> 10) & 0x1f;
  const fraction = h & 0x3ff;
  if (exponent === 0) return sign * 2 ** -14 * (fraction / 1024);
  if (exponent === 31) return fraction ? NaN : sign * Infinity;
  return sign * 2 ** (exponent - 15) * (1 + fraction / 1024);
}
