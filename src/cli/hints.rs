//! The flag that answers a library error: the library states domain facts
//! ("scene `x` has no `normal`"); the command line knows which of its flags
//! changes the outcome, and says so after the error.

use filterjit::evolve::{RunDirError, TerminalError};
use filterjit::scene::SceneError;

/// The flag to reach for after `error`, if one helps.
pub(crate) fn flag_for(error: &anyhow::Error) -> Option<&'static str> {
    for cause in error.chain() {
        if let Some(SceneError::MissingFeature { .. }) = cause.downcast_ref::<SceneError>() {
            return Some("`filterjit filter --absent zero` reads absent inputs as 0");
        }
        if let Some(e) = cause.downcast_ref::<RunDirError>() {
            return Some(match e {
                RunDirError::OtherSettings(_) => "resume with the same flags, or choose another `--output`",
                RunDirError::Occupied(_) => "`--resume` continues it; or choose another `--output`",
                RunDirError::NothingToResume(_) => "leave out `--resume` to start a run there",
            });
        }
        if let Some(e) = cause.downcast_ref::<TerminalError>() {
            return Some(match e {
                TerminalError::Unknown(_) | TerminalError::NotProvided(_) => "the allowed terminals are `--features`",
                TerminalError::NeedsOutliers(_) => "add `outliers=K` to `--pipeline`, or leave it out of `--features`",
                TerminalError::NeedsTemporal(_) => {
                    "add `temporal=A` to `--pipeline` (and score sequences), or leave it out of `--features`"
                }
                TerminalError::SeedReads(_) => "the seed expression is `--seed-expr`",
            });
        }
    }
    None
}
