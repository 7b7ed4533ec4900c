//! The output folder of a render: frames, `stats.jsonl` (one record per frame) and
//! `summary.json`.
//!
//! Invariant: a file in the folder is either absent or complete. Frames and the summary are
//! written to a hidden temporary file in the same folder and renamed into place (atomic on
//! one file system); a stats line is written with one `write_all` and flushed.

use std::fs::{self, File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use image::{ImageBuffer, ImageFormat, Rgb};
use serde::Serialize;

use crate::frame::FrameRecord;
use crate::render::LinearImage;
use crate::report::Percentiles;

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

#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: cannot encode image: {source}")]
    Encode {
        path: PathBuf,
        source: image::ImageError,
    },
}

fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> OutputError + '_ {
    move |source| OutputError::Io {
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
    /// an interrupted run is dropped) and returned, and new records are appended.
    pub fn open(
        dir: &Path,
        format: FrameFormat,
        shard: Option<Shard>,
        resume: bool,
    ) -> Result<(OutputDir, Vec<FrameRecord>), OutputError> {
        fs::create_dir_all(dir).map_err(io_error(dir))?;
        let (stats_name, summary_name) = match shard {
            Some(s) => (
                format!("stats.{}.jsonl", s.suffix()),
                format!("summary.{}.json", s.suffix()),
            ),
            None => ("stats.jsonl".to_string(), "summary.json".to_string()),
        };
        let stats_path = dir.join(stats_name);
        if resume {
            remove_stale_temporaries(dir);
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
                text.push_str(&serde_json::to_string(r).map_err(|e| OutputError::Io {
                    path: stats_path.clone(),
                    source: e.into(),
                })?);
                text.push('\n');
            }
            write_bytes_atomically(&stats_path, text.as_bytes())?;
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
    pub fn write_frame(&self, index: u32, image: &LinearImage) -> Result<PathBuf, OutputError> {
        let path = self.frame_path(index);
        write_image_atomically(&path, image, self.format)?;
        if self.format == FrameFormat::Exr {
            // Browsers cannot show EXR: the HTML page plays these sRGB previews instead.
            let preview = self.dir.join(format!("preview_{index:04}.png"));
            write_image_atomically(&preview, image, FrameFormat::Png)?;
        }
        Ok(path)
    }

    /// Appends one record to `stats.jsonl`.
    pub fn append_record(&mut self, record: &FrameRecord) -> Result<(), OutputError> {
        let path = self.stats_path.clone();
        let mut line = serde_json::to_string(record).map_err(|e| OutputError::Io {
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
    pub fn write_summary(&self, records: &[FrameRecord]) -> Result<PathBuf, OutputError> {
        let path = self.summary_path.clone();
        let text =
            serde_json::to_string_pretty(&Summary::of(records)).map_err(|e| OutputError::Io {
                path: path.clone(),
                source: e.into(),
            })?;
        write_bytes_atomically(&path, text.as_bytes())?;
        Ok(path)
    }
}

/// Removes `.NAME.tmp` files an interrupted run left behind (never complete outputs).
fn remove_stale_temporaries(dir: &Path) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') && name.ends_with(".tmp") {
            let _ = fs::remove_file(entry.path());
        }
    }
}

/// The records of a stats file up to its first unreadable line (an interrupted write leaves
/// at most a torn last line). A missing file has no records.
fn read_complete_records(path: &Path) -> Result<Vec<FrameRecord>, OutputError> {
    let text = match fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => {
            return Err(OutputError::Io {
                path: path.to_path_buf(),
                source: e,
            });
        }
    };
    Ok(text
        .lines()
        .map_while(|line| serde_json::from_str::<FrameRecord>(line).ok())
        .collect())
}

/// Writes `image` to `path` in `format` through a temporary file in the same folder.
pub fn write_image_atomically(
    path: &Path,
    image: &LinearImage,
    format: FrameFormat,
) -> Result<(), OutputError> {
    let tmp = temporary_sibling(path);
    let encoded = match format {
        FrameFormat::Png => {
            let buffer: ImageBuffer<Rgb<u8>, Vec<u8>> =
                ImageBuffer::from_raw(image.width, image.height, image.to_srgb8())
                    .expect("buffer length matches the image size");
            buffer.save_with_format(&tmp, ImageFormat::Png)
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
            buffer.save_with_format(&tmp, ImageFormat::OpenExr)
        }
    };
    if let Err(source) = encoded {
        let _ = fs::remove_file(&tmp);
        return Err(OutputError::Encode {
            path: path.to_path_buf(),
            source,
        });
    }
    fs::rename(&tmp, path).map_err(io_error(path))
}

/// Writes an 8-bit RGB PNG through a temporary file in the same folder.
pub fn write_rgb8_atomically(path: &Path, image: &image::RgbImage) -> Result<(), OutputError> {
    let tmp = temporary_sibling(path);
    if let Err(source) = image.save_with_format(&tmp, ImageFormat::Png) {
        let _ = fs::remove_file(&tmp);
        return Err(OutputError::Encode {
            path: path.to_path_buf(),
            source,
        });
    }
    fs::rename(&tmp, path).map_err(io_error(path))
}

