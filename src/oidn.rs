//! Intel Open Image Denoise, the peer a user would pick instead, run as its
//! own `oidnDenoise` program: images go in and out as PFM files, and its
//! device time comes from the program's own per-execution figures (CPU wall
//! time of each denoise after the first), as filterjit's are device times
//! of warm dispatches.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};

use crate::scene::Scene;

/// The environment variable naming the `oidnDenoise` program.
use crate::environment::OIDN as OIDN_ENV;

/// A found `oidnDenoise`.
#[derive(Clone, Debug)]
pub struct Oidn {
    pub program: PathBuf,
}

/// What OIDN is given besides the colour.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Auxiliary {
    ColorOnly,
    /// Albedo (clipped to [0, 1], as OIDN's documentation asks) and shading normal.
    AlbedoNormal,
}

impl Auxiliary {
    /// The method's name in the report.
    pub fn method_name(self) -> &'static str {
        match self {
            Auxiliary::ColorOnly => "OIDN colour",
            Auxiliary::AlbedoNormal => "OIDN colour+albedo+normal",
        }
    }
}

/// One denoised image and the program's execution times (warm runs, ms).
#[derive(Clone, Debug)]
pub struct Denoised {
    pub color: Vec<[f32; 3]>,
    pub warm_ms: Vec<f64>,
    /// The kind of device OIDN chose, as it names it (`CPU`, `CUDA`, …): its
    /// default is the fastest it finds, a GPU where its build supports one.
    pub device: String,
}

impl Oidn {
    /// `explicit` (`FILTERJIT_OIDN`), else `oidnDenoise` on `path` (`PATH`),
    /// else the one the `pyoidn` Python package ships (`pyoidn/oidn/bin/`).
    /// `Err` says what was tried.
    pub fn find(explicit: Option<&Path>, path: Option<&std::ffi::OsStr>) -> std::result::Result<Oidn, String> {
        if let Some(program) = explicit {
            return if program.is_file() {
                Ok(Oidn { program: program.to_path_buf() })
            } else {
                Err(format!("{OIDN_ENV}={} is not a file", program.display()))
            };
        }
        if let Some(paths) = path {
            if let Some(program) = std::env::split_paths(paths).map(|d| d.join("oidnDenoise")).find(|p| p.is_file()) {
                return Ok(Oidn { program });
            }
        }
        let package = Command::new("python3")
            .args(["-c", "import os, pyoidn; print(os.path.dirname(pyoidn.__file__))"])
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| PathBuf::from(String::from_utf8_lossy(&o.stdout).trim()).join("oidn/bin/oidnDenoise"));
        match package {
            Some(program) if program.is_file() => Ok(Oidn { program }),
            _ => Err(format!(
                "no oidnDenoise ({OIDN_ENV} unset, none on PATH, no pyoidn package for python3; `pip install pyoidn` provides one)"
            )),
        }
    }

    /// Denoise `scene`'s colour, HDR, with `aux` inputs, running the filter
    /// `1 + repeats` times (the first is a warm-up); files go to `dir`.
    pub fn denoise(&self, scene: &Scene, aux: Auxiliary, repeats: usize, dir: &Path) -> Result<Denoised> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let (w, h) = (scene.width, scene.height);
        let color: Vec<[f32; 3]> = scene.color.iter().map(|c| c.map(|v| v.max(0.0))).collect();
        let input = dir.join("color.pfm");
        write_pfm(&input, w, h, &color)?;
        let output = dir.join("output.pfm");
        let mut command = Command::new(&self.program);
        command.arg("--hdr").arg(&input);
        if aux == Auxiliary::AlbedoNormal {
            let albedo = scene.albedo.as_ref().context("OIDN with albedo: the scene was loaded without its albedo")?;
            let albedo: Vec<[f32; 3]> = albedo.iter().map(|a| a.map(|v| v.clamp(0.0, 1.0))).collect();
            let normal = scene
                .feature(crate::lang::Feature::Normal)
                .context("OIDN with normals: the scene was loaded without its normals")?;
            let (alb, nrm) = (dir.join("albedo.pfm"), dir.join("normal.pfm"));
            write_pfm(&alb, w, h, &albedo)?;
            write_pfm(&nrm, w, h, normal)?;
            command.arg("--alb").arg(&alb).arg("--nrm").arg(&nrm);
        }
        command.arg("-o").arg(&output).arg("-n").arg((repeats.max(1) + 1).to_string()).arg("-v").arg("2");
        let run = command.output().with_context(|| format!("running {}", self.program.display()))?;
        let stdout = String::from_utf8_lossy(&run.stdout).into_owned() + &String::from_utf8_lossy(&run.stderr);
        if !run.status.success() {
            bail!("{} failed ({}):\n{stdout}", self.program.display(), run.status);
        }
        // "Denoising" lines are each followed by "  msec=T, …": one per execution.
        let times: Vec<f64> = stdout
            .lines()
            .collect::<Vec<_>>()
            .windows(2)
            .filter(|pair| pair[0].trim() == "Denoising")
            .filter_map(|pair| pair[1].trim().strip_prefix("msec=")?.split(',').next()?.trim().parse().ok())
            .collect();
        if times.is_empty() {
            bail!("{} printed no execution times:\n{stdout}", self.program.display());
        }
        let (ow, oh, color) = read_pfm(&output)?;
        if (ow, oh) != (w, h) {
            bail!("{}: {ow}x{oh}, expected {w}x{h}", output.display());
        }
        // "  device=CUDA, version=…": the device it initialised.
        let device = stdout
            .lines()
            .find_map(|l| l.trim().strip_prefix("device=")?.split(',').next().map(str::to_string))
            .unwrap_or_else(|| "device unnamed".to_string());
        Ok(Denoised { color, warm_ms: times.into_iter().skip(1).collect(), device })
    }
}

