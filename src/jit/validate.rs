//! Stage 4: WGSL source → naga module, validated. A [`ValidatedKernel`] can
//! only be made here, and only a validated kernel reaches the GPU module.

use sha2::{Digest, Sha256};

use super::interface::TexelFormat;
use super::interface::{Access, Slot};
use super::kernel::{OutputFormat, TEMPLATE_VERSION, WORKGROUP};
use super::lower::KernelSource;

/// A kernel whose WGSL naga has parsed and validated.
#[derive(Debug)]
pub struct ValidatedKernel {
    source: KernelSource,
    validated: ValidatedModule,
    key: KernelKey,
}

/// Stable identity of a kernel: SHA-256 of everything that defines it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct KernelKey(pub [u8; 32]);

impl std::fmt::Display for KernelKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for byte in &self.0[..8] {
            write!(f, "{byte:02x}")?;
        }
        Ok(())
    }
}

impl KernelKey {
    /// The key of a kernel made from `source`: a stable encoding of its kind,
    /// lowering options, canonical text and interface, and the SHA-256 of the
    /// rendered WGSL itself (which covers `ops.wgsl`, the templates and the
    /// lowering, whatever changes in them).
    pub fn of(source: &KernelSource) -> Self {
        let mut hasher = Sha256::new();
        let o = &source.options;
        let fields = [
            "filterjit-kernel".to_string(),
            TEMPLATE_VERSION.to_string(),
            source.kind.encode(),
            source.shape.encode(),
            format!(
                "fold={} cse={} hoist={} strength={} skip={} tile={}",
                o.fold_constants,
                o.common_subexpressions,
                o.hoist_centre_terms,
                o.strength_reduction,
                o.skip_redundant_checks,
                o.tile_radius.map_or("none".to_string(), |r| r.to_string())
            ),
            source.canonical.clone(),
            source.interface.encode(),
            format!("{}x{}", WORKGROUP[0], WORKGROUP[1]),
        ];
        for field in fields {
            hasher.update((field.len() as u64).to_le_bytes());
            hasher.update(field.as_bytes());
        }
        hasher.update(Sha256::digest(source.wgsl.as_bytes()));
        KernelKey(hasher.finalize().into())
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ValidateError {
    #[error("generated WGSL does not parse (a filterjit bug) for `{expression}`:\n{message}\n--- source ---\n{wgsl}")]
    Parse { expression: String, message: String, wgsl: String },
    #[error(
        "generated WGSL fails validation (a filterjit bug) for `{expression}`:\n{message}\n--- source ---\n{wgsl}"
    )]
    Invalid { expression: String, message: String, wgsl: String },
}

/// A WGSL module naga has parsed and validated, with the resources it binds.
/// Kernels, the path tracer and the benchmark's reference kernels all come
/// through [`validate_module`], the one place a naga `Validator` is made.
#[derive(Debug)]
pub struct ValidatedModule {
    module: naga::Module,
    /// What validation learned; naga's back ends need it (`export`).
    info: naga::valid::ModuleInfo,
    slots: Vec<Slot>,
}

impl ValidatedModule {
    pub fn module(&self) -> &naga::Module {
        &self.module
    }
    pub fn info(&self) -> &naga::valid::ModuleInfo {
        &self.info
    }
    /// Group 0's bindings, in slot order: what a pipeline layout must hold.
    pub fn slots(&self) -> &[Slot] {
        &self.slots
    }
}

/// [`validate_module`], then a check that the module binds exactly what
/// `interface` assigns: for the generated modules that are not expression
/// kernels (the pre-pass, the fitness reduction).
pub fn validate_with_interface(
    wgsl: &str,
    what: &str,
    interface: &super::interface::BindingInterface,
) -> Result<ValidatedModule, ValidateError> {
    let module = validate_module(wgsl, what)?;
    let expected = interface.slots();
    if module.slots() != expected.as_slice() {
        let message = format!("{what} binds {:?}, its interface says {expected:?}", module.slots());
        return Err(ValidateError::Invalid { expression: what.into(), message, wgsl: wgsl.to_string() });
    }
    Ok(module)
}

