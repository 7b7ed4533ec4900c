//! Reading and merging the stats files of one render sequence.
//!
//! Each path given is either a stats file, read as is, or an output folder, from which
//! `stats.jsonl` and every `stats.shard-*.jsonl` are read (a folder with neither is an
//! error). A render split into shards (`--shard I/N`) leaves disjoint frames in several
//! folders or files; they are merged and sorted by frame number. When a frame appears more
//! than once (a resumed render appends a frame it already had) the last record read wins:
//! later lines of a file over earlier ones, later files of a folder (by name, `stats.jsonl`
//! first) and later paths given over earlier ones. The same file named twice is read once.
//! Blank lines are skipped, and so is a last line without its newline that is not a record
//! (what an interrupted write leaves while a render runs); any other line that is not a
//! record is an error naming the file and the 1-based line.
//!
//! Every tool that reads stats files reads them here: `mipray report`, `mipray diff`, the
//! render page (and, line by line through [`Record::parse`], a resumed render).

use std::fs;
use std::path::{Path, PathBuf};

use super::identity::{SettingDifference, describe_differences, run_differences};
use super::read::{Record, RecordError};

/// Why the stats files of a sequence could not be read: every error names the file (and
/// line) it is about.
#[derive(Debug, thiserror::Error)]
pub enum StatsFileError {
    /// A folder or file could not be listed or read.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// A folder holds neither `stats.jsonl` nor `stats.shard-*.jsonl`.
    #[error("{dir}: no stats.jsonl or stats.shard-*.jsonl")]
    NoStatsFile { dir: PathBuf },
    /// A line of a stats file is not JSON.
    #[error("{path}:{line}: invalid JSON: {source}")]
    Json {
        path: PathBuf,
        line: usize,
        source: serde_json::Error,
    },
    /// A line is JSON but not a frame record (no `frame`, a field of the wrong type).
    #[error("{path}:{line}: {message}")]
    Record {
        path: PathBuf,
        line: usize,
        message: String,
    },
    /// The stats files hold no record at all.
    #[error("no frame records in {sources}")]
    Empty { sources: String },
}

impl StatsFileError {
    fn io(path: &Path) -> impl FnOnce(std::io::Error) -> StatsFileError + '_ {
        move |source| StatsFileError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// The merged records of a sequence and where they came from.
#[derive(Debug, Clone, PartialEq)]
pub struct Sequence {
    /// One record per frame, ascending by frame.
    pub records: Vec<Record>,
    /// Every stats file read, in reading order.
    pub files: Vec<PathBuf>,
    /// Records dropped because a later record had the same frame number.
    pub duplicates_dropped: usize,
    /// The first two records read that came from different runs (another scene or
    /// settings), when any did: their frames do not make one sequence.
    pub mixed_runs: Option<MixedRuns>,
}

/// Two records of one sequence that came from different runs, and where each was read.
#[derive(Debug, Clone, PartialEq)]
pub struct MixedRuns {
    pub first: (PathBuf, u32),
    pub second: (PathBuf, u32),
    pub differences: Vec<SettingDifference>,
}

impl std::fmt::Display for MixedRuns {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "frame {} of {} and frame {} of {} were rendered with different settings ({}): \
             their frames are not one sequence",
            self.first.1,
            self.first.0.display(),
            self.second.1,
            self.second.0.display(),
            describe_differences(&self.differences, "in the first", "in the second")
        )
    }
}

/// The first record that disagrees with the first record read that says which run it
/// belongs to (records that do not say are unknown, never a disagreement).
fn find_mixed_runs(files: &[(PathBuf, Vec<Record>)]) -> Option<MixedRuns> {
    let mut identified = files
        .iter()
        .flat_map(|(path, records)| records.iter().map(move |r| (path, r)))
        .filter(|(_, r)| r.values.has_run_identity());
    let (first_path, first) = identified.next()?;
    identified.find_map(|(path, record)| {
        let differences = run_differences(&first.values, &record.values);
        (!differences.is_empty()).then(|| MixedRuns {
            first: (first_path.clone(), first.frame()),
            second: (path.clone(), record.frame()),
            differences,
        })
    })
}

/// Reads, merges, sorts and de-duplicates the records of `dirs` (see the module docs).
///
/// # Errors
/// A folder cannot be read or has no stats file, a line is not a record (the error names
/// the file and line), or there is no record at all.
pub fn load_records(dirs: &[PathBuf]) -> Result<Vec<Record>, StatsFileError> {
    load_sequence(dirs).map(|sequence| sequence.records)
}

/// [`load_records`], also telling which files were read and how many duplicates dropped.
///
/// # Errors
/// As [`load_records`].
pub fn load_sequence(dirs: &[PathBuf]) -> Result<Sequence, StatsFileError> {
    let mut files: Vec<PathBuf> = Vec::new();
    for dir in dirs {
        for file in stats_files(dir)? {
            if !is_listed(&files, &file) {
                files.push(file);
            }
        }
    }
    let mut read = Vec::with_capacity(files.len());
    for file in &files {
        read.push((file.clone(), read_stats_file(file)?));
    }
    let mixed_runs = find_mixed_runs(&read);
    let records: Vec<Record> = read.into_iter().flat_map(|(_, records)| records).collect();
    if records.is_empty() {
        return Err(StatsFileError::Empty {
            sources: describe(dirs),
        });
    }
    let (records, duplicates_dropped) = sort_keeping_last(records);
    Ok(Sequence {
        records,
        files,
        duplicates_dropped,
        mixed_runs,
    })
}

