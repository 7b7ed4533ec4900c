//! Whether a merged sequence is complete: every frame of an expected range has a record
//! and a frame file, which is what `render --resume` counts as done. A farm's merge step
//! asks this, so a shard that failed, was cancelled or never ran fails the merge by name
//! instead of leaving a short sequence behind.

use std::ops::Range;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::error::ReportError;
use crate::record::{Record, Sequence};

/// Where an expected range falls short: the frames missing, as half-open runs in order,
/// and the frame files among them that exist but are damaged.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct MissingFrames {
    /// Frames without a record, without a frame file, or whose file is damaged.
    pub runs: Vec<Range<u32>>,
    /// Damaged frame files and what is wrong with each.
    pub damaged: Vec<(PathBuf, String)>,
}

impl MissingFrames {
    /// How many frames are missing (up to the whole `u32` range).
    pub fn count(&self) -> u64 {
        self.runs.iter().map(|r| u64::from(r.end - r.start)).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.runs.is_empty()
    }
}

/// The frames of `expected` that `sequence` lacks: no record, or no frame file
/// (`frame_NNNN.png` or `.exr`) in any of `folders`, or one that does not decode at its
/// record's size ([`frame_file_problem`]). Time and memory grow with the records, not
/// with the range: the missing frames are the gaps between the complete ones.
pub fn missing_frames(
    sequence: &Sequence,
    folders: &[PathBuf],
    expected: Range<u32>,
) -> MissingFrames {
    let records = &sequence.records;
    let first = records.partition_point(|r| r.frame() < expected.start);
    let last = records.partition_point(|r| r.frame() < expected.end);
    let judged: Vec<(u32, Result<(), Option<(PathBuf, String)>>)> = records[first..last]
        .par_iter()
        .map(|r| (r.frame(), judge_frame_file(folders, r)))
        .collect();
    let mut missing = MissingFrames::default();
    let mut next = expected.start;
    for (frame, verdict) in judged {
        match verdict {
            Ok(()) => {
                if frame > next {
                    missing.runs.push(next..frame);
                }
                next = frame + 1;
            }
            Err(damage) => missing.damaged.extend(damage),
        }
    }
    if next < expected.end {
        missing.runs.push(next..expected.end);
    }
    missing
}

/// `Ok` when the record's frame file is complete; else the damaged file and its problem,
/// or `None` when there is no file.
fn judge_frame_file(folders: &[PathBuf], record: &Record) -> Result<(), Option<(PathBuf, String)>> {
    let Some(path) = find_frame_file(folders, record.frame()) else {
        return Err(None);
    };
    let size = record
        .if_present("width", record.values.width)
        .zip(record.if_present("height", record.values.height));
    match frame_file_problem(&path, size) {
        None => Ok(()),
        Some(problem) => Err(Some((path, problem))),
    }
}

/// What is wrong with the frame file at `path`, `None` when it decodes (PNG or OpenEXR, by
/// its extension) as an image of `size` (any size when not known). A file cut short or not
/// an image at all fails to decode.
pub fn frame_file_problem(path: &Path, size: Option<(u32, u32)>) -> Option<String> {
    let image = match image::open(path) {
        Ok(image) => image,
        Err(e) => return Some(format!("cannot be decoded ({e})")),
    };
    let (width, height) = (image.width(), image.height());
    match size {
        Some((w, h)) if (w, h) != (width, height) => {
            Some(format!("is {width}x{height}, but its record says {w}x{h}"))
        }
        _ => None,
    }
}

/// Fails with [`ReportError::MixedRuns`] when the records came from different runs, and
/// with [`ReportError::Incomplete`] when [`missing_frames`] finds any.
///
/// # Errors
/// The records came from different runs, or some frame of `expected` has no record, no
/// frame file or a damaged one.
pub fn require_frames(
    sequence: &Sequence,
    folders: &[PathBuf],
    expected: Range<u32>,
) -> Result<(), ReportError> {
    if let Some(mixed) = &sequence.mixed_runs {
        return Err(ReportError::MixedRuns(mixed.clone()));
    }
    let missing = missing_frames(sequence, folders, expected.clone());
    if missing.is_empty() {
        return Ok(());
    }
    Err(ReportError::Incomplete {
        sources: folders
            .iter()
            .map(|f| f.display().to_string())
            .collect::<Vec<_>>()
            .join(", "),
        count: missing.count(),
        frames: runs(&missing.runs),
        expected: format!("{}..{}", expected.start, expected.end),
        damaged: damaged_list(&missing.damaged),
    })
}

/// The folder of each path given to the report: a folder itself, or a stats file's folder.
pub fn frame_folders(paths: &[PathBuf]) -> Vec<PathBuf> {
    paths
        .iter()
        .map(|p| {
            if p.is_dir() {
                p.clone()
            } else {
                p.parent().map(Path::to_path_buf).unwrap_or_default()
            }
        })
        .collect()
}

/// The frame file of `frame` in the first of `folders` that has one (`.png`, then `.exr`).
fn find_frame_file(folders: &[PathBuf], frame: u32) -> Option<PathBuf> {
    folders.iter().find_map(|folder| {
        ["png", "exr"]
            .iter()
            .map(|ext| folder.join(format!("frame_{frame:04}.{ext}")))
            .find(|path| path.is_file())
    })
}

/// At most this many runs (and damaged files) are named in a message; the rest are counted.
const NAMED_AT_MOST: usize = 40;

