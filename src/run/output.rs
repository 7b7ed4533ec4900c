//! The output folder of a render: frames, `stats.jsonl` (one record per frame) and
//! `summary.json`.
//!
//! Invariant: a file in the folder is either absent or complete. Frames and the summary are
//! written through [`crate::atomic_file`] (a hidden temporary file in the same folder,
//! renamed into place); a stats line is written with one `write_all` and flushed. The
//! record is [`FrameRecord`]; the summary is [`Summary`], built from a slice of records.

use std::fs::{self, File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use image::{ImageBuffer, ImageFormat, Rgb};

use crate::atomic_file::{
    FileWriteError, temporary_target, write_bytes_atomically, write_image_atomically,
};
use crate::record::{FrameRecord, Record};
use crate::render::LinearImage;
use crate::report::Summary;

/// Output image format of frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum FrameFormat {
    /// 8-bit sRGB PNG.
    #[default]
    Png,
    /// Linear 32-bit float OpenEXR, for compositing.
    Exr,
}

impl FrameFormat {
    pub fn extension(self) -> &'static str {
        match self {
            FrameFormat::Png => "png",
            FrameFormat::Exr => "exr",
        }
    }
}

fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> FileWriteError + '_ {
    move |source| FileWriteError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// A render's output folder.
pub struct OutputDir {
    dir: PathBuf,
    format: FrameFormat,
    /// `stats.jsonl`, or `stats.shard-I-of-N.jsonl` for a shard.
    stats_path: PathBuf,
    /// `summary.json`, or `summary.shard-I-of-N.json` for a shard.
    summary_path: PathBuf,
    stats: File,
}

/// File name of frame `index`: `frame_0000.png` (at least four digits).
pub fn frame_file_name(index: u32, format: FrameFormat) -> String {
    format!("frame_{index:04}.{}", format.extension())
}

/// One of `count` machines rendering parts of a sequence (0-based `index`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    pub index: u32,
    pub count: u32,
}

impl Shard {
    /// This shard's contiguous block of `frames` (blocks differ in length by at most one;
    /// contiguous so each machine refits from frame to frame).
    pub fn frames(self, frames: std::ops::Range<u32>) -> std::ops::Range<u32> {
        let len = (frames.end - frames.start) as u64;
        let at = |i: u32| frames.start + (len * i as u64 / self.count as u64) as u32;
        at(self.index)..at(self.index + 1)
    }

    fn suffix(self) -> String {
        format!("shard-{}-of-{}", self.index, self.count)
    }
}

impl OutputDir {
    /// Creates the folder (and parents) and starts its stats file. A fresh render truncates
    /// it; with `resume` the complete records already there are kept (a torn last line from
    /// an interrupted run is dropped) and returned, and new records are appended, and the
    /// temporary files an interrupted run of this shard left are removed: those of its
    /// `frames` and its own stats and summary files; never another shard's, which may be
    /// running beside it in the same folder (without a shard, every temporary).
    pub fn open(
        dir: &Path,
        format: FrameFormat,
        shard: Option<Shard>,
        frames: std::ops::Range<u32>,
        resume: bool,
    ) -> Result<(OutputDir, Vec<FrameRecord>), FileWriteError> {
        if dir.exists() && !dir.is_dir() {
            // `create_dir_all` would say only "File exists".
            let message = "exists and is not a folder (the output must be a folder)";
            return Err(io_error(dir)(std::io::Error::other(message)));
        }
        fs::create_dir_all(dir).map_err(io_error(dir))?;
        let (stats_name, summary_name) = match shard {
            Some(s) => (
                format!("stats.{}.jsonl", s.suffix()),
                format!("summary.{}.json", s.suffix()),
            ),
            None => ("stats.jsonl".to_string(), "summary.json".to_string()),
        };
        let stats_path = dir.join(&stats_name);
        if resume {
            remove_stale_temporaries(dir, |target| match shard {
                None => true,
                Some(_) => {
                    target == stats_name
                        || target == summary_name
                        || frame_of_file(target).is_some_and(|f| frames.contains(&f))
                }
            });
        }
        let previous = if resume {
            read_complete_records(&stats_path)?
        } else {
            Vec::new()
        };
        if resume {
            // Rewrite without any torn tail before appending to it.
            let mut text = String::new();
            for r in &previous {
                text.push_str(&serde_json::to_string(r).map_err(|e| FileWriteError::Io {
                    path: stats_path.clone(),
                    source: e.into(),
                })?);
                text.push('\n');
            }
            write_bytes_atomically(&stats_path, text.as_bytes())
                .map_err(|(path, source)| FileWriteError::Io { path, source })?;
        }
        let stats = OpenOptions::new()
            .create(true)
            .append(resume)
            .write(true)
            .truncate(!resume)
            .open(&stats_path)
            .map_err(io_error(&stats_path))?;
        let summary_path = dir.join(summary_name);
        Ok((
            OutputDir {
                dir: dir.to_path_buf(),
                format,
                stats_path,
                summary_path,
                stats,
            },
            previous,
        ))
    }