/// Whether `file` (or the same file under another name) is already in `files`.
fn is_listed(files: &[PathBuf], file: &Path) -> bool {
    let canonical = fs::canonicalize(file).ok();
    files
        .iter()
        .any(|f| f == file || (canonical.is_some() && fs::canonicalize(f).ok() == canonical))
}

/// Whether `name` is a stats file of an output folder.
pub fn is_stats_file_name(name: &str) -> bool {
    name == "stats.jsonl" || (name.starts_with("stats.shard-") && name.ends_with(".jsonl"))
}

/// The stats files of `path`: itself if it is a file, else the folder's stats files,
/// `stats.jsonl` first, then the shard files by name.
fn stats_files(path: &Path) -> Result<Vec<PathBuf>, StatsFileError> {
    if path.is_file() {
        return Ok(vec![path.to_path_buf()]);
    }
    let mut names: Vec<String> = Vec::new();
    for entry in fs::read_dir(path).map_err(StatsFileError::io(path))? {
        let entry = entry.map_err(StatsFileError::io(path))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if is_stats_file_name(&name) && entry.path().is_file() {
            names.push(name);
        }
    }
    if names.is_empty() {
        return Err(StatsFileError::NoStatsFile {
            dir: path.to_path_buf(),
        });
    }
    names.sort_by_key(|name| (name != "stats.jsonl", name.clone()));
    Ok(names.into_iter().map(|name| path.join(name)).collect())
}

/// The records of one stats file, in line order (a torn last line left out).
///
/// # Errors
/// The file cannot be read, or a line other than a torn last one is not a record (the
/// error names the file and line).
pub fn read_stats_file(path: &Path) -> Result<Vec<Record>, StatsFileError> {
    let text = fs::read_to_string(path).map_err(StatsFileError::io(path))?;
    let torn_tail = !text.is_empty() && !text.ends_with('\n');
    let lines: Vec<&str> = text.lines().collect();
    let mut records = Vec::new();
    for (index, line) in lines.iter().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let error = match Record::parse(line) {
            Ok(record) => {
                records.push(record);
                continue;
            }
            // An interrupted write: the line was never finished.
            Err(_) if torn_tail && index + 1 == lines.len() => break,
            Err(e) => e,
        };
        return Err(match error {
            RecordError::Json(source) => StatsFileError::Json {
                path: path.to_path_buf(),
                line: index + 1,
                source,
            },
            RecordError::Invalid(message) => StatsFileError::Record {
                path: path.to_path_buf(),
                line: index + 1,
                message,
            },
        });
    }
    Ok(records)
}

/// Sorts by frame (stable), keeps the last record of each frame; returns how many dropped.
fn sort_keeping_last(mut records: Vec<Record>) -> (Vec<Record>, usize) {
    let read = records.len();
    records.sort_by_key(Record::frame);
    let mut kept: Vec<Record> = Vec::with_capacity(read);
    for record in records {
        match kept.last_mut() {
            Some(last) if last.frame() == record.frame() => *last = record,
            _ => kept.push(record),
        }
    }
    let dropped = read - kept.len();
    (kept, dropped)
}

/// The paths as one comma-separated list for messages.
fn describe(dirs: &[PathBuf]) -> String {
    if dirs.is_empty() {
        return "(no folder given)".into();
    }
    let names: Vec<String> = dirs.iter().map(|d| d.display().to_string()).collect();
    names.join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::FrameRecord;

    fn record(frame: u32, render_ms: f64) -> Record {
        let values = FrameRecord {
            frame,
            render_ms,
            ..FrameRecord::default()
        };
        Record::new(values, ["render_ms"])
    }

    #[test]
    fn last_record_of_a_frame_wins() {
        let input = vec![
            record(2, 1.0),
            record(0, 1.0),
            record(2, 2.0),
            record(1, 1.0),
            record(2, 3.0),
        ];
        let (kept, dropped) = sort_keeping_last(input);
        let frames: Vec<(u32, f64)> = kept
            .iter()
            .map(|r| (r.frame(), r.values.render_ms))
            .collect();
        assert_eq!(frames, [(0, 1.0), (1, 1.0), (2, 3.0)]);
        assert_eq!(dropped, 2);
    }

    #[test]
    fn a_torn_last_line_is_left_out_and_any_other_bad_line_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("stats.jsonl");
        fs::write(
            &path,
            "{\"frame\": 0}\n\n{\"frame\": 1}\n{\"frame\": 2, \"tor",
        )
        .unwrap();
        let frames: Vec<u32> = read_stats_file(&path)
            .unwrap()
            .iter()
            .map(Record::frame)
            .collect();
        assert_eq!(frames, [0, 1]);
        // With its newline the line was finished: it is an error.
        fs::write(&path, "{\"frame\": 0}\n{\"frame\": 2, \"tor\n").unwrap();
        let message = read_stats_file(&path).unwrap_err().to_string();
        assert!(
            message.starts_with(&format!("{}:2: invalid JSON", path.display())),
            "{message}"
        );
        // A bad line before the last one is an error even when the file is torn.
        fs::write(&path, "[1]\n{\"frame\": 2, \"tor").unwrap();
        let message = read_stats_file(&path).unwrap_err().to_string();
        assert_eq!(message, format!("{}:1: not a JSON object", path.display()));
    }

    #[test]
    fn stats_file_names() {
        assert!(is_stats_file_name("stats.jsonl"));
        assert!(is_stats_file_name("stats.shard-1-of-4.jsonl"));
        assert!(!is_stats_file_name("stats.jsonl.tmp"));
        assert!(!is_stats_file_name("summary.json"));
        assert!(!is_stats_file_name(".stats.jsonl.tmp"));
    }
}
