//! Every environment variable filterjit reads, read in one place. The edge
//! (the command line, the tests, the examples) calls [`Environment::read`]
//! once and hands its plain values to the library; nothing deeper reads the
//! process environment. (The one variable filterjit *sets*, for Mesa's
//! device selection layer, is set in `main` before any driver loads.)

use std::ffi::OsString;
use std::path::PathBuf;

use crate::gpu::adapter::{self, Request};
use crate::gpu::GpuError;

/// Restricts the adapter search to one backend: `vulkan`, `gl`, `metal`, `dx12`.
pub const BACKEND: &str = "FILTERJIT_BACKEND";
/// Picks the first adapter whose name contains this text.
pub const ADAPTER: &str = "FILTERJIT_ADAPTER";
/// The dataset cache's directory.
pub const CACHE: &str = "FILTERJIT_CACHE";
/// Intel Open Image Denoise's `oidnDenoise` program, for `report`.
pub const OIDN: &str = "FILTERJIT_OIDN";

/// glibc's own allocator settings: where one is set, filterjit leaves the
/// allocator as the user set it (`gpu::host_memory`).
pub const MALLOC_KNOBS: [&str; 3] = ["MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "GLIBC_TUNABLES"];

/// What the environment asks for.
#[derive(Clone, Debug)]
pub struct Environment {
    pub adapter: Request,
    /// Root of the dataset cache: `$FILTERJIT_CACHE`, else
    /// `$XDG_CACHE_HOME/filterjit`, else `~/.cache/filterjit`.
    pub cache: PathBuf,
    /// `$FILTERJIT_OIDN`, when set.
    pub oidn: Option<PathBuf>,
    /// `$PATH`, where `report` looks for `oidnDenoise` next.
    pub path: Option<OsString>,
    /// Ranks of the MPI job this process was started in, as its launcher
    /// says (Open MPI's mpirun and srun: `OMPI_COMM_WORLD_SIZE`; MPICH's
    /// hydra: `PMI_SIZE`); 1 without one.
    pub launched_ranks: usize,
    /// Where temporary files go: `$TMPDIR`, else `/tmp`.
    pub scratch: PathBuf,
}

impl Environment {
    /// The process's environment. A backend name that is none is an error.
    pub fn read() -> Result<Environment, GpuError> {
        Environment::from_vars(|name| std::env::var_os(name))
    }

    /// The environment `var` describes (`None`: unset).
    pub fn from_vars(var: impl Fn(&str) -> Option<OsString>) -> Result<Environment, GpuError> {
        let text = |name: &str| var(name).map(|v| v.to_string_lossy().into_owned());
        let adapter = Request {
            backends: match text(BACKEND) {
                Some(value) => adapter::backends_named(&value)?,
                None => Request::default().backends,
            },
            name: text(ADAPTER).filter(|n| !n.is_empty()),
            keep_freed_images: MALLOC_KNOBS.iter().all(|name| var(name).is_none()),
        };
        let scratch = var("TMPDIR").map_or_else(|| PathBuf::from("/tmp"), PathBuf::from);
        let cache = match (var(CACHE), var("XDG_CACHE_HOME"), var("HOME")) {
            (Some(dir), _, _) => PathBuf::from(dir),
            (None, Some(dir), _) => PathBuf::from(dir).join("filterjit"),
            (None, None, Some(home)) => PathBuf::from(home).join(".cache/filterjit"),
            (None, None, None) => scratch.join("filterjit-cache"),
        };
        let launched_ranks =
            ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE"].iter().find_map(|v| text(v)?.parse().ok()).unwrap_or(1);
        Ok(Environment {
            adapter,
            cache,
            oidn: var(OIDN).map(PathBuf::from),
            path: var("PATH"),
            launched_ranks,
            scratch,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with(vars: &[(&str, &str)]) -> Result<Environment, GpuError> {
        Environment::from_vars(|name| vars.iter().find(|(k, _)| *k == name).map(|(_, v)| OsString::from(v)))
    }

    #[test]
    fn variables_become_plain_values() {
        let env = with(&[(BACKEND, "Vulkan"), (ADAPTER, "llvmpipe"), ("HOME", "/home/u")]).unwrap();
        assert_eq!(
            env.adapter,
            Request { backends: wgpu::Backends::VULKAN, name: Some("llvmpipe".into()), keep_freed_images: true }
        );
        assert!(!with(&[("MALLOC_MMAP_THRESHOLD_", "65536")]).unwrap().adapter.keep_freed_images);
        assert_eq!(env.cache, PathBuf::from("/home/u/.cache/filterjit"));
        let env = with(&[(CACHE, "/c"), ("XDG_CACHE_HOME", "/x"), ("HOME", "/h")]).unwrap();
        assert_eq!(env.cache, PathBuf::from("/c"));
        assert_eq!(with(&[("XDG_CACHE_HOME", "/x")]).unwrap().cache, PathBuf::from("/x/filterjit"));
        assert_eq!(with(&[]).unwrap().adapter, Request::default());
        assert_eq!(with(&[]).unwrap().launched_ranks, 1);
        assert_eq!(with(&[("PMI_SIZE", "4")]).unwrap().launched_ranks, 4);
        let error = with(&[(BACKEND, "glide")]).unwrap_err().to_string();
        assert!(error.contains("glide"), "{error}");
    }
}
