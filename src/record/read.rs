//! One line of `stats.jsonl`, read into a [`FrameRecord`]: the one parser of a line.
//!
//! Every field but `frame` is optional: records written before a field existed load with
//! that field absent (the record holds its default, and [`Record::has`] says it is not
//! there), never reported as 0, so the report does not invent data. `null` (how
//! serde_json writes a NaN) is absent too. Unknown fields are ignored by the values and
//! kept in the line ([`Record::line`]), so newer files load and the render page still shows
//! them. A field of the wrong type is an error that names the field. A reader that needs
//! more than `frame` asks [`Record::missing`].

use serde_json::{Map, Value};

use super::{FrameRecord, Settings, UpdateStats};

/// One frame's record as read back from a stats file, and which fields the line had.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Record {
    /// The line's values; a field the line lacked holds its default.
    pub values: FrameRecord,
    /// `stats.jsonl` names of the fields the line had (non-null).
    present: Vec<&'static str>,
    /// The line's JSON object as read (unknown fields included).
    line: Map<String, Value>,
}

impl Record {
    /// A record whose fields named in `present` were read (the rest count as absent).
    /// Its line is the JSON of the present fields.
    pub fn new(values: FrameRecord, present: impl IntoIterator<Item = &'static str>) -> Record {
        let present: Vec<&'static str> = present.into_iter().collect();
        let line = match serde_json::to_value(&values) {
            Ok(Value::Object(all)) => all
                .into_iter()
                .filter(|(name, _)| present.contains(&name.as_str()))
                .collect(),
            _ => Map::new(),
        };
        Record {
            values,
            present,
            line,
        }
    }

    /// Parses one non-blank line. The error is a message without file or line (the
    /// caller adds them): invalid JSON, not an object, no integer `frame`, a field of the
    /// wrong type.
    pub fn parse(line: &str) -> Result<Record, RecordError> {
        let value: Value = serde_json::from_str(line).map_err(RecordError::Json)?;
        let Value::Object(o) = value else {
            return Err(RecordError::Invalid("not a JSON object".into()));
        };
        Record::from_object(o).map_err(RecordError::Invalid)
    }

    /// The frame number (always present).
    pub fn frame(&self) -> u32 {
        self.values.frame
    }

    /// Whether the line had the field `name` (a `stats.jsonl` name).
    pub fn has(&self, name: &str) -> bool {
        self.present.contains(&name)
    }

    /// `value` when the line had the field `name`, else `None`.
    pub fn if_present<T>(&self, name: &str, value: T) -> Option<T> {
        self.has(name).then_some(value)
    }

    /// The fields of [`FrameRecord`] the line lacked, except those whose absence means
    /// their default ([`FrameRecord::DEFAULTED`]): empty for a complete record, one that
    /// can be written back unchanged.
    pub fn missing(&self) -> Vec<&'static str> {
        FrameRecord::FIELDS
            .into_iter()
            .filter(|name| !self.has(name) && !FrameRecord::DEFAULTED.contains(name))
            .collect()
    }

    /// The line's JSON object as read, unknown fields included.
    pub fn line(&self) -> &Map<String, Value> {
        &self.line
    }

    /// [`Record::line`], taken out of the record (no copy).
    pub fn into_line(self) -> Map<String, Value> {
        self.line
    }

    fn from_object(o: Map<String, Value>) -> Result<Record, String> {
        let frame = integer(&o, "frame")?.ok_or("missing `frame`")?;
        let mut f = Fields {
            o: &o,
            present: vec!["frame"],
        };
        let values = FrameRecord {
            frame,
            time_s: f.number("time_s")? as f32,
            width: f.integer("width")?,
            height: f.integer("height")?,
            lod_method: f.string("lod_method")?,
            lod_bias: f.number("lod_bias")? as f32,
            triangles: f.integer("triangles")?,
            lights: f.integer("lights")?,
            spp: f.integer("spp")?,
            bvh_layout: f.string("bvh_layout")?,
            instanced_meshes: f.integer("instanced_meshes")?,
            update: UpdateStats {
                animate_ms: f.number("animate_ms")?,
                dirty_ms: f.number("dirty_ms")?,
                refit_ms: f.number("refit_ms")?,
                build_ms: f.number("build_ms")?,
                rebuild: f.boolean("rebuild")?,
                sah_ratio: f.number("sah_ratio")? as f32,
                lod_update_ms: f.number("lod_update_ms")?,
                moved_triangles: f.integer("moved_triangles")?,
                deformed_triangles: f.integer("deformed_triangles")?,
                lod_recomputed: f.integer("lod_recomputed")?,
                lod_shifted: f.integer("lod_shifted")?,
            },
            render_ms: f.number("render_ms")?,
            total_ms: f.number("total_ms")?,
            rays: f.integer("rays")?,
            mip_histogram: f.counts("mip_histogram")?,
            nonfinite_samples: f.integer("nonfinite_samples")?,
            scene: f.string("scene")?,
            scene_files: f.string("scene_files")?,
            settings: f.settings("settings")?,
        };
        let present = f.present;
        Ok(Record {
            values,
            present,
            line: o,
        })
    }
}

