//! The output folder of a render: frames, `stats.jsonl` (one record per frame) and
//! `summary.json`.
//!
//! Invariant: a file in the folder is either absent or complete. Frames and the summary are
//! written through [`crate::atomic_file`] (a hidden temporary file in the same folder,
//! renamed into place); a stats line is written with one `write_all` and flushed. The
//! record is [`FrameRecord`]; the summary is [`Summary`], built from a slice of records.

use std::collections::BTreeMap;
use std::fs::{self, File, OpenOptions};
use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use image::{ImageBuffer, ImageFormat, Rgb};

use crate::atomic_file::{
    FileWriteError, remove_stale_temporaries, write_bytes_atomically_as, write_image_atomically_as,
    write_rgb_f32_exr_atomically_as,
};
use crate::record::{
    FrameRecord, Record, RunIdentity, StatsFileError, describe_differences, is_stats_file_name,
    read_stats_file,
};
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
    /// The shard's name (`shard-I-of-N`), which names its temporary files; `None` for a
    /// whole render.
    owner: Option<String>,
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

    /// `shard-I-of-N`: in its stats and summary file names and its temporary files'.
    pub fn suffix(self) -> String {
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
    ///
    /// Refused before anything in the folder changes: records of another run (other scene
    /// or settings than `identity`) in a stats file this render would keep (`resume`) or
    /// beside it (another shard's, or a whole render's), and a line of the kept stats file
    /// that is not a record (other than a torn last one): its frame would be rendered again
    /// while the line was silently dropped.
    pub fn open(
        dir: &Path,
        format: FrameFormat,
        shard: Option<Shard>,
        frames: std::ops::Range<u32>,
        resume: bool,
        identity: &RunIdentity,
    ) -> Result<(OutputDir, Vec<FrameRecord>)> {
        if dir.exists() && !dir.is_dir() {
            // `create_dir_all` would say only "File exists".
            let message = "exists and is not a folder (the output must be a folder)";
            return Err(io_error(dir)(std::io::Error::other(message)).into());
        }
        fs::create_dir_all(dir).map_err(io_error(dir))?;
        let (stats_name, summary_name) = match shard {
            Some(s) => (
                format!("stats.{}.jsonl", s.suffix()),
                format!("summary.{}.json", s.suffix()),
            ),
            None => ("stats.jsonl".to_string(), "summary.json".to_string()),
        };
        let owner = shard.map(Shard::suffix);
        let stats_path = dir.join(&stats_name);
        refuse_other_runs_beside(dir, &stats_name, identity)?;
        let previous = if resume {
            let kept = read_complete_records(&stats_path)?;
            refuse_resuming_another_run(dir, &kept, identity)?;
            kept
        } else {
            Vec::new()
        };
        if resume {
            remove_stale_temporaries(dir, owner.as_deref(), |target| {
                target == stats_name
                    || target == summary_name
                    || target == crate::pages::PAGE_NAME
                    || frame_of_file(target).is_some_and(|f| frames.contains(&f))
            });
            // Rewrite without any torn tail before appending to it.
            let mut text = String::new();
            for r in &previous {
                text.push_str(&serde_json::to_string(r).map_err(|e| FileWriteError::Io {
                    path: stats_path.clone(),
                    source: e.into(),
                })?);
                text.push('\n');
            }
            write_bytes_atomically_as(&stats_path, owner.as_deref(), text.as_bytes())
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
                owner,
                stats,
            },
            previous,
        ))
    }

    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// The owner named in this render's temporary files: the shard (`shard-I-of-N`), or
    /// `None` for a whole render (see [`crate::atomic_file::write_atomically_as`]).
    pub fn owner(&self) -> Option<&str> {
        self.owner.as_deref()
    }

    pub fn frame_path(&self, index: u32) -> PathBuf {
        self.dir.join(frame_file_name(index, self.format))
    }

    /// Writes a frame atomically (temporary file, then rename); returns its path.
    pub fn write_frame(&self, index: u32, image: &LinearImage) -> Result<PathBuf, FileWriteError> {
        let path = self.frame_path(index);
        write_frame_atomically_as(&path, self.owner(), image, self.format)?;
        if self.format == FrameFormat::Exr {
            // Browsers cannot show EXR: the HTML page plays these sRGB previews instead.
            let preview = self.dir.join(format!("preview_{index:04}.png"));
            write_frame_atomically_as(&preview, self.owner(), image, FrameFormat::Png)?;
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
        write_bytes_atomically_as(&path, self.owner(), text.as_bytes())
            .map_err(|(path, source)| FileWriteError::Io { path, source })?;
        Ok(path)
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

/// The complete records of a stats file, which a resumed render keeps and writes back, one
/// per frame (the last, as every reader keeps it), by frame: a torn last line (an
/// interrupted write) is dropped, and so is a record that lacks a field (an older
/// version's, which cannot be written back unchanged; its frame is rendered again). A
/// missing file has no records.
///
/// # Errors
/// The file cannot be read, or a line other than the last is not a record: the one stats
/// reader's rule ([`crate::record::read_stats_file`]), so a resume and `mipray report`
/// judge a file alike; the message says how to go on.
fn read_complete_records(path: &Path) -> Result<Vec<FrameRecord>> {
    if !path.exists() {
        return Ok(Vec::new());
    }
    let records = read_stats_file(path).map_err(|error| match error {
        StatsFileError::Json { .. } | StatsFileError::Record { .. } => anyhow::anyhow!(
            "{error}; cannot resume: the line is not a frame record, and a resume would drop \
             it. Remove or mend that line (its frame is then rendered again), or render \
             without --resume to replace the records"
        ),
        other => other.into(),
    })?;
    let mut last_of_each: BTreeMap<u32, FrameRecord> = BTreeMap::new();
    for record in records.into_iter().filter(|r| r.missing().is_empty()) {
        last_of_each.insert(record.frame(), record.values);
    }
    Ok(last_of_each.into_values().collect())
}

/// Refuses a resume whose kept records were rendered by another run than `identity`.
fn refuse_resuming_another_run(
    dir: &Path,
    kept: &[FrameRecord],
    identity: &RunIdentity,
) -> Result<()> {
    let Some(differences) = kept
        .iter()
        .map(|r| identity.differences_from(r))
        .find(|d| !d.is_empty())
    else {
        return Ok(());
    };
    bail!(
        "{}: cannot resume: the frames there were rendered with other settings ({}); \
         render without --resume to replace them, or into another folder",
        dir.display(),
        describe_differences(&differences, "there", "in this render")
    )
}

/// Refuses to render into a folder whose other stats files (other shards', or a whole
/// render's beside shards) hold records of another run than `identity`: their frames would
/// be merged with this render's. A file's records agree with each other (every render
/// that writes one checks), so the first record that says which run it belongs to speaks
/// for the file; lines that are not records are left to the tools that read the file.
fn refuse_other_runs_beside(dir: &Path, own: &str, identity: &RunIdentity) -> Result<()> {
    let Ok(entries) = fs::read_dir(dir) else {
        return Ok(());
    };
    let mut others: Vec<PathBuf> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| is_stats_file_name(n) && n != own)
        })
        .collect();
    others.sort();
    for path in others {
        let Some(first) = first_identified_record(&path) else {
            continue;
        };
        let differences = identity.differences_from(&first);
        if !differences.is_empty() {
            bail!(
                "{}: its frames were rendered with other settings than this render ({}); \
                 the frames of one folder must all be rendered alike: render into another \
                 folder, or remove that file (and its frames) if they are no longer wanted",
                path.display(),
                describe_differences(&differences, "there", "in this render")
            );
        }
    }
    Ok(())
}