    pub fn path(&self) -> &Path {
        &self.dir
    }

    pub fn frame_path(&self, index: u32) -> PathBuf {
        self.dir.join(frame_file_name(index, self.format))
    }

    /// Writes a frame atomically (temporary file, then rename); returns its path.
    pub fn write_frame(&self, index: u32, image: &LinearImage) -> Result<PathBuf, FileWriteError> {
        let path = self.frame_path(index);
        write_frame_atomically(&path, image, self.format)?;
        if self.format == FrameFormat::Exr {
            // Browsers cannot show EXR: the HTML page plays these sRGB previews instead.
            let preview = self.dir.join(format!("preview_{index:04}.png"));
            write_frame_atomically(&preview, image, FrameFormat::Png)?;
        }
        Ok(path)
    }

    /// Appends one record to `stats.jsonl`.
    pub fn append_record(&mut self, record: &FrameRecord) -> Result<(), FileWriteError> {
        let path = self.stats_path.clone();
        let mut line = serde_json::to_string(record).map_err(|e| FileWriteError::Io {
            path: path.clone(),
            source: e.into(),
        })?;
        line.push('\n');
        self.stats
            .write_all(line.as_bytes())
            .and_then(|_| self.stats.flush())
            .map_err(io_error(&path))
    }

    /// Writes `summary.json` for the given records.
    pub fn write_summary(&self, records: &[FrameRecord]) -> Result<PathBuf, FileWriteError> {
        let path = self.summary_path.clone();
        let text = serde_json::to_string_pretty(&Summary::of(records)).map_err(|e| {
            FileWriteError::Io {
                path: path.clone(),
                source: e.into(),
            }
        })?;
        write_bytes_atomically(&path, text.as_bytes())
            .map_err(|(path, source)| FileWriteError::Io { path, source })?;
        Ok(path)
    }
}

/// Removes the `.NAME.PID.tmp` (and older `.NAME.tmp`) files an interrupted run left behind
/// whose `NAME` is `owned` (never complete outputs).
fn remove_stale_temporaries(dir: &Path, owned: impl Fn(&str) -> bool) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if temporary_target(&name).is_some_and(&owned) {
            let _ = fs::remove_file(entry.path());
        }
    }
}

/// The frame number of a file a frame writes (`frame_0003.png`, `preview_0003.png`,
/// `lod_0003.png`), `None` for other files.
fn frame_of_file(name: &str) -> Option<u32> {
    let (stem, _extension) = name.rsplit_once('.')?;
    let digits = ["frame_", "preview_", "lod_"]
        .iter()
        .find_map(|prefix| stem.strip_prefix(prefix))?;
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    digits.parse().ok()
}