/// The fields of one line, read one by one: each read returns the value (the default when
/// absent) and remembers whether it was there.
struct Fields<'a> {
    o: &'a Map<String, Value>,
    present: Vec<&'static str>,
}

impl Fields<'_> {
    fn mark<T: Default>(&mut self, name: &'static str, value: Option<T>) -> T {
        if value.is_some() {
            self.present.push(name);
        }
        value.unwrap_or_default()
    }

    fn number(&mut self, name: &'static str) -> Result<f64, String> {
        let value = number(self.o, name)?;
        Ok(self.mark(name, value))
    }

    fn integer<T: TryFrom<u64> + Default>(&mut self, name: &'static str) -> Result<T, String> {
        let value = integer(self.o, name)?;
        Ok(self.mark(name, value))
    }

    fn boolean(&mut self, name: &'static str) -> Result<bool, String> {
        let value = boolean(self.o, name)?;
        Ok(self.mark(name, value))
    }

    fn string(&mut self, name: &'static str) -> Result<String, String> {
        let value = string(self.o, name)?;
        Ok(self.mark(name, value))
    }

    fn counts(&mut self, name: &'static str) -> Result<Vec<u64>, String> {
        let value = counts(self.o, name)?;
        Ok(self.mark(name, value))
    }

    fn settings(&mut self, name: &'static str) -> Result<Settings, String> {
        let value = settings(self.o, name)?;
        Ok(self.mark(name, value))
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

/// An object whose every value is a string (a record's `settings`).
fn settings(o: &Map<String, Value>, name: &str) -> Result<Option<Settings>, String> {
    let expected = "an object of strings";
    field(o, name)
        .map(|v| {
            let entries = v.as_object().ok_or_else(|| wrong_type(name, v, expected))?;
            entries
                .iter()
                .map(|(key, value)| match value.as_str() {
                    Some(text) => Ok((key.clone(), text.to_owned())),
                    None => Err(wrong_type(name, v, expected)),
                })
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
            "lod_bias":0.5,"triangles":100,"lights":2,"spp":4,"bvh_layout":"two-level",
            "instanced_meshes":3,"animate_ms":1.0,"dirty_ms":0.25,
            "refit_ms":0.5,"build_ms":0.0,"rebuild":false,"sah_ratio":1.1,"lod_update_ms":0.75,
            "moved_triangles":10,"deformed_triangles":5,"lod_recomputed":15,"lod_shifted":3,
            "render_ms":20.0,"total_ms":23.0,"rays":4096,"mip_histogram":[1,2,3],
            "nonfinite_samples":0}"#;
        let r = Record::parse(line).unwrap();
        let v = &r.values;
        assert_eq!(v.lod_method, "paper");
        assert_eq!((v.width, v.height, v.spp, v.lod_bias), (64, 32, 4, 0.5));
        assert_eq!(
            (v.update.dirty_ms, v.update.refit_ms, v.update.rebuild),
            (0.25, 0.5, false)
        );
        assert_eq!(
            (
                v.update.moved_triangles,
                v.update.deformed_triangles,
                v.update.lod_shifted
            ),
            (10, 5, 3)
        );
        assert_eq!(v.mip_histogram, [1, 2, 3]);
        assert_eq!((v.rays, v.nonfinite_samples), (4096, 0));
        assert_eq!(
            (v.bvh_layout.as_str(), v.instanced_meshes),
            ("two-level", 3)
        );
        // Every field of the line is present, `false` and 0 included.
        let all = serde_json::to_value(FrameRecord::default()).unwrap();
        for name in all.as_object().unwrap().keys() {
            assert!(r.has(name), "{name}");
        }
    }

    #[test]
    fn written_record_reads_back_equal() {
        let mut values = FrameRecord {
            frame: 7,
            lod_method: "cones".into(),
            total_ms: 3.5,
            mip_histogram: vec![4, 5],
            scene: "s.gltf#0123456789abcdef".into(),
            settings: Settings::from([
                ("size".into(), "8x4".into()),
                ("lod".into(), "cones".into()),
            ]),
            ..FrameRecord::default()
        };
        values.update.rebuild = true;
        let line = serde_json::to_string(&values).unwrap();
        assert_eq!(Record::parse(&line).unwrap().values, values);
        // Settings are strings: anything else is an error naming the field.
        let bad = line.replace("\"8x4\"", "[8, 4]");
        let Err(RecordError::Invalid(message)) = Record::parse(&bad) else {
            panic!("expected an error: {bad}");
        };
        assert!(message.starts_with("`settings` is"), "{message}");
    }

    #[test]
    fn missing_fields_are_absent() {
        let r = Record::parse(r#"{"frame": 3, "render_ms": 2.5, "future_field": [1]}"#).unwrap();
        assert_eq!(r.frame(), 3);
        assert_eq!(r.if_present("render_ms", r.values.render_ms), Some(2.5));
        assert!(!r.has("dirty_ms"));
        assert!(!r.has("rebuild"));
        assert!(!r.has("future_field"));
    }

    #[test]
    fn a_complete_record_misses_nothing_and_keeps_its_line() {
        let mut json = serde_json::to_value(FrameRecord {
            frame: 4,
            ..FrameRecord::default()
        })
        .unwrap();
        let object = json.as_object_mut().unwrap();
        object.insert("future_field".into(), Value::from(2));
        let r = Record::parse(&json.to_string()).unwrap();
        assert!(r.missing().is_empty());
        assert_eq!(r.line()["future_field"], 2);
        // An older record without `lod_bias` is complete (it means no bias).
        json.as_object_mut().unwrap().remove("lod_bias");
        let older = Record::parse(&json.to_string()).unwrap();
        assert!(older.missing().is_empty());
        assert_eq!(older.values.lod_bias, 0.0);
        // So is one written before the layout was recorded (it reads as not recorded).
        for name in ["bvh_layout", "instanced_meshes"] {
            json.as_object_mut().unwrap().remove(name);
        }
        let unrecorded = Record::parse(&json.to_string()).unwrap();
        assert!(unrecorded.missing().is_empty());
        assert!(!unrecorded.has("bvh_layout"));
        assert_eq!(unrecorded.values.bvh_layout, "");
        json.as_object_mut().unwrap().remove("rays");
        json.as_object_mut()
            .unwrap()
            .insert("spp".into(), Value::Null);
        let partial = Record::parse(&json.to_string()).unwrap();
        assert_eq!(partial.missing(), ["spp", "rays"]);
    }

    #[test]
    fn made_records_have_the_line_of_their_present_fields() {
        let r = Record::new(
            FrameRecord {
                frame: 2,
                render_ms: 1.5,
                ..FrameRecord::default()
            },
            ["frame", "render_ms"],
        );
        assert_eq!(
            Value::Object(r.line().clone()).to_string(),
            r#"{"frame":2,"render_ms":1.5}"#
        );
    }

    #[test]
    fn null_is_absent() {
        // serde_json writes a NaN f64 as null.
        let r = Record::parse(r#"{"frame": 0, "total_ms": null}"#).unwrap();
        assert!(!r.has("total_ms"));
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