/// Parse and validate any WGSL module; `what` names it in errors.
pub fn validate_module(wgsl: &str, what: &str) -> Result<ValidatedModule, ValidateError> {
    let module = naga::front::wgsl::parse_str(wgsl).map_err(|e| ValidateError::Parse {
        expression: what.to_string(),
        message: e.emit_to_string(wgsl),
        wgsl: wgsl.to_string(),
    })?;
    let mut validator =
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty());
    let info = validator.validate(&module).map_err(|e| ValidateError::Invalid {
        expression: what.to_string(),
        message: e.emit_to_string(wgsl),
        wgsl: wgsl.to_string(),
    })?;
    let slots = reflect(&module).map_err(|message| ValidateError::Invalid {
        expression: what.to_string(),
        message,
        wgsl: wgsl.to_string(),
    })?;
    Ok(ValidatedModule { module, info, slots })
}

/// The bindings a module declares, read from naga's IR.
fn reflect(module: &naga::Module) -> Result<Vec<Slot>, String> {
    use naga::{AddressSpace, ImageClass, StorageAccess, TypeInner};
    let mut slots = Vec::new();
    for (_, var) in module.global_variables.iter() {
        let Some(binding) = &var.binding else { continue };
        if binding.group != 0 {
            return Err(format!(
                "`{}` is in bind group {}; filterjit binds group 0 only",
                var.name.as_deref().unwrap_or("?"),
                binding.group
            ));
        }
        let access = match (var.space, &module.types[var.ty].inner) {
            (AddressSpace::Uniform, _) => Access::Uniform,
            (AddressSpace::Storage { access }, _) if access.contains(StorageAccess::STORE) => Access::StorageReadWrite,
            (AddressSpace::Storage { .. }, _) => Access::StorageRead,
            (AddressSpace::Handle, TypeInner::Image { class: ImageClass::Sampled { .. }, .. }) => {
                Access::SampledTexture
            }
            (AddressSpace::Handle, TypeInner::Image { class: ImageClass::Storage { format, .. }, .. }) => {
                Access::StorageTexture(match format {
                    naga::StorageFormat::Rgba16Float => TexelFormat::Color(OutputFormat::Rgba16float),
                    naga::StorageFormat::Rgba32Float => TexelFormat::Color(OutputFormat::Rgba32float),
                    naga::StorageFormat::R32Float => TexelFormat::R32float,
                    other => return Err(format!("storage texture format {other:?} is not one filterjit writes")),
                })
            }
            (space, _) => {
                return Err(format!("binding {} in address space {space:?} is not supported", binding.binding))
            }
        };
        slots.push(Slot { slot: binding.binding, access });
    }
    slots.sort_by_key(|s| s.slot);
    Ok(slots)
}

/// Parse and validate a kernel's WGSL with naga; its bindings must be exactly
/// its [`BindingInterface`]'s.
pub fn validate(source: KernelSource) -> Result<ValidatedKernel, ValidateError> {
    let validated = validate_module(&source.wgsl, &source.canonical)?;
    let declared = source.interface.slots();
    if validated.slots != declared {
        return Err(ValidateError::Invalid {
            expression: source.canonical.clone(),
            message: format!(
                "the kernel declares bindings {:?} but its interface has {declared:?} (a template disagrees with jit::interface)",
                validated.slots
            ),
            wgsl: source.wgsl.clone(),
        });
    }
    let key = KernelKey::of(&source);
    Ok(ValidatedKernel { source, validated, key })
}

impl ValidatedKernel {
    pub fn source(&self) -> &KernelSource {
        &self.source
    }
    pub fn wgsl(&self) -> &str {
        &self.source.wgsl
    }
    pub fn module(&self) -> &naga::Module {
        self.validated.module()
    }
    pub fn info(&self) -> &naga::valid::ModuleInfo {
        self.validated.info()
    }
    pub fn validated(&self) -> &ValidatedModule {
        &self.validated
    }
    pub fn key(&self) -> KernelKey {
        self.key
    }
}