/// Runs of frames as `--frames` ranges: `3, 5..8` for 3, 5, 6, 7 (the first
/// [`NAMED_AT_MOST`], then how many more).
fn runs(runs: &[Range<u32>]) -> String {
    let named: Vec<String> = runs
        .iter()
        .take(NAMED_AT_MOST)
        .map(|r| {
            if r.end == r.start + 1 {
                r.start.to_string()
            } else {
                format!("{}..{}", r.start, r.end)
            }
        })
        .collect();
    with_more(named.join(", "), runs.len(), "runs")
}

/// `; damaged frame files: PATH (problem), ...`, or nothing when none is damaged.
fn damaged_list(damaged: &[(PathBuf, String)]) -> String {
    if damaged.is_empty() {
        return String::new();
    }
    let named: Vec<String> = damaged
        .iter()
        .take(NAMED_AT_MOST)
        .map(|(path, problem)| format!("{} {problem}", path.display()))
        .collect();
    let list = with_more(named.join("; "), damaged.len(), "damaged files");
    format!("; damaged frame files: {list}")
}

/// `listed`, followed by how many of `total` were left out.
fn with_more(listed: String, total: usize, what: &str) -> String {
    if total > NAMED_AT_MOST {
        format!("{listed} and {} more {what}", total - NAMED_AT_MOST)
    } else {
        listed
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::FrameRecord;
    use crate::record::Record;

    fn sequence(frames: &[u32]) -> Sequence {
        Sequence {
            records: frames
                .iter()
                .map(|&frame| {
                    Record::new(
                        FrameRecord {
                            frame,
                            ..FrameRecord::default()
                        },
                        [],
                    )
                })
                .collect(),
            files: Vec::new(),
            duplicates_dropped: 0,
            mixed_runs: None,
        }
    }

    /// A 2x1 PNG at `dir/name`.
    fn write_png(dir: &Path, name: &str) {
        image::RgbImage::new(2, 1).save(dir.join(name)).unwrap();
    }

    #[test]
    fn runs_are_half_open_ranges() {
        assert_eq!(runs(&[3..4, 5..8, 10..11]), "3, 5..8, 10");
        assert_eq!(runs(&[0..1]), "0");
        assert_eq!(runs(&[]), "");
        let many: Vec<Range<u32>> = (0..50).map(|i| 2 * i..2 * i + 1).collect();
        assert!(
            runs(&many).ends_with("78 and 10 more runs"),
            "{}",
            runs(&many)
        );
    }

    #[test]
    fn a_frame_needs_its_record_and_a_file_that_decodes() {
        let dir = tempfile::tempdir().unwrap();
        let folders = vec![dir.path().to_path_buf()];
        for frame in [0u32, 1, 3] {
            write_png(dir.path(), &format!("frame_{frame:04}.png"));
        }
        image::Rgb32FImage::new(2, 1)
            .save(dir.path().join("frame_0004.exr"))
            .unwrap();
        // Frame 1 has a file but no record, 2 neither, 5 a record but no file.
        let seq = sequence(&[0, 3, 4, 5]);
        let missing = missing_frames(&seq, &folders, 0..6);
        assert_eq!(missing.runs, [1..3, 5..6]);
        assert_eq!(missing.count(), 3);
        assert!(missing.damaged.is_empty());
        assert!(require_frames(&seq, &folders, 0..1).is_ok());
        let message = require_frames(&seq, &folders, 0..6)
            .unwrap_err()
            .to_string();
        assert!(message.contains("3 frame(s) of 0..6"), "{message}");
        assert!(message.contains("1..3, 5"), "{message}");
        // A file cut short, and one that is text: damaged, named with their problem.
        let whole = std::fs::read(dir.path().join("frame_0003.png")).unwrap();
        std::fs::write(dir.path().join("frame_0003.png"), &whole[..whole.len() / 2]).unwrap();
        std::fs::write(dir.path().join("frame_0004.exr"), "not a picture").unwrap();
        let missing = missing_frames(&seq, &folders, 0..6);
        assert_eq!(missing.runs, [1..6]);
        let damaged: Vec<&Path> = missing.damaged.iter().map(|(p, _)| p.as_path()).collect();
        assert_eq!(
            damaged,
            [
                dir.path().join("frame_0003.png"),
                dir.path().join("frame_0004.exr")
            ]
        );
        let message = require_frames(&seq, &folders, 0..6)
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("damaged frame files: ") && message.contains("cannot be decoded"),
            "{message}"
        );
    }

    #[test]
    fn a_frame_of_another_size_than_its_record_is_damaged() {
        let dir = tempfile::tempdir().unwrap();
        write_png(dir.path(), "frame_0000.png");
        let path = dir.path().join("frame_0000.png");
        assert_eq!(frame_file_problem(&path, Some((2, 1))), None);
        assert_eq!(frame_file_problem(&path, None), None);
        assert_eq!(
            frame_file_problem(&path, Some((4, 4))).as_deref(),
            Some("is 2x1, but its record says 4x4")
        );
    }

    /// Four billion expected frames cost what the records cost: the gaps are runs.
    #[test]
    fn a_huge_range_costs_what_its_records_cost() {
        let dir = tempfile::tempdir().unwrap();
        write_png(dir.path(), "frame_0002.png");
        let folders = vec![dir.path().to_path_buf()];
        let started = std::time::Instant::now();
        let missing = missing_frames(&sequence(&[2]), &folders, 0..4_000_000_000);
        assert_eq!(missing.runs, [0..2, 3..4_000_000_000]);
        assert_eq!(missing.count(), 3_999_999_999);
        assert!(started.elapsed().as_secs() < 5, "{:?}", started.elapsed());
    }
}
