//! Writing a file so that it is either absent, the old version or complete.
//!
//! The bytes go to a hidden temporary sibling (`dir/.name.PID.tmp`: same folder, so the
//! rename stays on one file system, and distinct per process; `dir/.name.OWNER.PID.tmp`
//! when the writer names its owner, a shard or a command), which is renamed into place
//! once fully written and flushed; on any error the temporary file is removed and `path` is
//! untouched. A path that is a symbolic link is written through (the file it points to is
//! replaced, from a temporary beside that file); a path that is a device or a named pipe is
//! written in place, with no temporary. This is the one implementation: frames, stats
//! summaries, plots, pages, reports and exported meshes all go through
//! [`write_atomically`] (or [`write_atomically_as`], naming the owner), text through
//! [`write_text_atomically`], images through [`write_image_atomically`] and EXR frames,
//! encoded from the frame's own pixels, through [`write_rgb_f32_exr_atomically_as`]. A run that
//! starts again (a resumed render, `mipray report`) removes the stale temporaries its
//! owner left for the files it writes, and no others ([`remove_stale_temporaries`]).

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
    write_atomically_as(path, None, write)
}

/// [`write_atomically`], with the temporary named after its `owner` (a shard,
/// `shard-1-of-4`, or a command, `report`) so that a later run of that owner can tell its
/// own stale temporaries from those of others writing into the same folder
/// ([`remove_stale_temporaries`]); `None`: a temporary of nobody in particular (a whole
/// render, every other command).
///
/// A `path` that is a symbolic link is written through: the file it points to (after every
/// link) is replaced, from a temporary beside it, and the link stays. A `path` that exists
/// and is neither a regular file nor a folder (a device such as `/dev/null`, a named pipe)
/// is written directly, with no temporary and no rename, since neither can be replaced
/// whole.
///
/// # Errors
/// As [`write_atomically`]; also a chain of more than 40 links.
pub fn write_atomically_as<E>(
    path: &Path,
    owner: Option<&str>,
    write: impl FnOnce(&mut BufWriter<File>) -> Result<(), E>,
) -> Result<(), AtomicWriteError<E>> {
    let io_error = |path: &Path| {
        let path = path.to_path_buf();
        move |source| AtomicWriteError::Io { path, source }
    };
    let (target, kind) = destination(path).map_err(io_error(path))?;
    if kind == Destination::Special {
        let file = fs::OpenOptions::new()
            .write(true)
            .open(&target)
            .map_err(io_error(path))?;
        let mut writer = BufWriter::with_capacity(1 << 16, file);
        write(&mut writer).map_err(AtomicWriteError::Write)?;
        return writer.flush().map_err(io_error(path));
    }
    let tmp = temporary_sibling(&target, owner);
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
    fs::rename(&tmp, &target).map_err(|e| {
        let _ = fs::remove_file(&tmp);
        io_error(path)(e)
    })
}

/// What a destination path is, once its links are followed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Destination {
    /// Absent, a regular file or a folder: replaced by a rename (which fails, naming the
    /// path, for a folder).
    Replaced,
    /// A device, named pipe or socket: written in place.
    Special,
}

/// The path a write to `path` lands on (links followed, relative link targets taken from
/// the link's folder) and what is there. A dangling link yields its target, which the
/// write creates.
fn destination(path: &Path) -> io::Result<(PathBuf, Destination)> {
    let mut current = path.to_path_buf();
    for _ in 0..=MAX_LINKS {
        let metadata = match fs::symlink_metadata(&current) {
            Ok(m) => m,
            // Absent, or not inspectable: the create or the rename says what is wrong.
            Err(_) => return Ok((current, Destination::Replaced)),
        };
        let kind = metadata.file_type();
        if kind.is_symlink() {
            let link = fs::read_link(&current)?;
            current = match current.parent() {
                Some(folder) if link.is_relative() => folder.join(link),
                _ => link,
            };
        } else if kind.is_file() || kind.is_dir() {
            return Ok((current, Destination::Replaced));
        } else {
            return Ok((current, Destination::Special));
        }
    }
    Err(io::Error::other(format!(
        "more than {MAX_LINKS} symbolic links in a chain (a loop?)"
    )))
}

/// Links followed at most, as Linux's `ELOOP` limit.
const MAX_LINKS: usize = 40;

/// Writes `bytes` to `path` atomically; the error names the file that failed.
///
/// # Errors
/// As [`write_atomically`]; the `io::Error` is returned with the path it concerns.
pub fn write_bytes_atomically(path: &Path, bytes: &[u8]) -> Result<(), (PathBuf, io::Error)> {
    write_bytes_atomically_as(path, None, bytes)
}