/// Write an RGB PFM (little endian, rows bottom to top).
pub fn write_pfm(path: &Path, width: usize, height: usize, rgb: &[[f32; 3]]) -> Result<()> {
    let mut bytes = format!("PF\n{width} {height}\n-1.0\n").into_bytes();
    for y in (0..height).rev() {
        for px in &rgb[y * width..(y + 1) * width] {
            for v in px {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    std::fs::write(path, bytes).with_context(|| format!("writing {}", path.display()))
}

/// Read an RGB PFM of either byte order.
pub fn read_pfm(path: &Path) -> Result<(usize, usize, Vec<[f32; 3]>)> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let bad = |why: &str| anyhow::anyhow!("{}: not an RGB PFM image ({why})", path.display());
    // Three whitespace-separated header tokens after "PF", then one whitespace byte.
    let mut fields = Vec::new();
    let mut start = None;
    let mut offset = 0;
    for (k, b) in bytes.iter().enumerate() {
        if b.is_ascii_whitespace() {
            if let Some(s) = start.take() {
                fields.push(String::from_utf8_lossy(&bytes[s..k]).into_owned());
                if fields.len() == 4 {
                    offset = k + 1;
                    break;
                }
            }
        } else if start.is_none() {
            start = Some(k);
        }
    }
    if fields.len() != 4 || fields[0] != "PF" {
        return Err(bad("header"));
    }
    let width: usize = fields[1].parse().map_err(|_| bad("width"))?;
    let height: usize = fields[2].parse().map_err(|_| bad("height"))?;
    let scale: f32 = fields[3].parse().map_err(|_| bad("scale"))?;
    let data = &bytes[offset..];
    if data.len() < width * height * 12 {
        return Err(bad("too short"));
    }
    let value = |k: usize| {
        let raw: [u8; 4] = data[4 * k..4 * k + 4].try_into().expect("4 bytes");
        if scale < 0.0 {
            f32::from_le_bytes(raw)
        } else {
            f32::from_be_bytes(raw)
        }
    };
    let mut rgb = vec![[0f32; 3]; width * height];
    for y in 0..height {
        for x in 0..width {
            let k = ((height - 1 - y) * width + x) * 3;
            rgb[y * width + x] = [value(k), value(k + 1), value(k + 2)];
        }
    }
    Ok((width, height, rgb))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pfm_round_trips_with_rows_in_order() {
        let dir = std::env::temp_dir().join(format!("filterjit-pfm-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let rgb: Vec<[f32; 3]> = (0..6).map(|k| [k as f32, 0.5, -1.0]).collect();
        let path = dir.join("t.pfm");
        write_pfm(&path, 3, 2, &rgb).unwrap();
        assert_eq!(read_pfm(&path).unwrap(), (3, 2, rgb));
        let bytes = std::fs::read(&path).unwrap();
        // The first stored row is the image's bottom row.
        assert_eq!(f32::from_le_bytes(bytes[12..16].try_into().unwrap()), 3.0);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
