//! Sequences: the frames of an animation in order, each a dataset of its
//! own (docs/SCENES.md, "Sequences"). Three folder layouts are read:
//!
//! - a folder of frame files (`frame_0001.exr`, `frame_0002.exr`, …, as
//!   Blender writes an animation), with references of the same names in a
//!   `reference/` folder beside it or inside it;
//! - a folder holding such a `noisy/` folder and its `reference/` beside;
//! - a folder of frame datasets (`frame_0001/noisy.exr` with its
//!   `reference.exr`, …, as `filterjit render` writes a sequence).
//!
//! Frames are ordered by the number in their names; a gap in the numbers is
//! a missing frame, and an error. [`Sequence::check`] reads every frame's
//! header before any is filtered, so that a damaged sequence is refused
//! before anything is written.

use std::path::{Path, PathBuf};

use super::{exr_io, import, Request, Scene, SceneError, NOISY_FILE, REFERENCE_FILE};

/// One frame's files.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FrameFiles {
    /// The frame's name: its file's stem or its folder's name (`frame_0007`).
    pub name: String,
    /// Its number, where its name has one.
    pub number: Option<u64>,
    /// The noisy image (a dataset's folder, or the EXR file).
    pub path: PathBuf,
    /// The reference, where there is one.
    pub reference: Option<PathBuf>,
}

/// A sequence's frames, in order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Sequence {
    /// The sequence's name (its folder's).
    pub name: String,
    pub frames: Vec<FrameFiles>,
}