/// [`write_bytes_atomically`] with a temporary named after `owner` (see
/// [`write_atomically_as`]).
///
/// # Errors
/// As [`write_atomically`]; the `io::Error` is returned with the path it concerns.
pub fn write_bytes_atomically_as(
    path: &Path,
    owner: Option<&str>,
    bytes: &[u8],
) -> Result<(), (PathBuf, io::Error)> {
    write_atomically_as(path, owner, |w| w.write_all(bytes)).map_err(|e| match e {
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
    write_image_atomically_as(path, None, image, format)
}

/// [`write_image_atomically`] with a temporary named after `owner` (see
/// [`write_atomically_as`]).
///
/// # Errors
/// As [`write_image_atomically`].
pub fn write_image_atomically_as<P, C>(
    path: &Path,
    owner: Option<&str>,
    image: &ImageBuffer<P, C>,
    format: ImageFormat,
) -> Result<(), FileWriteError>
where
    P: image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
    C: std::ops::Deref<Target = [P::Subpixel]>,
{
    write_encoded_atomically_as(path, owner, |mut w| image.write_to(&mut w, format))
}

/// Writes a linear RGB image of `width x height` pixels as a 32-bit float OpenEXR file
/// (the layout and compression `image`'s EXR encoder writes) atomically, pixel `(x, y)`
/// read from `pixel` as the encoder asks for it: no copy of the image is made.
///
/// # Errors
/// As [`write_image_atomically`].
pub fn write_rgb_f32_exr_atomically_as(
    path: &Path,
    owner: Option<&str>,
    (width, height): (usize, usize),
    pixel: impl Fn(usize, usize) -> (f32, f32, f32) + Sync,
) -> Result<(), FileWriteError> {
    use exr::prelude::{Image, SpecificChannels, Vec2, WritableImage};
    write_encoded_atomically_as(path, owner, |w| {
        Image::from_channels(
            (width, height),
            SpecificChannels::rgb(|at: Vec2<usize>| pixel(at.x(), at.y())),
        )
        .write()
        .to_buffered(w)
        .map_err(|e| match e {
            exr::error::Error::Io(e) => image::ImageError::IoError(e),
            // As `image`'s EXR encoder reports the crate's other errors: one line.
            e => image::ImageError::Decoding(image::error::DecodingError::new(
                ImageFormat::OpenExr.into(),
                e.to_string(),
            )),
        })
    })
}

/// Writes what `encode` writes into `path` atomically. Encoders may seek: into a temporary
/// (a regular file) they write directly; a device or pipe cannot seek, so it gets the bytes
/// whole, encoded in memory first.
fn write_encoded_atomically_as(
    path: &Path,
    owner: Option<&str>,
    encode: impl Fn(&mut dyn SeekWrite) -> Result<(), image::ImageError>,
) -> Result<(), FileWriteError> {
    let encode = |w: &mut BufWriter<File>| -> Result<(), image::ImageError> {
        if w.get_ref().metadata()?.is_file() {
            return encode(w);
        }
        let mut bytes = io::Cursor::new(Vec::new());
        encode(&mut bytes)?;
        w.write_all(bytes.get_ref())
            .map_err(image::ImageError::IoError)
    };
    write_atomically_as(path, owner, encode).map_err(|e| match e {
        AtomicWriteError::Io { path, source } => FileWriteError::Io { path, source },
        AtomicWriteError::Write(source) => FileWriteError::Encode {
            path: path.to_path_buf(),
            source,
        },
    })
}

/// A writer encoders can seek in.
trait SeekWrite: Write + io::Seek {}
impl<T: Write + io::Seek> SeekWrite for T {}

/// Writes an 8-bit RGB PNG atomically.
///
/// # Errors
/// As [`write_image_atomically`].
pub fn write_rgb8_atomically(path: &Path, image: &image::RgbImage) -> Result<(), FileWriteError> {
    write_image_atomically(path, image, ImageFormat::Png)
}

/// A temporary file of this module, read from its name: `.frame_0003.png.PID.tmp` (no
/// owner), `.frame_0003.png.shard-1-of-4.PID.tmp` (owner `shard-1-of-4`) or the older
/// `.frame_0003.png.tmp` (no owner).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Temporary<'a> {
    /// The file it was written for (`frame_0003.png`).
    pub target: &'a str,
    /// Who wrote it (see [`write_atomically_as`]).
    pub owner: Option<&'a str>,
}

impl<'a> Temporary<'a> {
    /// `None` for a name that is not a temporary of this module.
    pub fn parse(file_name: &'a str) -> Option<Temporary<'a>> {
        let inner = file_name.strip_prefix('.')?.strip_suffix(".tmp")?;
        let inner = match inner.rsplit_once('.') {
            Some((name, pid)) if is_number(pid) => name,
            _ => inner,
        };
        let (target, owner) = match inner.rsplit_once('.') {
            Some((name, owner)) if is_owner(owner) => (name, Some(owner)),
            _ => (inner, None),
        };
        (!target.is_empty()).then_some(Temporary { target, owner })
    }
}

fn is_number(s: &str) -> bool {
    !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit())
}

/// An owner's name in a temporary's name: a shard's (`shard-1-of-4`) or `report`.
fn is_owner(s: &str) -> bool {
    if s == REPORT_OWNER {
        return true;
    }
    let numbers = s
        .strip_prefix("shard-")
        .and_then(|rest| rest.split_once("-of-"));
    numbers.is_some_and(|(index, count)| is_number(index) && is_number(count))
}

/// The owner of the temporaries `mipray report` writes (its plot and page).
pub const REPORT_OWNER: &str = "report";

/// The file name a temporary sibling was written for: `frame_0003.png` for
/// `.frame_0003.png.PID.tmp` (or `.frame_0003.png.shard-1-of-4.PID.tmp`, or the older
/// `.frame_0003.png.tmp`); `None` for a name that is not a temporary of this module.
pub fn temporary_target(file_name: &str) -> Option<&str> {
    Temporary::parse(file_name).map(|t| t.target)
}

/// Removes the temporaries in `dir` that an interrupted run of `owner` left behind for
/// files it `writes` (by target name): never another owner's, which may be in the middle
/// of its own write in the same folder, and never a complete file. Returns how many were
/// removed; a folder that cannot be read has none.
pub fn remove_stale_temporaries(
    dir: &Path,
    owner: Option<&str>,
    writes: impl Fn(&str) -> bool,
) -> usize {
    let Ok(entries) = fs::read_dir(dir) else {
        return 0;
    };
    let mut removed = 0;
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let Some(temporary) = Temporary::parse(&name) else {
            continue;
        };
        if temporary.owner == owner
            && writes(temporary.target)
            && entry.file_type().is_ok_and(|t| t.is_file())
            && fs::remove_file(entry.path()).is_ok()
        {
            removed += 1;
        }
    }
    removed
}

