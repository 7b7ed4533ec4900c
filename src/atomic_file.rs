//! Writing a file so that it is either absent, the old version or complete.
//!
//! The bytes go to a hidden temporary sibling (`dir/.name.PID.tmp`: same folder, so the
//! rename stays on one file system, and distinct per process), which is renamed into place
//! once fully written and flushed; on any error the temporary file is removed and `path` is
//! untouched. This is the one implementation: frames, stats summaries, plots, reports and
//! exported meshes all go through [`write_atomically`], text through
//! [`write_text_atomically`] and images through [`write_image_atomically`]. A resumed
//! render removes the stale `.*.tmp` files of its own outputs an interrupted run left
//! behind (`run::output`, which finds what a temporary was for with [`temporary_target`]).

use std::fs::{self, File};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

use image::{ImageBuffer, ImageFormat};

/// Why an atomic write failed: the temporary file could not be created, written or renamed
/// (`Io`, naming the path), or the caller's writer failed (`Write`).
#[derive(Debug)]
pub enum AtomicWriteError<E> {
    Io { path: PathBuf, source: io::Error },
    Write(E),
}

impl<E> AtomicWriteError<E> {
    /// The error as one type, for callers whose writer fails with I/O errors only.
    pub fn into_io(self) -> io::Error
    where
        E: Into<io::Error>,
    {
        match self {
            AtomicWriteError::Io { source, .. } => source,
            AtomicWriteError::Write(e) => e.into(),
        }
    }
}

/// Streams a file through `write` (a buffered writer on a temporary sibling of `path`),
/// then renames it into place.
///
/// # Errors
/// The temporary file cannot be created, flushed or renamed ([`AtomicWriteError::Io`], with
/// the path), or `write` fails ([`AtomicWriteError::Write`]). `path` is then untouched.
pub fn write_atomically<E>(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> Result<(), E>,
) -> Result<(), AtomicWriteError<E>> {
    let tmp = temporary_sibling(path);
    let io_error = |path: &Path| {
        let path = path.to_path_buf();
        move |source| AtomicWriteError::Io { path, source }
    };
    let file = File::create(&tmp).map_err(io_error(&tmp))?;
    let mut writer = BufWriter::with_capacity(1 << 20, file);
    let written = match write(&mut writer) {
        Ok(()) => writer.flush().map_err(io_error(path)),
        Err(e) => Err(AtomicWriteError::Write(e)),
    };
    drop(writer);
    if let Err(e) = written {
        let _ = fs::remove_file(&tmp);
        return Err(e);
    }
    fs::rename(&tmp, path).map_err(|e| {
        let _ = fs::remove_file(&tmp);
        io_error(path)(e)
    })
}

/// Writes `bytes` to `path` atomically; the error names the file that failed.
///
/// # Errors
/// As [`write_atomically`]; the `io::Error` is returned with the path it concerns.
pub fn write_bytes_atomically(path: &Path, bytes: &[u8]) -> Result<(), (PathBuf, io::Error)> {
    write_atomically(path, |w| w.write_all(bytes)).map_err(|e| match e {
        AtomicWriteError::Io { path, source } => (path, source),
        AtomicWriteError::Write(source) => (path.to_path_buf(), source),
    })
}

/// Writes a text file atomically.
///
/// # Errors
/// As [`write_atomically`].
pub fn write_text_atomically(path: &Path, text: &str) -> io::Result<()> {
    write_bytes_atomically(path, text.as_bytes()).map_err(|(_, source)| source)
}

/// Why writing a file failed; both variants name it.
#[derive(Debug, thiserror::Error)]
pub enum FileWriteError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: io::Error },
    #[error("{path}: cannot encode image: {source}")]
    Encode {
        path: PathBuf,
        source: image::ImageError,
    },
}

/// Encodes `image` as `format` into `path` atomically.
///
/// # Errors
/// The file cannot be written ([`FileWriteError::Io`]) or the encoder fails
/// ([`FileWriteError::Encode`]); `path` is then untouched.
pub fn write_image_atomically<P, C>(
    path: &Path,
    image: &ImageBuffer<P, C>,
    format: ImageFormat,
) -> Result<(), FileWriteError>
where
    P: image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
    C: std::ops::Deref<Target = [P::Subpixel]>,
{
    write_atomically(path, |w| image.write_to(w, format)).map_err(|e| match e {
        AtomicWriteError::Io { path, source } => FileWriteError::Io { path, source },
        AtomicWriteError::Write(source) => FileWriteError::Encode {
            path: path.to_path_buf(),
            source,
        },
    })
}

/// Writes an 8-bit RGB PNG atomically.
///
/// # Errors
/// As [`write_image_atomically`].
pub fn write_rgb8_atomically(path: &Path, image: &image::RgbImage) -> Result<(), FileWriteError> {
    write_image_atomically(path, image, ImageFormat::Png)
}

/// The file name a temporary sibling was written for: `frame_0003.png` for
/// `.frame_0003.png.PID.tmp` (or the older `.frame_0003.png.tmp`); `None` for a name that
/// is not a temporary of this module.
pub fn temporary_target(file_name: &str) -> Option<&str> {
    let inner = file_name.strip_prefix('.')?.strip_suffix(".tmp")?;
    let target = match inner.rsplit_once('.') {
        Some((name, pid)) if !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()) => name,
        _ => inner,
    };
    (!target.is_empty()).then_some(target)
}

/// `dir/.name.PID.tmp`: hidden, same folder, distinct per process.
fn temporary_sibling(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.{}.tmp", std::process::id()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<std::ffi::OsString> {
        fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect()
    }

    #[test]
    fn replaces_the_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("plot.svg");
        write_bytes_atomically(&path, b"old").unwrap();
        write_bytes_atomically(&path, b"new").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"new");
        assert_eq!(names(dir.path()), ["plot.svg"]);
    }

    #[test]
    fn failed_write_keeps_the_old_file_and_removes_the_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("mesh.obj");
        write_bytes_atomically(&path, b"complete").unwrap();
        let result = write_atomically(&path, |w| {
            w.write_all(b"half")?;
            Err(io::Error::other("encoder failed"))
        });
        assert!(matches!(result, Err(AtomicWriteError::Write(_))));
        assert_eq!(fs::read(&path).unwrap(), b"complete");
        assert_eq!(names(dir.path()), ["mesh.obj"]);
    }

    #[test]
    fn temporaries_name_their_target() {
        let tmp = temporary_sibling(Path::new("/out/frame_0003.png"));
        let name = tmp.file_name().unwrap().to_str().unwrap();
        assert_eq!(temporary_target(name), Some("frame_0003.png"));
        assert_eq!(temporary_target(".stats.jsonl.tmp"), Some("stats.jsonl"));
        assert_eq!(temporary_target("frame_0003.png"), None);
        assert_eq!(temporary_target(".tmp"), None);
        assert_eq!(temporary_target("..tmp"), None);
    }

    #[test]
    fn missing_folder_names_the_temporary_path() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("absent").join("a.txt");
        let (failed, _) = write_bytes_atomically(&path, b"x").unwrap_err();
        assert_eq!(failed.parent(), path.parent());
    }
}