/// Writes a text file through a temporary file in the same folder.
pub fn write_text_atomically(path: &Path, text: &str) -> std::io::Result<()> {
    write_bytes_atomically(path, text.as_bytes()).map_err(|e| match e {
        OutputError::Io { source, .. } => source,
        other => std::io::Error::other(other.to_string()),
    })
}

fn write_bytes_atomically(path: &Path, bytes: &[u8]) -> Result<(), OutputError> {
    let tmp = temporary_sibling(path);
    fs::write(&tmp, bytes).map_err(io_error(&tmp))?;
    fs::rename(&tmp, path).map_err(io_error(path))
}

/// `dir/.name.tmp`: hidden, same folder (so the rename stays on one file system).
fn temporary_sibling(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.tmp"))
}

/// `summary.json`: totals over the sequence, the preprocessing share of frame time, and
/// min / median / p95 / max of every per-frame phase and count.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    pub frames: usize,
    pub width: u32,
    pub height: u32,
    pub lod_method: String,
    pub total_rays: u64,
    pub total_render_ms: f64,
    pub total_ms: f64,
    pub total_lod_recomputed: u64,
    pub total_nonfinite_samples: u64,
    pub rebuilds: usize,
    /// (animate + dirty + refit + build + lod_update) / total, over the sequence.
    pub preprocessing_share: f64,
    pub mip_histogram: Vec<u64>,
    pub triangles: Percentiles,
    pub animate_ms: Percentiles,
    pub dirty_ms: Percentiles,
    pub refit_ms: Percentiles,
    pub build_ms: Percentiles,
    pub lod_update_ms: Percentiles,
    pub render_ms: Percentiles,
    pub frame_total_ms: Percentiles,
    pub moved_triangles: Percentiles,
    pub deformed_triangles: Percentiles,
    pub lod_recomputed: Percentiles,
    pub rays: Percentiles,
    /// Rays per second of render time over the whole sequence.
    pub rays_per_second: f64,
}

impl Summary {
    pub fn of(records: &[FrameRecord]) -> Summary {
        let first = records.first();
        let spread = |f: fn(&FrameRecord) -> f64| Percentiles::of(records.iter().map(f));
        let sum = |f: fn(&FrameRecord) -> f64| records.iter().map(f).sum::<f64>();
        let mut histogram = vec![0u64; first.map_or(0, |r| r.mip_histogram.len())];
        for r in records {
            for (a, b) in histogram.iter_mut().zip(&r.mip_histogram) {
                *a += b;
            }
        }
        let total_rays = records.iter().map(|r| r.rays).sum();
        let total_render_ms = sum(|r| r.render_ms);
        let total_ms = sum(|r| r.total_ms);
        let preprocessing = sum(|r| {
            r.update.animate_ms
                + r.update.dirty_ms
                + r.update.refit_ms
                + r.update.build_ms
                + r.update.lod_update_ms
        });
        Summary {
            frames: records.len(),
            width: first.map_or(0, |r| r.width),
            height: first.map_or(0, |r| r.height),
            lod_method: first.map_or(String::new(), |r| r.lod_method.clone()),
            total_rays,
            total_render_ms,
            total_ms,
            total_lod_recomputed: records.iter().map(|r| r.update.lod_recomputed as u64).sum(),
            total_nonfinite_samples: records.iter().map(|r| r.nonfinite_samples).sum(),
            rebuilds: records.iter().filter(|r| r.update.rebuild).count(),
            preprocessing_share: if total_ms > 0.0 {
                preprocessing / total_ms
            } else {
                0.0
            },
            mip_histogram: histogram,
            triangles: spread(|r| r.triangles as f64),
            animate_ms: spread(|r| r.update.animate_ms),
            dirty_ms: spread(|r| r.update.dirty_ms),
            refit_ms: spread(|r| r.update.refit_ms),
            build_ms: spread(|r| r.update.build_ms),
            lod_update_ms: spread(|r| r.update.lod_update_ms),
            render_ms: spread(|r| r.render_ms),
            frame_total_ms: spread(|r| r.total_ms),
            moved_triangles: spread(|r| r.update.moved_triangles as f64),
            deformed_triangles: spread(|r| r.update.deformed_triangles as f64),
            lod_recomputed: spread(|r| r.update.lod_recomputed as f64),
            rays: spread(|r| r.rays as f64),
            rays_per_second: if total_render_ms > 0.0 {
                total_rays as f64 / (total_render_ms / 1e3)
            } else {
                0.0
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_names_are_zero_padded() {
        assert_eq!(frame_file_name(7, FrameFormat::Png), "frame_0007.png");
        assert_eq!(frame_file_name(12345, FrameFormat::Exr), "frame_12345.exr");
    }
}
