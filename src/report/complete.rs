//! Whether a merged sequence is complete: every frame of an expected range has a record
//! and a frame file, which is what `render --resume` counts as done. A farm's merge step
//! asks this, so a shard that failed, was cancelled or never ran fails the merge by name
//! instead of leaving a short sequence behind.

use std::ops::Range;
use std::path::{Path, PathBuf};

use super::error::ReportError;
use crate::record::Sequence;

/// The frames of `expected` that `sequence` lacks: no record, or no frame file
/// (`frame_NNNN.png` or `.exr`) in any of `folders`.
pub fn missing_frames(sequence: &Sequence, folders: &[PathBuf], expected: Range<u32>) -> Vec<u32> {
    let recorded: std::collections::BTreeSet<u32> =
        sequence.records.iter().map(|r| r.frame()).collect();
    expected
        .filter(|frame| !(recorded.contains(frame) && has_frame_file(folders, *frame)))
        .collect()
}

/// Fails with [`ReportError::Incomplete`] when [`missing_frames`] finds any.
///
/// # Errors
/// Some frame of `expected` has no record or no frame file.
pub fn require_frames(
    sequence: &Sequence,
    folders: &[PathBuf],
    expected: Range<u32>,
) -> Result<(), ReportError> {
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
        count: missing.len(),
        frames: runs(&missing),
        expected: format!("{}..{}", expected.start, expected.end),
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

fn has_frame_file(folders: &[PathBuf], frame: u32) -> bool {
    folders.iter().any(|folder| {
        ["png", "exr"]
            .iter()
            .any(|ext| folder.join(format!("frame_{frame:04}.{ext}")).is_file())
    })
}

/// Sorted frame numbers as `--frames` ranges: `3, 5..8` for 3, 5, 6, 7.
fn runs(frames: &[u32]) -> String {
    let mut parts = Vec::new();
    let mut i = 0;
    while i < frames.len() {
        let start = frames[i];
        let mut end = start + 1;
        while i + 1 < frames.len() && frames[i + 1] == end {
            end += 1;
            i += 1;
        }
        parts.push(if end == start + 1 {
            start.to_string()
        } else {
            format!("{start}..{end}")
        });
        i += 1;
    }
    parts.join(", ")
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
        }
    }

    #[test]
    fn runs_are_half_open_ranges() {
        assert_eq!(runs(&[3, 5, 6, 7, 10]), "3, 5..8, 10");
        assert_eq!(runs(&[0]), "0");
        assert_eq!(runs(&[]), "");
    }

    #[test]
    fn a_frame_needs_its_record_and_its_file() {
        let dir = tempfile::tempdir().unwrap();
        let folders = vec![dir.path().to_path_buf()];
        for frame in [0u32, 1, 3] {
            std::fs::write(dir.path().join(format!("frame_{frame:04}.png")), b"png").unwrap();
        }
        std::fs::write(dir.path().join("frame_0004.exr"), b"exr").unwrap();
        // Frame 1 has a file but no record, 2 neither, 5 a record but no file.
        let seq = sequence(&[0, 3, 4, 5]);
        assert_eq!(missing_frames(&seq, &folders, 0..6), [1, 2, 5]);
        assert!(require_frames(&seq, &folders, 0..1).is_ok());
        let message = require_frames(&seq, &folders, 0..6)
            .unwrap_err()
            .to_string();
        assert!(message.contains("3 frame(s) of 0..6"), "{message}");
        assert!(message.contains("1..3, 5"), "{message}");
    }
}
