//! The ray file (`rays_NNNN.bin`): every ray a real frame traces, so that any tracer can
//! trace exactly mipray's rays and compare its answers (`mipray export --rays`), and
//! `mipray bench --rays FILE` can time mipray's own kernels class by class.
//!
//! Layout, little-endian: 8 bytes magic `MIPRAYS1`, `u64` count `N`, then `N` records of 48
//! bytes:
//!
//! | offset | field | type |
//! |---:|---|---|
//! | 0 | origin x y z | 3 x f32 |
//! | 12 | direction x y z, as traced (not renormalised) | 3 x f32 |
//! | 24 | t min | f32 |
//! | 28 | t max (infinity for closest-hit rays) | f32 |
//! | 32 | class: 0 primary, 1 shadow, 2 reflection, 3 refraction | u32 |
//! | 36 | pixel index, `y * width + x`, of the sample that spawned the ray | u32 |
//! | 40 | result: closest hit, the triangle's index in the face order of the frame's OBJ export (whatever `--format` wrote beside it) (`0xFFFFFFFF` for a miss); shadow, 1 blocked (any surface in `[t min, t max)`), 0 clear | u32 |
//! | 44 | hit distance (NaN where there is none) | f32 |
//!
//! Records follow the film's order: tile by tile (32 x 32 pixels, row-major tiles), within a
//! tile the order it traced them, bounce by bounce: the bounce's closest-hit rays (first the
//! primary rays, the tile's pixels in Morton order), then the shadow rays of their hits,
//! light by light.

use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};

use glam::{Vec3, Vec3A};

use crate::render::{RayAnswer, RayClass, TracedRay};

/// The first eight bytes of a ray file.
pub const MAGIC: &[u8; 8] = b"MIPRAYS1";
/// Bytes per record.
pub const RECORD_BYTES: usize = 48;
/// The `result` of a closest-hit ray that hit nothing.
pub const MISS: u32 = u32::MAX;

/// One record of a ray file, laid out in memory as in the file (48 bytes, `repr(C)`).
///
/// Why this layout: `mipray bench --rays` traces from these records inside its clock, as
/// Embree's anchor traces from the file's 48-byte records inside its own. With 16-byte
/// `Vec3A` fields a record would take 64 bytes, a cache line a ray, and the bench would
/// read a third more memory per ray than the anchor it is compared with.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C)]
pub struct RayRecord {
    pub origin: Vec3,
    pub direction: Vec3,
    pub t_min: f32,
    pub t_max: f32,
    pub class: RayClass,
    pub pixel: u32,
    /// Closest hit: face index or [`MISS`]; shadow: 1 blocked, 0 clear.
    pub result: u32,
    /// Hit distance, NaN where there is none.
    pub t: f32,
}

const _: () = assert!(std::mem::size_of::<RayRecord>() == RECORD_BYTES);

impl RayRecord {
    /// The ray's origin and direction as the kernels take them (widened to `Vec3A`).
    #[inline]
    pub fn origin_direction(&self) -> (Vec3A, Vec3A) {
        (self.origin.into(), self.direction.into())
    }

    /// The record of a traced ray; `face_of_slot` maps a slot of the frame's triangles to
    /// its face index in the exported mesh.
    ///
    /// # Panics
    /// If a hit names a slot `face_of_slot` does not cover (the log and the mesh are of
    /// different frames).
    pub fn of(ray: &TracedRay, face_of_slot: &[u32]) -> RayRecord {
        let (result, t) = match ray.answer {
            RayAnswer::Closest(Some((triangle, t))) => (face_of_slot[triangle.slot as usize], t),
            RayAnswer::Closest(None) => (MISS, f32::NAN),
            RayAnswer::Blocked(blocked) => (blocked as u32, f32::NAN),
        };
        RayRecord {
            origin: ray.origin.into(),
            direction: ray.direction.into(),
            t_min: ray.t_min,
            t_max: ray.t_max,
            class: ray.class,
            pixel: ray.pixel,
            result,
            t,
        }
    }

