//! A software device's images are this process's memory.
//!
//! lavapipe and llvmpipe allocate a buffer or texture with the C library's
//! `malloc` and free it with `free`. A frame's image at 1920×1080 (RGBA32F:
//! 33 MB) is above glibc's largest mapping threshold (32 MB), so each is
//! mapped fresh and unmapped when dropped, and the next frame's kernels
//! fault every page of their new images in again: in `bench --frames
//! 1920x1080` this was 25–60 % of a frame's device time, the temporal
//! stage (which makes the most images a frame) hit hardest (docs/JOURNAL.md,
//! "A software device's frames paid for their memory"). A renderer keeps
//! its images from frame to frame; filterjit makes them per frame, so on a
//! software device it asks the C library to keep freed blocks for reuse
//! (unless the user set the library's own knobs:
//! [`super::adapter::Request::keep_freed_images`]).

/// Blocks up to this size come from the heap and go back to it when freed.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const HEAP_BLOCKS_UP_TO: libc::c_int = 1 << 30;

/// Keep freed images in the heap for the next frame's, once per process.
/// The cost: the heap keeps up to its peak until the process ends. Elsewhere
/// than glibc, nothing.
pub(super) fn keep_freed_images() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        static ONCE: std::sync::Once = std::sync::Once::new();
        // SAFETY: mallopt only sets the allocator's parameters.
        ONCE.call_once(|| unsafe {
            libc::mallopt(libc::M_MMAP_THRESHOLD, HEAP_BLOCKS_UP_TO);
            libc::mallopt(libc::M_TRIM_THRESHOLD, HEAP_BLOCKS_UP_TO);
        });
    }
}