/// The records of a stats file up to its first line that is not a complete record (an
/// interrupted write leaves at most a torn last line; a resumed render writes its records
/// back, so it keeps only those it can write back unchanged). A missing file has no records.
fn read_complete_records(path: &Path) -> Result<Vec<FrameRecord>, FileWriteError> {
    let text = match fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => {
            return Err(FileWriteError::Io {
                path: path.to_path_buf(),
                source: e,
            });
        }
    };
    Ok(text
        .lines()
        .map_while(|line| Record::parse(line).ok().filter(|r| r.missing().is_empty()))
        .map(|r| r.values)
        .collect())
}

/// Writes `image` to `path` in `format` atomically (see [`crate::atomic_file`]).
pub fn write_frame_atomically(
    path: &Path,
    image: &LinearImage,
    format: FrameFormat,
) -> Result<(), FileWriteError> {
    match format {
        FrameFormat::Png => {
            let buffer: ImageBuffer<Rgb<u8>, Vec<u8>> =
                ImageBuffer::from_raw(image.width, image.height, image.to_srgb8())
                    .expect("buffer length matches the image size");
            write_image_atomically(path, &buffer, ImageFormat::Png)
        }
        FrameFormat::Exr => {
            let data: Vec<f32> = image
                .pixels
                .iter()
                .flat_map(|p| p.to_array().map(|c| if c.is_finite() { c } else { 0.0 }))
                .collect();
            let buffer: ImageBuffer<Rgb<f32>, Vec<f32>> =
                ImageBuffer::from_raw(image.width, image.height, data)
                    .expect("buffer length matches the image size");
            write_image_atomically(path, &buffer, ImageFormat::OpenExr)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A shard resumed beside other shards in one folder removes only its own temporaries:
    /// the others may be writing theirs at that moment.
    #[test]
    fn resumed_shard_removes_only_its_own_temporaries() {
        let dir = tempfile::tempdir().unwrap();
        let names = [
            ".frame_0001.png.11.tmp",            // shard 0's frame
            ".lod_0004.png.11.tmp",              // shard 0's level image
            ".stats.shard-0-of-2.jsonl.11.tmp",  // shard 0's stats
            ".frame_0005.png.22.tmp",            // shard 1's frame
            ".stats.shard-1-of-2.jsonl.22.tmp",  // shard 1's stats
            ".summary.shard-1-of-2.json.22.tmp", // shard 1's summary
            ".index.html.22.tmp",                // the page every shard writes
        ];
        for name in names {
            fs::write(dir.path().join(name), b"half").unwrap();
        }
        let shard = Some(Shard { index: 0, count: 2 });
        OutputDir::open(dir.path(), FrameFormat::Png, shard, 0..5, true).unwrap();
        let mut left: Vec<String> = fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".tmp"))
            .collect();
        left.sort();
        assert_eq!(left, [names[3], names[6], names[4], names[5]]);
        // Alone in its folder (no shard), a resumed render removes every temporary.
        OutputDir::open(dir.path(), FrameFormat::Png, None, 0..10, true).unwrap();
        assert!(
            fs::read_dir(dir.path()).unwrap().all(|e| !e
                .unwrap()
                .file_name()
                .to_string_lossy()
                .ends_with(".tmp"))
        );
    }

    #[test]
    fn frame_files_name_their_frame() {
        assert_eq!(frame_of_file("frame_0003.png"), Some(3));
        assert_eq!(frame_of_file("preview_12345.png"), Some(12345));
        assert_eq!(frame_of_file("lod_0000.png"), Some(0));
        assert_eq!(frame_of_file("frame_.png"), None);
        assert_eq!(frame_of_file("frame_+1.png"), None);
        assert_eq!(frame_of_file("stats.jsonl"), None);
        assert_eq!(frame_of_file("index.html"), None);
    }

    #[test]
    fn frame_names_are_zero_padded() {
        assert_eq!(frame_file_name(7, FrameFormat::Png), "frame_0007.png");
        assert_eq!(frame_file_name(12345, FrameFormat::Exr), "frame_12345.exr");
    }
}