    fn to_bytes(self) -> [u8; RECORD_BYTES] {
        let mut b = [0u8; RECORD_BYTES];
        let words: [u32; 12] = [
            self.origin.x.to_bits(),
            self.origin.y.to_bits(),
            self.origin.z.to_bits(),
            self.direction.x.to_bits(),
            self.direction.y.to_bits(),
            self.direction.z.to_bits(),
            self.t_min.to_bits(),
            self.t_max.to_bits(),
            self.class as u32,
            self.pixel,
            self.result,
            self.t.to_bits(),
        ];
        for (chunk, w) in b.chunks_exact_mut(4).zip(words) {
            chunk.copy_from_slice(&w.to_le_bytes());
        }
        b
    }

    /// The record in `b`, checked for what no traced ray can be: a non-finite origin, a
    /// direction that is not finite or is zero, a `t min` that is negative or NaN, a
    /// `t max` below it or NaN, an unknown class, a shadow result other than 0 or 1.
    fn from_bytes(b: &[u8; RECORD_BYTES]) -> Result<RayRecord, String> {
        let w = |i: usize| u32::from_le_bytes([b[4 * i], b[4 * i + 1], b[4 * i + 2], b[4 * i + 3]]);
        let f = |i: usize| f32::from_bits(w(i));
        let class =
            RayClass::from_u32(w(8)).ok_or_else(|| format!("class {} is not 0..=3", w(8)))?;
        let record = RayRecord {
            origin: Vec3::new(f(0), f(1), f(2)),
            direction: Vec3::new(f(3), f(4), f(5)),
            t_min: f(6),
            t_max: f(7),
            class,
            pixel: w(9),
            result: w(10),
            t: f(11),
        };
        if !record.origin.is_finite() {
            return Err(format!("origin {} is not finite", record.origin));
        }
        if !record.direction.is_finite() || record.direction == Vec3::ZERO {
            return Err(format!(
                "direction {} is not a finite non-zero vector",
                record.direction
            ));
        }
        if !(record.t_min >= 0.0) {
            return Err(format!(
                "t min {} is not a distance of 0 or more",
                record.t_min
            ));
        }
        if !(record.t_max >= record.t_min) {
            return Err(format!(
                "t max {} is not at least t min {}",
                record.t_max, record.t_min
            ));
        }
        if class == RayClass::Shadow && record.result > 1 {
            return Err(format!(
                "a shadow ray's result is 1 (blocked) or 0 (clear), not {}",
                record.result
            ));
        }
        Ok(record)
    }
}

/// An error reading a ray file, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum RayFileError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: io::Error },
    #[error("{path}: not a mipray ray file (the first 8 bytes are not MIPRAYS1)")]
    Magic { path: PathBuf },
    #[error("{path}: {actual} bytes, shorter than a ray file's 16-byte header")]
    Header { path: PathBuf, actual: u64 },
    #[error(
        "{path}: the header says {count} records ({needed} bytes) but the file has {actual} bytes"
    )]
    Length {
        path: PathBuf,
        count: u64,
        needed: u128,
        actual: u64,
    },
    #[error("{path}: {count} records, more than this process can hold in memory ({cause})")]
    Memory {
        path: PathBuf,
        count: u64,
        cause: std::collections::TryReserveError,
    },
    #[error("{path}: record {index}: {problem}")]
    Record {
        path: PathBuf,
        index: u64,
        problem: String,
    },
}

/// Writes `records` as a ray file to `out`.
pub fn write_records(out: &mut impl Write, records: &[RayRecord]) -> io::Result<()> {
    out.write_all(MAGIC)?;
    out.write_all(&(records.len() as u64).to_le_bytes())?;
    for r in records {
        out.write_all(&r.to_bytes())?;
    }
    Ok(())
}