/// Whether `path` is a sequence rather than one render: a folder that holds
/// no `noisy.exr` but frames (EXR files, a `noisy/` folder of them, or
/// datasets). Whether they make a good sequence is [`Sequence::find`]'s to say.
pub fn is_sequence(path: &Path) -> bool {
    if !path.is_dir() || path.join(NOISY_FILE).is_file() {
        return false;
    }
    if path.join("noisy").is_dir() {
        return true;
    }
    let Ok(entries) = std::fs::read_dir(path) else { return false };
    entries.filter_map(Result::ok).map(|e| e.path()).any(|p| {
        (p.is_file() && p.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr"))) || p.join(NOISY_FILE).is_file()
    })
}

impl Sequence {
    /// The folder its frames are listed in (`noisy/` where the frames are
    /// files there, else the folder given): where files of the frames' names
    /// would be read as frames.
    pub fn folder(&self) -> Option<&Path> {
        self.frames.first().and_then(|f| f.path.parent())
    }

    /// Whether the folder holds frames of one sequence: two or more, and a
    /// frame number at the end of their names. A folder whose renders are
    /// named without one (`tabletop/`, `corridor_4spp.exr`), or that holds one
    /// render, holds renders of their own.
    pub fn is_numbered(&self) -> bool {
        self.frames.len() >= 2 && self.frames.iter().any(|f| f.number.is_some())
    }

    /// The frames of the sequence at `dir`, in order.
    pub fn find(dir: &Path) -> Result<Sequence, SceneError> {
        let io = |e| SceneError::io(dir, e);
        let name = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "sequence".into());
        let noisy = dir.join("noisy");
        if noisy.is_dir() && !dir.join(NOISY_FILE).is_file() {
            let mut sequence = Self::find(&noisy)?;
            sequence.name = name;
            return Ok(sequence);
        }
        let references = reference_folders(dir).into_iter().find(|r| r.is_dir());
        let mut frames = Vec::new();
        for entry in std::fs::read_dir(dir).map_err(io)? {
            let path = entry.map_err(io)?.path();
            let stem = path.file_stem().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            let file_name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            let frame = if path.is_dir() && path.join(NOISY_FILE).is_file() {
                let reference = Some(path.join(REFERENCE_FILE)).filter(|r| r.is_file());
                FrameFiles { number: number_in(&file_name), name: file_name, path, reference }
            } else if path.is_file() && path.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr")) {
                let reference = references.as_ref().map(|r| r.join(&file_name)).filter(|r| r.is_file());
                FrameFiles { number: number_in(&stem), name: stem, path, reference }
            } else {
                continue;
            };
            frames.push(frame);
        }
        frames.sort_by(|a, b| (a.number, &a.name).cmp(&(b.number, &b.name)));
        let sequence = Sequence { name, frames };
        sequence.check_numbers(dir)?;
        Ok(sequence)
    }

    /// Frame numbers that skip one are a missing frame; one number twice
    /// (a frame's folder beside a file of its name) is two layouts in one folder.
    fn check_numbers(&self, dir: &Path) -> Result<(), SceneError> {
        for pair in self.frames.windows(2) {
            if let (Some(a), Some(b)) = (pair[0].number, pair[1].number) {
                if a == b {
                    return Err(SceneError::Sequence {
                        path: dir.to_path_buf(),
                        message: format!(
                            "frame {a} is there twice: {} and {} (a sequence's folder holds each frame once, as a \
                             dataset folder or as an EXR file; move one of them out)",
                            pair[0].path.display(),
                            pair[1].path.display()
                        ),
                    });
                }
                if b > a + 1 {
                    return Err(SceneError::Sequence {
                        path: dir.to_path_buf(),
                        message: format!(
                            "frame {} is missing: {} is followed by {} (frames are numbered in order; \
                             render the missing frame, or filter the frames on each side as sequences of their own)",
                            a + 1,
                            pair[0].path.display(),
                            pair[1].path.display()
                        ),
                    });
                }
            }
        }
        Ok(())
    }

    /// Read every frame's header (and its reference's) before any is
    /// filtered: all of one size, each holding the channels `request` needs
    /// that the first frame holds (a frame that lacks one is named), the
    /// motion vectors where it asks for them. The size, on success.
    pub fn check(&self, request: &Request) -> Result<(usize, usize), SceneError> {
        let mut size = None;
        let mut first_channels: Option<(PathBuf, Vec<String>)> = None;
        for frame in &self.frames {
            let file = if frame.path.is_dir() { frame.path.join(NOISY_FILE) } else { frame.path.clone() };
            let (names, width, height) = exr_io::channel_names(&file)?;
            match size {
                None => size = Some((width, height)),
                Some(expected) if expected != (width, height) => {
                    let first = self.frames[0].path.clone();
                    return Err(SceneError::SizeMismatch { file, size: (width, height), noisy: first, expected });
                }
                Some(_) => {}
            }
            if let Some(reference) = &frame.reference {
                let (_, w, h) = exr_io::channel_names(reference)?;
                if (w, h) != (width, height) {
                    return Err(SceneError::SizeMismatch {
                        file: reference.clone(),
                        size: (w, h),
                        noisy: file,
                        expected: (width, height),
                    });
                }
            }
            let view = import::Channels::of(&file, names, request.view_layer.as_deref())?;
            let layout = view.layout();
            if request.motion && import::pick(layout.motion(), &view.names).is_none() {
                return Err(SceneError::MissingMotion {
                    scene: frame.name.clone(),
                    origin: super::Origin::File { layout, file },
                });
            }
            // What the first frame holds, every frame holds: a render setting changed mid-sequence is named.
            match &first_channels {
                None => first_channels = Some((file, view.names)),
                Some((first, expected)) => {
                    if let Some(missing) = expected.iter().find(|c| !view.names.contains(c)) {
                        return Err(SceneError::MissingChannel {
                            file,
                            channel: format!("{missing} (which {} has)", first.display()),
                            available: view.names,
                        });
                    }
                }
            }
        }
        size.ok_or_else(|| SceneError::Sequence { path: PathBuf::from(&self.name), message: "no frames".into() })
    }

    /// Load frame `k` for `request` (its reference where the frame has one).
    pub fn load(&self, k: usize, request: &Request) -> Result<Scene, SceneError> {
        let frame = &self.frames[k];
        let request = Request { reference_path: frame.reference.clone(), ..request.clone() };
        let mut scene = super::load(&frame.path, &request)?;
        scene.name = frame.name.clone();
        Ok(scene)
    }
}

/// Where the references of the frames in `dir` are: a `reference/` folder
/// inside it, else one beside it (`noisy/` and `reference/`).
pub(super) fn reference_folders(dir: &Path) -> [PathBuf; 2] {
    [dir.join("reference"), dir.with_file_name("reference")]
}

/// The digits that end `name` (`frame_0012` → 12; `corridor_4spp` has none).
fn number_in(name: &str) -> Option<u64> {
    // ASCII digits are one byte each, so the count is a char boundary.
    let digits = name.bytes().rev().take_while(u8::is_ascii_digit).count();
    name[name.len() - digits..].parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_numbers_are_the_last_digits() {
        assert_eq!(number_in("frame_0012"), Some(12));
        assert_eq!(number_in("shot3_frame9"), Some(9));
        assert_eq!(number_in("0007"), Some(7));
        assert_eq!(number_in("still"), None);
        // Digits inside a name are not a frame number: a sample count, a version.
        assert_eq!(number_in("corridor_4spp"), None);
        assert_eq!(number_in("v2_still"), None);
        assert_eq!(number_in("kadr·0003"), Some(3));
    }
}