/// The first record of a stats file that says which run it belongs to, if any.
fn first_identified_record(path: &Path) -> Option<FrameRecord> {
    let file = File::open(path).ok()?;
    std::io::BufReader::new(file)
        .lines()
        .map_while(std::result::Result::ok)
        .filter_map(|line| Record::parse(&line).ok())
        .map(|r| r.values)
        .find(FrameRecord::has_run_identity)
}

/// Writes `image` to `path` in `format` atomically (see [`crate::atomic_file`]).
pub fn write_frame_atomically(
    path: &Path,
    image: &LinearImage,
    format: FrameFormat,
) -> Result<(), FileWriteError> {
    write_frame_atomically_as(path, None, image, format)
}

/// [`write_frame_atomically`], the temporary named after `owner`.
fn write_frame_atomically_as(
    path: &Path,
    owner: Option<&str>,
    image: &LinearImage,
    format: FrameFormat,
) -> Result<(), FileWriteError> {
    match format {
        FrameFormat::Png => {
            let buffer: ImageBuffer<Rgb<u8>, Vec<u8>> =
                ImageBuffer::from_raw(image.width, image.height, image.to_srgb8())
                    .expect("buffer length matches the image size");
            write_image_atomically_as(path, owner, &buffer, ImageFormat::Png)
        }
        FrameFormat::Exr => {
            // Encoded straight from the frame's pixels: a float copy of a 16384 x 16384
            // frame would be 3.2 GB more.
            let width = image.width as usize;
            let finite = |c: f32| if c.is_finite() { c } else { 0.0 };
            write_rgb_f32_exr_atomically_as(path, owner, (width, image.height as usize), |x, y| {
                let p = image.pixels[y * width + x];
                (finite(p.x), finite(p.y), finite(p.z))
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An EXR frame encoded from the frame's pixels has the bytes `image`'s encoder writes
    /// from a float copy of them (non-finite components as 0), on a size that is not a
    /// whole number of tiles or EXR blocks; it decodes to those values.
    #[test]
    fn exr_frames_have_the_bytes_of_images_encoder() {
        let (width, height) = (37u32, 19u32);
        let pixels: Vec<glam::Vec3> = (0..width * height)
            .map(|i| match i % 7 {
                0 => glam::Vec3::new(f32::NAN, 1.0, -0.0),
                1 => glam::Vec3::new(f32::INFINITY, f32::NEG_INFINITY, 2.5),
                _ => glam::Vec3::new(i as f32 * 0.01, 1.0 / (i as f32 + 1.0), -0.25),
            })
            .collect();
        let frame = LinearImage {
            width,
            height,
            pixels,
        };
        let dir = tempfile::tempdir().unwrap();
        let ours = dir.path().join("ours.exr");
        write_frame_atomically(&ours, &frame, FrameFormat::Exr).unwrap();
        let finite = |c: f32| if c.is_finite() { c } else { 0.0 };
        let copy: Vec<f32> = frame
            .pixels
            .iter()
            .flat_map(|p| p.to_array().map(finite))
            .collect();
        let buffer: ImageBuffer<Rgb<f32>, Vec<f32>> =
            ImageBuffer::from_raw(width, height, copy.clone()).unwrap();
        let mut theirs = std::io::Cursor::new(Vec::new());
        buffer.write_to(&mut theirs, ImageFormat::OpenExr).unwrap();
        assert_eq!(fs::read(&ours).unwrap(), theirs.into_inner());
        let decoded = image::open(&ours).unwrap().into_rgb32f();
        assert_eq!(decoded.into_raw(), copy);
    }

    fn temporaries_in(dir: &Path) -> Vec<String> {
        let mut left: Vec<String> = fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".tmp"))
            .collect();
        left.sort();
        left
    }

    /// A render resumed beside shards in one folder (a shard, or a whole render) removes
    /// only its own temporaries: the others may be writing theirs at that moment.
    #[test]
    fn resumes_remove_only_their_own_temporaries() {
        let dir = tempfile::tempdir().unwrap();
        let shard_0 = [
            ".frame_0001.png.shard-0-of-2.11.tmp",
            ".lod_0004.png.shard-0-of-2.11.tmp",
            ".stats.shard-0-of-2.jsonl.shard-0-of-2.11.tmp",
            ".index.html.shard-0-of-2.11.tmp",
        ];
        let shard_1 = [
            ".frame_0005.png.shard-1-of-2.22.tmp",
            ".index.html.shard-1-of-2.22.tmp",
            ".stats.shard-1-of-2.jsonl.shard-1-of-2.22.tmp",
            ".summary.shard-1-of-2.json.shard-1-of-2.22.tmp",
        ];
        // A whole render's (and an older version's, which named no owner).
        let whole = [
            ".frame_0005.png.33.tmp",
            ".index.html.33.tmp",
            ".stats.jsonl.33.tmp",
            ".summary.json.tmp",
        ];
        let report = [".index.html.report.44.tmp", ".report.svg.report.44.tmp"];
        for name in shard_0.iter().chain(&shard_1).chain(&whole).chain(&report) {
            fs::write(dir.path().join(name), b"half").unwrap();
        }
        let sorted = |names: &[&[&str]]| {
            let mut all: Vec<String> = names.concat().iter().map(|n| n.to_string()).collect();
            all.sort();
            all
        };
        let identity = RunIdentity::default();
        let open = |shard: Option<Shard>, frames: std::ops::Range<u32>| {
            OutputDir::open(dir.path(), FrameFormat::Png, shard, frames, true, &identity).unwrap();
        };
        open(Some(Shard { index: 0, count: 2 }), 0..5);
        assert_eq!(
            temporaries_in(dir.path()),
            sorted(&[&shard_1, &whole, &report])
        );
        open(None, 0..10);
        assert_eq!(temporaries_in(dir.path()), sorted(&[&shard_1, &report]));
        open(Some(Shard { index: 1, count: 2 }), 5..10);
        assert_eq!(temporaries_in(dir.path()), sorted(&[&report]));
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