/// Reads a whole ray file. The header's count is checked against the file's length before
/// anything is allocated, so a damaged header cannot ask for gigabytes.
///
/// # Errors
/// The file cannot be read, is not a ray file, its length disagrees with its count, its
/// records are more than this process can allocate, or a record holds what no traced ray
/// can (see `RayRecord::from_bytes`).
pub fn read_ray_file(path: &Path) -> Result<Vec<RayRecord>, RayFileError> {
    let io_err = |source| RayFileError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut file = std::fs::File::open(path).map_err(io_err)?;
    let actual = file.metadata().map_err(io_err)?.len();
    let mut header = [0u8; 16];
    if actual < 8 || file.read_exact(&mut header[..8]).is_err() || &header[..8] != MAGIC {
        return Err(RayFileError::Magic {
            path: path.to_path_buf(),
        });
    }
    if actual < 16 {
        return Err(RayFileError::Header {
            path: path.to_path_buf(),
            actual,
        });
    }
    file.read_exact(&mut header[8..]).map_err(io_err)?;
    let count = u64::from_le_bytes(header[8..16].try_into().expect("8 bytes"));
    let needed = 16 + count as u128 * RECORD_BYTES as u128;
    if needed != actual as u128 {
        return Err(RayFileError::Length {
            path: path.to_path_buf(),
            count,
            needed,
            actual,
        });
    }
    // The file's bytes and its records are held at once: both are asked for before reading,
    // so a file larger than the process may hold is an error, not an abort.
    let too_large = |cause| RayFileError::Memory {
        path: path.to_path_buf(),
        count,
        cause,
    };
    let mut bytes = Vec::new();
    bytes
        .try_reserve_exact(usize::try_from(actual - 16).unwrap_or(usize::MAX))
        .map_err(too_large)?;
    let mut records = Vec::new();
    records
        .try_reserve_exact(usize::try_from(count).unwrap_or(usize::MAX))
        .map_err(too_large)?;
    file.read_to_end(&mut bytes).map_err(io_err)?;
    for (index, chunk) in bytes.chunks_exact(RECORD_BYTES).enumerate() {
        let record =
            RayRecord::from_bytes(chunk.try_into().expect("48 bytes")).map_err(|problem| {
                RayFileError::Record {
                    path: path.to_path_buf(),
                    index: index as u64,
                    problem,
                }
            })?;
        records.push(record);
    }
    Ok(records)
}

