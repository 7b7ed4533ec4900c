//! Whether this process can hold what a command keeps for frames of one size, checked
//! before any work starts: a `--size` too large for the memory the process may use fails
//! at once with an error naming it, not with an abort after minutes of rendering.
//!
//! Each command states how many bytes per pixel it holds at least (its frames' pixels, its
//! recorded rays); [`check_frame_memory`] reserves that much once and frees it. The figure
//! is a lower bound: what a command allocates besides (scene, textures, encoders) comes on
//! top, so a size just under the limit can still run out. The check sees the process's own
//! limits (`ulimit -v`, the address space); where the system overcommits memory it cannot
//! foresee the kernel's out-of-memory killer.

use std::collections::TryReserveError;

/// Bytes of a linear pixel as the film keeps it (`Vec3`).
pub const LINEAR_PIXEL_BYTES: u64 = std::mem::size_of::<glam::Vec3>() as u64;

/// Bytes of an 8-bit sRGB pixel (a written frame, a compared image).
pub const SRGB8_PIXEL_BYTES: u64 = 3;

/// A `--size` whose frames need more memory than this process can allocate.
#[derive(Debug, thiserror::Error)]
#[error(
    "--size {width}x{height}: {what} needs at least {gb:.2} GB, and this process cannot \
     allocate that ({cause}); use a smaller size or allow the process more memory",
    gb = *bytes as f64 / 1e9
)]
pub struct FrameTooLarge {
    pub width: u32,
    pub height: u32,
    /// What needs the memory ("rendering and writing a frame this size as PNG").
    pub what: String,
    pub bytes: u64,
    pub cause: TryReserveError,
}

/// The bytes `bytes_per_pixel` come to over a `width x height` frame (saturating: a
/// product past `u64` is refused like any other too large figure).
pub fn frame_bytes(width: u32, height: u32, bytes_per_pixel: u64) -> u64 {
    (u64::from(width) * u64::from(height)).saturating_mul(bytes_per_pixel)
}

/// Checks that this process can allocate `bytes_per_pixel` for every pixel of a `width x
/// height` frame (see the module head); `what` names what needs them, for the error.
///
/// # Errors
/// The allocation is refused: the error names the size, what needs it and the bytes.
pub fn check_frame_memory(
    width: u32,
    height: u32,
    bytes_per_pixel: u64,
    what: impl FnOnce() -> String,
) -> Result<(), FrameTooLarge> {
    let bytes = frame_bytes(width, height, bytes_per_pixel);
    let mut probe: Vec<u8> = Vec::new();
    probe
        .try_reserve_exact(usize::try_from(bytes).unwrap_or(usize::MAX))
        .map_err(|cause| FrameTooLarge {
            width,
            height,
            what: what(),
            bytes,
            cause,
        })?;
    // The probe must really be allocated: a block made and freed unused is one the
    // optimizer may leave out, taking the allocation to succeed (a release build did, and
    // a 16384x16384 render then aborted in its first allocation instead of this error).
    std::hint::black_box(probe.as_mut_ptr());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_bytes_saturate_instead_of_wrapping() {
        assert_eq!(frame_bytes(800, 600, 15), 7_200_000);
        assert_eq!(frame_bytes(0, 600, 15), 0);
        assert_eq!(frame_bytes(u32::MAX, u32::MAX, u64::MAX), u64::MAX);
    }

    #[test]
    fn a_small_frame_passes_and_an_impossible_one_is_refused_with_its_size() {
        assert!(check_frame_memory(64, 48, 15, || "a frame".into()).is_ok());
        assert!(check_frame_memory(0, 0, 15, || "a frame".into()).is_ok());
        // More than any address space holds: refused whatever the machine.
        let err = check_frame_memory(u32::MAX, u32::MAX, 1 << 20, || "a test frame".into())
            .expect_err("2^84 bytes");
        let message = err.to_string();
        assert!(
            message.starts_with(&format!(
                "--size {}x{}: a test frame needs at least",
                u32::MAX,
                u32::MAX
            )),
            "{message}"
        );
        assert!(message.contains("cannot allocate"), "{message}");
    }
}
