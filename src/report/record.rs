//! One line of `stats.jsonl`, read tolerantly.
//!
//! Every field but `frame` is optional: records written before a field existed load with
//! that field `None` (absent), never 0, so the report does not invent data. `null` (how
//! serde_json writes a NaN) is absent too. Unknown fields are ignored, so newer files load.
//! A field of the wrong type is an error that names the field.

use serde_json::{Map, Value};

/// One frame's record as read back from a stats file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Record {
    pub frame: u32,
    pub time_s: Option<f64>,
    pub width: Option<u32>,
    pub height: Option<u32>,
    pub lod_method: Option<String>,
    pub triangles: Option<u64>,
    pub lights: Option<u64>,
    pub spp: Option<u32>,
    pub animate_ms: Option<f64>,
    pub dirty_ms: Option<f64>,
    pub refit_ms: Option<f64>,
    pub build_ms: Option<f64>,
    /// Whether the BVH was rebuilt (rather than refitted) this frame.
    pub rebuild: Option<bool>,
    pub sah_ratio: Option<f64>,
    pub lod_update_ms: Option<f64>,
    pub moved_triangles: Option<u64>,
    pub deformed_triangles: Option<u64>,
    pub lod_recomputed: Option<u64>,
    pub render_ms: Option<f64>,
    pub total_ms: Option<f64>,
    pub rays: Option<u64>,
    pub mip_histogram: Option<Vec<u64>>,
    pub nonfinite_samples: Option<u64>,
}

impl Record {
    /// Parses one non-blank line. The error is a message without file or line (the
    /// caller adds them): invalid JSON, not an object, no integer `frame`, a field of the
    /// wrong type.
    pub fn parse(line: &str) -> Result<Record, RecordError> {
        let value: Value = serde_json::from_str(line).map_err(RecordError::Json)?;
        let Some(o) = value.as_object() else {
            return Err(RecordError::Invalid("not a JSON object".into()));
        };
        Record::from_object(o).map_err(RecordError::Invalid)
    }

    fn from_object(o: &Map<String, Value>) -> Result<Record, String> {
        let frame = integer(o, "frame")?.ok_or("missing `frame`")?;
        Ok(Record {
            frame,
            time_s: number(o, "time_s")?,
            width: integer(o, "width")?,
            height: integer(o, "height")?,
            lod_method: string(o, "lod_method")?,
            triangles: integer(o, "triangles")?,
            lights: integer(o, "lights")?,
            spp: integer(o, "spp")?,
            animate_ms: number(o, "animate_ms")?,
            dirty_ms: number(o, "dirty_ms")?,
            refit_ms: number(o, "refit_ms")?,
            build_ms: number(o, "build_ms")?,
            rebuild: boolean(o, "rebuild")?,
            sah_ratio: number(o, "sah_ratio")?,
            lod_update_ms: number(o, "lod_update_ms")?,
            moved_triangles: integer(o, "moved_triangles")?,
            deformed_triangles: integer(o, "deformed_triangles")?,
            lod_recomputed: integer(o, "lod_recomputed")?,
            render_ms: number(o, "render_ms")?,
            total_ms: number(o, "total_ms")?,
            rays: integer(o, "rays")?,
            mip_histogram: counts(o, "mip_histogram")?,
            nonfinite_samples: integer(o, "nonfinite_samples")?,
        })
    }
}

/// The field's value, `None` when missing or `null`.
fn field<'a>(o: &'a Map<String, Value>, name: &str) -> Option<&'a Value> {
    o.get(name).filter(|v| !v.is_null())
}

fn wrong_type(name: &str, value: &Value, expected: &str) -> String {
    format!("`{name}` is {value}, expected {expected}")
}

fn number(o: &Map<String, Value>, name: &str) -> Result<Option<f64>, String> {
    field(o, name)
        .map(|v| v.as_f64().ok_or_else(|| wrong_type(name, v, "a number")))
        .transpose()
}

fn integer<T: TryFrom<u64>>(o: &Map<String, Value>, name: &str) -> Result<Option<T>, String> {
    field(o, name)
        .map(|v| {
            v.as_u64()
                .and_then(|u| T::try_from(u).ok())
                .ok_or_else(|| wrong_type(name, v, "a non-negative integer in range"))
        })
        .transpose()
}