/// File name of frame `index`'s rays: `rays_0000.bin`.
pub fn ray_file_name(index: u32) -> String {
    format!("rays_{index:04}.bin")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::TriangleRef;

    fn record(class: RayClass, result: u32, t: f32) -> RayRecord {
        RayRecord {
            origin: Vec3::new(1.0, -2.5, 3.0e7),
            direction: Vec3::new(0.0, -0.0, 1.0),
            t_min: 0.0,
            t_max: f32::INFINITY,
            class,
            pixel: 1234,
            result,
            t,
        }
    }

    #[test]
    fn records_round_trip_bit_for_bit_at_48_bytes_each() {
        let records = vec![
            record(RayClass::Primary, 7, 2.5),
            record(RayClass::Shadow, 1, f32::NAN),
            record(RayClass::Reflection, MISS, f32::NAN),
            record(RayClass::Refraction, 0, 1e-30),
        ];
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(ray_file_name(3));
        let mut bytes = Vec::new();
        write_records(&mut bytes, &records).unwrap();
        assert_eq!(bytes.len(), 16 + 4 * RECORD_BYTES);
        assert_eq!(&bytes[..8], b"MIPRAYS1");
        assert_eq!(u64::from_le_bytes(bytes[8..16].try_into().unwrap()), 4);
        // class and result of the first record at their documented offsets
        assert_eq!(
            u32::from_le_bytes(bytes[16 + 32..16 + 36].try_into().unwrap()),
            0
        );
        assert_eq!(
            u32::from_le_bytes(bytes[16 + 40..16 + 44].try_into().unwrap()),
            7
        );
        std::fs::write(&path, &bytes).unwrap();
        let back = read_ray_file(&path).unwrap();
        assert_eq!(back.len(), records.len());
        for (a, b) in back.iter().zip(&records) {
            assert_eq!(a.to_bytes(), b.to_bytes());
        }
    }

    #[test]
    fn damaged_files_are_named_errors_not_allocations() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.bin");
        std::fs::write(&path, b"NOTRAYS!\0\0\0\0\0\0\0\0").unwrap();
        assert!(matches!(
            read_ray_file(&path),
            Err(RayFileError::Magic { .. })
        ));
        // a header asking for 2^60 records in a 16-byte file
        let mut bytes = MAGIC.to_vec();
        bytes.extend_from_slice(&(1u64 << 60).to_le_bytes());
        std::fs::write(&path, &bytes).unwrap();
        let err = read_ray_file(&path).unwrap_err();
        assert!(matches!(err, RayFileError::Length { .. }), "{err}");
        assert!(err.to_string().contains("bad.bin"));
        // an unknown class
        let mut bytes = Vec::new();
        write_records(&mut bytes, &[record(RayClass::Primary, 0, 1.0)]).unwrap();
        bytes[16 + 32] = 9;
        std::fs::write(&path, &bytes).unwrap();
        let err = read_ray_file(&path).unwrap_err();
        assert!(err.to_string().contains("record 0: class 9"), "{err}");
        // the magic alone, or cut inside the count: a short header, not a wrong magic
        for cut in [8, 12] {
            std::fs::write(
                &path,
                &MAGIC.iter().chain(&[0u8; 8]).copied().collect::<Vec<_>>()[..cut],
            )
            .unwrap();
            let err = read_ray_file(&path).unwrap_err();
            assert!(matches!(err, RayFileError::Header { .. }), "{err}");
            assert!(err.to_string().contains("shorter than"), "{err}");
        }
        for short in [&b""[..], b"MIPR"] {
            std::fs::write(&path, short).unwrap();
            assert!(matches!(
                read_ray_file(&path),
                Err(RayFileError::Magic { .. })
            ));
        }
    }

    /// Records no traced ray can be are named errors: the bench would otherwise count them
    /// as answers that differ, or as matching.
    #[test]
    fn impossible_records_are_named_errors() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rays.bin");
        let good = record(RayClass::Primary, 0, 1.0);
        let cases: [(RayRecord, &str); 9] = [
            (
                RayRecord {
                    origin: Vec3::new(f32::NAN, 0.0, 0.0),
                    ..good
                },
                "origin",
            ),
            (
                RayRecord {
                    origin: Vec3::new(0.0, f32::INFINITY, 0.0),
                    ..good
                },
                "origin",
            ),
            (
                RayRecord {
                    direction: Vec3::ZERO,
                    ..good
                },
                "direction",
            ),
            (
                RayRecord {
                    direction: Vec3::new(0.0, f32::NAN, 1.0),
                    ..good
                },
                "direction",
            ),
            (
                RayRecord {
                    t_min: f32::NAN,
                    ..good
                },
                "t min",
            ),
            (
                RayRecord {
                    t_min: -1.0,
                    ..good
                },
                "t min",
            ),
            (
                RayRecord {
                    t_max: f32::NAN,
                    ..good
                },
                "t max",
            ),
            (
                RayRecord {
                    t_min: 2.0,
                    t_max: 1.0,
                    ..good
                },
                "t max",
            ),
            (record(RayClass::Shadow, 7, f32::NAN), "shadow ray's result"),
        ];
        for (bad, problem) in cases {
            let mut bytes = Vec::new();
            write_records(&mut bytes, &[good, bad]).unwrap();
            std::fs::write(&path, &bytes).unwrap();
            let err = read_ray_file(&path).unwrap_err().to_string();
            assert!(
                err.contains("rays.bin: record 1: ") && err.contains(problem),
                "{err}"
            );
        }
        // The edges that are allowed: t min 0 with t max 0, and an infinite t max.
        let edges = [
            RayRecord { t_max: 0.0, ..good },
            record(RayClass::Shadow, 1, f32::NAN),
            record(RayClass::Shadow, 0, f32::NAN),
        ];
        let mut bytes = Vec::new();
        write_records(&mut bytes, &edges).unwrap();
        std::fs::write(&path, &bytes).unwrap();
        assert_eq!(read_ray_file(&path).unwrap().len(), 3);
    }

    #[test]
    fn answers_map_to_face_indices_and_flags() {
        let faces = [5u32, 3, 9];
        let traced = |answer| TracedRay {
            origin: Vec3A::ZERO,
            direction: Vec3A::X,
            t_min: 0.0,
            t_max: 4.0,
            class: RayClass::Reflection,
            pixel: 0,
            answer,
        };
        let hit = RayAnswer::Closest(Some((
            TriangleRef {
                instance: u32::MAX,
                slot: 1,
            },
            2.0,
        )));
        let r = RayRecord::of(&traced(hit), &faces);
        assert_eq!((r.result, r.t), (3, 2.0));
        let r = RayRecord::of(&traced(RayAnswer::Closest(None)), &faces);
        assert!(r.result == MISS && r.t.is_nan());
        let r = RayRecord::of(&traced(RayAnswer::Blocked(true)), &faces);
        assert!(r.result == 1 && r.t.is_nan());
    }
}
