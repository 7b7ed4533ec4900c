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
    stats: File,
}

/// File name of frame `index`: `frame_0000.png` (at least four digits).
pub fn frame_file_name(index: u32, format: FrameFormat) -> String {
    format!("frame_{index:04}.{}", format.extension())
}

impl OutputDir {
    /// Creates the folder (and parents) and starts a fresh `stats.jsonl`.
    pub fn create(dir: &Path, format: FrameFormat) -> Result<OutputDir, OutputError> {
        fs::create_dir_all(dir).map_err(io_error(dir))?;
        let stats_path = dir.join("stats.jsonl");
        let stats = OpenOptions::new()
            .create(true)
            .write(true)
            .truncate(true)
            .open(&stats_path)
            .map_err(io_error(&stats_path))?;
        Ok(OutputDir {
            dir: dir.to_path_buf(),
            format,
            stats,
        })
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
        Ok(path)
    }

    /// Appends one record to `stats.jsonl`.
    pub fn append_record(&mut self, record: &FrameRecord) -> Result<(), OutputError> {
        let path = self.dir.join("stats.jsonl");
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
        let path = self.dir.join("summary.json");
        let text =
            serde_json::to_string_pretty(&Summary::of(records)).map_err(|e| OutputError::Io {
                path: path.clone(),
                source: e.into(),
            })?;
        write_bytes_atomically(&path, text.as_bytes())?;
        Ok(path)
    }
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

/// Minimum, median and maximum of one per-frame quantity.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Spread {
    pub min: f64,
    pub median: f64,
    pub max: f64,
}

impl Spread {
    pub fn of(values: impl IntoIterator<Item = f64>) -> Spread {
        let mut v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return Spread {
                min: 0.0,
                median: 0.0,
                max: 0.0,
            };
        }
        v.sort_by(f64::total_cmp);
        let mid = v.len() / 2;
        let median = if v.len() % 2 == 1 {
            v[mid]
        } else {
            0.5 * (v[mid - 1] + v[mid])
        };
        Spread {
            min: v[0],
            median,
            max: v[v.len() - 1],
        }
    }
}

/// `summary.json`: totals over the sequence and the spread of every per-frame field.
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
    pub mip_histogram: Vec<u64>,
    pub triangles: Spread,
    pub animate_ms: Spread,
    pub build_ms: Spread,
    pub lod_update_ms: Spread,
    pub lod_recomputed: Spread,
    pub render_ms: Spread,
    pub frame_total_ms: Spread,
    pub rays: Spread,
    /// Rays per second of render time over the whole sequence.
    pub rays_per_second: f64,
}

impl Summary {
    pub fn of(records: &[FrameRecord]) -> Summary {
        let first = records.first();
        let spread = |f: fn(&FrameRecord) -> f64| Spread::of(records.iter().map(f));
        let mut histogram = vec![0u64; first.map_or(0, |r| r.mip_histogram.len())];
        for r in records {
            for (a, b) in histogram.iter_mut().zip(&r.mip_histogram) {
                *a += b;
            }
        }
        let total_rays = records.iter().map(|r| r.rays).sum();
        let total_render_ms: f64 = records.iter().map(|r| r.render_ms).sum();
        Summary {
            frames: records.len(),
            width: first.map_or(0, |r| r.width),
            height: first.map_or(0, |r| r.height),
            lod_method: first.map_or(String::new(), |r| r.lod_method.clone()),
            total_rays,
            total_render_ms,
            total_ms: records.iter().map(|r| r.total_ms).sum(),
            total_lod_recomputed: records.iter().map(|r| r.lod_recomputed as u64).sum(),
            total_nonfinite_samples: records.iter().map(|r| r.nonfinite_samples).sum(),
            mip_histogram: histogram,
            triangles: spread(|r| r.triangles as f64),
            animate_ms: spread(|r| r.animate_ms),
            build_ms: spread(|r| r.build_ms),
            lod_update_ms: spread(|r| r.lod_update_ms),
            lod_recomputed: spread(|r| r.lod_recomputed as f64),
            render_ms: spread(|r| r.render_ms),
            frame_total_ms: spread(|r| r.total_ms),
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
    fn median_of_even_and_odd_counts() {
        assert_eq!(Spread::of([3.0, 1.0, 2.0]).median, 2.0);
        assert_eq!(Spread::of([4.0, 1.0, 2.0, 3.0]).median, 2.5);
        let s = Spread::of([f64::NAN, 5.0]);
        assert_eq!((s.min, s.median, s.max), (5.0, 5.0, 5.0));
    }

    #[test]
    fn frame_names_are_zero_padded() {
        assert_eq!(frame_file_name(7, FrameFormat::Png), "frame_0007.png");
        assert_eq!(frame_file_name(12345, FrameFormat::Exr), "frame_12345.exr");
    }
}