fn boolean(o: &Map<String, Value>, name: &str) -> Result<Option<bool>, String> {
    field(o, name)
        .map(|v| {
            v.as_bool()
                .ok_or_else(|| wrong_type(name, v, "true or false"))
        })
        .transpose()
}

fn string(o: &Map<String, Value>, name: &str) -> Result<Option<String>, String> {
    field(o, name)
        .map(|v| {
            v.as_str()
                .map(str::to_owned)
                .ok_or_else(|| wrong_type(name, v, "a string"))
        })
        .transpose()
}

fn counts(o: &Map<String, Value>, name: &str) -> Result<Option<Vec<u64>>, String> {
    let expected = "an array of non-negative integers";
    field(o, name)
        .map(|v| {
            let items = v.as_array().ok_or_else(|| wrong_type(name, v, expected))?;
            items
                .iter()
                .map(|c| c.as_u64().ok_or_else(|| wrong_type(name, v, expected)))
                .collect()
        })
        .transpose()
}

/// Why a line is not a record.
#[derive(Debug)]
pub enum RecordError {
    Json(serde_json::Error),
    Invalid(String),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn current_format_loads_every_field() {
        let line = r#"{"frame":2,"time_s":0.5,"width":64,"height":32,"lod_method":"paper",
            "triangles":100,"lights":2,"spp":4,"animate_ms":1.0,"dirty_ms":0.25,"refit_ms":0.5,
            "build_ms":0.0,"rebuild":false,"sah_ratio":1.1,"lod_update_ms":0.75,
            "moved_triangles":10,"deformed_triangles":5,"lod_recomputed":15,"render_ms":20.0,
            "total_ms":23.0,"rays":4096,"mip_histogram":[1,2,3],"nonfinite_samples":0}"#;
        let r = Record::parse(line).unwrap();
        assert_eq!(r.lod_method.as_deref(), Some("paper"));
        assert_eq!((r.width, r.height, r.spp), (Some(64), Some(32), Some(4)));
        assert_eq!(
            (r.dirty_ms, r.refit_ms, r.rebuild),
            (Some(0.25), Some(0.5), Some(false))
        );
        assert_eq!(
            (r.moved_triangles, r.deformed_triangles),
            (Some(10), Some(5))
        );
        assert_eq!(r.mip_histogram, Some(vec![1, 2, 3]));
        assert_eq!((r.rays, r.nonfinite_samples), (Some(4096), Some(0)));
    }

    #[test]
    fn missing_fields_are_absent() {
        let r = Record::parse(r#"{"frame": 3, "render_ms": 2.5, "future_field": [1]}"#).unwrap();
        assert_eq!(r.frame, 3);
        assert_eq!(r.render_ms, Some(2.5));
        assert_eq!(r.dirty_ms, None);
        assert_eq!(r.rebuild, None);
    }

    #[test]
    fn null_is_absent() {
        // serde_json writes a NaN f64 as null.
        let r = Record::parse(r#"{"frame": 0, "total_ms": null}"#).unwrap();
        assert_eq!(r.total_ms, None);
    }

    #[test]
    fn frame_is_required_and_integral() {
        for line in [
            r#"{"render_ms": 1}"#,
            r#"{"frame": null}"#,
            r#"{"frame": -1}"#,
            r#"{"frame": 1.5}"#,
            r#"{"frame": "2"}"#,
            "[1, 2]",
        ] {
            assert!(
                matches!(Record::parse(line), Err(RecordError::Invalid(_))),
                "{line}"
            );
        }
        assert!(matches!(
            Record::parse("{\"frame\": 1"),
            Err(RecordError::Json(_))
        ));
    }

    #[test]
    fn wrong_type_names_the_field() {
        let Err(RecordError::Invalid(message)) = Record::parse(r#"{"frame": 1, "rebuild": 3}"#)
        else {
            panic!("expected an error");
        };
        assert_eq!(message, "`rebuild` is 3, expected true or false");
    }
}