/// `dir/.name.PID.tmp` (`dir/.name.OWNER.PID.tmp` with an owner): hidden, same folder,
/// distinct per process.
fn temporary_sibling(path: &Path, owner: Option<&str>) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let pid = std::process::id();
    match owner {
        Some(owner) => path.with_file_name(format!(".{name}.{owner}.{pid}.tmp")),
        None => path.with_file_name(format!(".{name}.{pid}.tmp")),
    }
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
        let tmp = temporary_sibling(Path::new("/out/frame_0003.png"), None);
        let name = tmp.file_name().unwrap().to_str().unwrap();
        assert_eq!(temporary_target(name), Some("frame_0003.png"));
        assert_eq!(temporary_target(".stats.jsonl.tmp"), Some("stats.jsonl"));
        assert_eq!(temporary_target("frame_0003.png"), None);
        assert_eq!(temporary_target(".tmp"), None);
        assert_eq!(temporary_target("..tmp"), None);
    }

    #[test]
    fn temporaries_name_their_owner() {
        let tmp = temporary_sibling(Path::new("out/frame_0003.png"), Some("shard-1-of-4"));
        let name = tmp.file_name().unwrap().to_str().unwrap();
        let parsed = Temporary::parse(name).unwrap();
        assert_eq!(parsed.target, "frame_0003.png");
        assert_eq!(parsed.owner, Some("shard-1-of-4"));
        let shard_stats = Temporary::parse(".stats.shard-0-of-2.jsonl.shard-0-of-2.7.tmp");
        assert_eq!(
            shard_stats,
            Some(Temporary {
                target: "stats.shard-0-of-2.jsonl",
                owner: Some("shard-0-of-2")
            })
        );
        let report = Temporary::parse(".report.svg.report.7.tmp").unwrap();
        assert_eq!(
            (report.target, report.owner),
            ("report.svg", Some("report"))
        );
        // A shard's stats file written by a whole render (or an older version): no owner.
        let unowned = Temporary::parse(".stats.shard-0-of-2.jsonl.7.tmp").unwrap();
        assert_eq!(
            (unowned.target, unowned.owner),
            ("stats.shard-0-of-2.jsonl", None)
        );
    }

    #[test]
    fn stale_temporaries_of_other_owners_are_kept() {
        let dir = tempfile::tempdir().unwrap();
        let files = [
            ".frame_0001.png.shard-0-of-2.5.tmp",
            ".frame_0001.png.5.tmp",
            ".index.html.report.5.tmp",
            ".frame_0009.png.shard-0-of-2.5.tmp",
        ];
        for name in files {
            fs::write(dir.path().join(name), b"half").unwrap();
        }
        let frame_1 = |target: &str| target == "frame_0001.png";
        assert_eq!(
            remove_stale_temporaries(dir.path(), Some("shard-0-of-2"), frame_1),
            1
        );
        let mut left = names(dir.path());
        left.sort();
        assert_eq!(left, [files[1], files[3], files[2]]);
        assert_eq!(remove_stale_temporaries(dir.path(), None, |_| true), 1);
        assert_eq!(
            remove_stale_temporaries(dir.path(), Some("report"), |_| true),
            1
        );
        assert_eq!(names(dir.path()), [files[3]]);
    }

    /// A link as the destination is written through: its target gets the bytes (replaced
    /// from a temporary beside it, in its own folder) and the link stays a link.
    #[cfg(unix)]
    #[test]
    fn a_symbolic_link_is_written_through() {
        let dir = tempfile::tempdir().unwrap();
        let elsewhere = dir.path().join("elsewhere");
        let out = dir.path().join("out");
        fs::create_dir_all(&elsewhere).unwrap();
        fs::create_dir_all(&out).unwrap();
        fs::write(elsewhere.join("plot.svg"), b"old").unwrap();
        let link = out.join("plot.svg");
        std::os::unix::fs::symlink("../elsewhere/plot.svg", &link).unwrap();
        write_bytes_atomically(&link, b"new").unwrap();
        assert!(
            fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        assert_eq!(fs::read(elsewhere.join("plot.svg")).unwrap(), b"new");
        assert_eq!(names(&out), ["plot.svg"]);
        assert_eq!(names(&elsewhere), ["plot.svg"]);
        // A dangling link creates its target; a loop of links is an error naming the path.
        fs::remove_file(elsewhere.join("plot.svg")).unwrap();
        write_bytes_atomically(&link, b"again").unwrap();
        assert_eq!(fs::read(elsewhere.join("plot.svg")).unwrap(), b"again");
        let looped = out.join("loop");
        std::os::unix::fs::symlink("loop", &looped).unwrap();
        let (path, error) = write_bytes_atomically(&looped, b"x").unwrap_err();
        assert_eq!(path, looped);
        assert!(error.to_string().contains("symbolic links"), "{error}");
    }

    /// A named pipe (as a device) cannot be replaced by a rename: it is written in place,
    /// and stays a pipe.
    #[cfg(unix)]
    #[test]
    fn a_named_pipe_is_written_in_place() {
        use std::os::unix::fs::FileTypeExt;
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("junit.xml");
        let name = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: `name` is a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(name.as_ptr(), 0o600) }, 0);
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || fs::read(fifo).unwrap())
        };
        write_bytes_atomically(&fifo, b"through the pipe").unwrap();
        // (Before the join: a pipe replaced by a file would leave the reader waiting.)
        assert!(fs::metadata(&fifo).unwrap().file_type().is_fifo());
        assert_eq!(names(dir.path()), ["junit.xml"]);
        assert_eq!(reader.join().unwrap(), b"through the pipe");
        // Images too (their encoders seek, which a pipe cannot).
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || fs::read(fifo).unwrap())
        };
        write_rgb8_atomically(&fifo, &image::RgbImage::new(2, 2)).unwrap();
        assert!(reader.join().unwrap().starts_with(b"\x89PNG"));
        assert!(fs::metadata(&fifo).unwrap().file_type().is_fifo());
        // And EXR frames, encoded from a closure.
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || fs::read(fifo).unwrap())
        };
        write_rgb_f32_exr_atomically_as(&fifo, None, (3, 2), |x, y| (x as f32, y as f32, 0.5))
            .unwrap();
        let bytes = reader.join().unwrap();
        assert!(bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]), "not an EXR");
        let decoded = image::load_from_memory(&bytes).unwrap().into_rgb32f();
        assert_eq!(decoded.get_pixel(2, 1).0, [2.0, 1.0, 0.5]);
        assert!(fs::metadata(&fifo).unwrap().file_type().is_fifo());
    }

    #[test]
    fn missing_folder_names_the_temporary_path() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("absent").join("a.txt");
        let (failed, _) = write_bytes_atomically(&path, b"x").unwrap_err();
        assert_eq!(failed.parent(), path.parent());
    }
}
