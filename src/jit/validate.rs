//! Stage 4: WGSL source → naga module, validated. A [`ValidatedKernel`] can
//! only be made here, and only a validated kernel reaches the GPU module.

use sha2::{Digest, Sha256};

use super::lower::{KernelSource, TEMPLATE_VERSION, WORKGROUP};

/// A kernel whose WGSL naga has parsed and validated.
#[derive(Debug)]
pub struct ValidatedKernel {
    source: KernelSource,
    module: naga::Module,
    /// What validation learned; naga's back ends need it (`export`).
    info: naga::valid::ModuleInfo,
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
    /// The key of a kernel made from `source`: canonical expression text,
    /// template version, binding layout and workgroup shape.
    pub fn of(source: &KernelSource) -> Self {
        let mut hasher = Sha256::new();
        hasher.update(b"filterjit-kernel\0");
        hasher.update(TEMPLATE_VERSION.to_le_bytes());
        hasher.update(format!("{:?} {:?}", source.kind, source.options).as_bytes());
        hasher.update(source.canonical.as_bytes());
        hasher.update(b"\0");
        hasher.update(source.layout.describe().as_bytes());
        hasher.update(b"\0");
        for w in WORKGROUP {
            hasher.update(w.to_le_bytes());
        }
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

/// Parse and validate a kernel's WGSL with naga.
pub fn validate(source: KernelSource) -> Result<ValidatedKernel, ValidateError> {
    let module = naga::front::wgsl::parse_str(&source.wgsl).map_err(|e| ValidateError::Parse {
        expression: source.canonical.clone(),
        message: e.emit_to_string(&source.wgsl),
        wgsl: source.wgsl.clone(),
    })?;
    let mut validator =
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty());
    let info = validator.validate(&module).map_err(|e| ValidateError::Invalid {
        expression: source.canonical.clone(),
        message: e.emit_to_string(&source.wgsl),
        wgsl: source.wgsl.clone(),
    })?;
    let key = KernelKey::of(&source);
    Ok(ValidatedKernel { source, module, info, key })
}

impl ValidatedKernel {
    pub fn source(&self) -> &KernelSource {
        &self.source
    }
    pub fn wgsl(&self) -> &str {
        &self.source.wgsl
    }
    pub fn module(&self) -> &naga::Module {
        &self.module
    }
    pub fn info(&self) -> &naga::valid::ModuleInfo {
        &self.info
    }
    pub fn key(&self) -> KernelKey {
        self.key
    }
}
