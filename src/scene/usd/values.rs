//! Reading composed attribute values: `sdf::Value` to glam types, default values and time
//! samples (times converted from time codes to seconds), every number checked finite.
//!
//! Every function that can fail returns a message naming the attribute (`/Prim.attr`), which
//! the loader prefixes with the file.

use glam::{DMat4, DQuat, DVec3, Quat, Vec2, Vec3};
use openusd::sdf::Value;
use openusd::usd::{Prim, Stage};

/// Reads attribute values of one stage, converting time codes to seconds.
pub(super) struct Reader<'s> {
    pub stage: &'s Stage,
    /// `timeCodesPerSecond` (> 0, finite).
    pub time_codes_per_second: f64,
}

/// One attribute's time samples: times in seconds (strictly increasing, finite) and values.
pub(super) struct Samples {
    pub times: Vec<f32>,
    pub values: Vec<Value>,
}

impl Reader<'_> {
    /// The attribute's composed default value (`None` when unauthored or blocked).
    pub fn default_value(&self, prim: &Prim, name: &str) -> Result<Option<Value>, String> {
        let attr = attribute(prim, name)?;
        match attr.get::<Value>() {
            Ok(Some(Value::ValueBlock | Value::None)) | Ok(None) => Ok(None),
            Ok(Some(v)) => Ok(Some(v)),
            Err(e) => Err(format!(
                "{}: cannot read the value: {e:#}",
                attr_path(prim, name)
            )),
        }
    }

    /// The attribute's time samples in seconds (empty when it has none); blocked samples
    /// are dropped (a USD block means "no value" from that time on, which the frame loop
    /// cannot express; the caller notes nothing, as no converter writes them).
    pub fn samples(&self, prim: &Prim, name: &str) -> Result<Samples, String> {
        let attr = attribute(prim, name)?;
        let what = || attr_path(prim, name);
        let raw = attr
            .time_samples()
            .map_err(|e| format!("{}: cannot read its time samples: {e:#}", what()))?
            .unwrap_or_default();
        // The stage retimes samples through layer offsets; take its times when they line up.
        let retimed = attr.time_sample_times().unwrap_or_default();
        let use_retimed = retimed.len() == raw.len();
        let mut times = Vec::with_capacity(raw.len());
        let mut values = Vec::with_capacity(raw.len());
        for (k, (time, value)) in raw.into_iter().enumerate() {
            if matches!(value, Value::ValueBlock | Value::None) {
                continue;
            }
            let code = if use_retimed { retimed[k] } else { time };
            let seconds = (code / self.time_codes_per_second) as f32;
            if !seconds.is_finite() {
                return Err(format!(
                    "{}: time sample at time code {code} is not finite",
                    what()
                ));
            }
            if times.last().is_some_and(|&last| seconds <= last) {
                // Two time codes closer than an f32 second can tell apart: keep the later.
                times.pop();
                values.pop();
            }
            times.push(seconds);
            values.push(value);
        }
        Ok(Samples { times, values })
    }

    /// How many time samples the attribute has (their values are not read).
    pub fn sample_count(&self, prim: &Prim, name: &str) -> Result<usize, String> {
        attribute(prim, name)?.num_time_samples().map_err(|e| {
            format!(
                "{}: cannot read its time samples: {e:#}",
                attr_path(prim, name)
            )
        })
    }

    /// Whether the attribute has an opinion (a default or time samples).
    pub fn has_value(&self, prim: &Prim, name: &str) -> Result<bool, String> {
        Ok(self.sample_count(prim, name)? > 0 || self.default_value(prim, name)?.is_some())
    }

    /// The value used for a static read of a possibly animated attribute: the first time
    /// sample when there are samples (USD: samples win over the default at every time), else
    /// the default. Only that one value is read.
    pub fn static_value(&self, prim: &Prim, name: &str) -> Result<Option<Value>, String> {
        let attr = attribute(prim, name)?;
        let times = attr.time_sample_times().map_err(|e| {
            format!(
                "{}: cannot read its time samples: {e:#}",
                attr_path(prim, name)
            )
        })?;
        let Some(&first) = times.first() else {
            return self.default_value(prim, name);
        };
        match attr.get_at::<Value>(openusd::usd::TimeCode::new(first)) {
            Ok(Some(Value::ValueBlock | Value::None)) | Ok(None) => Ok(None),
            Ok(Some(v)) => Ok(Some(v)),
            Err(e) => Err(format!(
                "{}: cannot read the value: {e:#}",
                attr_path(prim, name)
            )),
        }
    }

    /// A token metadata field of an attribute (e.g. `interpolation`).
    pub fn attr_token_metadata(&self, prim: &Prim, name: &str, key: &str) -> Option<String> {
        attribute(prim, name)
            .ok()?
            .get_metadata::<Value>(key)
            .ok()
            .flatten()
            .and_then(|v| token(&v))
    }

    /// An integer metadata field of an attribute (e.g. `elementSize`).
    pub fn attr_int_metadata(&self, prim: &Prim, name: &str, key: &str) -> Option<i64> {
        attribute(prim, name)
            .ok()?
            .get_metadata::<Value>(key)
            .ok()
            .flatten()
            .and_then(|v| scalar(&v))
            .map(|x| x as i64)
    }

    /// The targets of a relationship (empty when unauthored): paths as the file writes
    /// them, each checked with [`walkable_path`] before anything looks it up.
    pub fn targets(&self, prim: &Prim, name: &str) -> Result<Vec<openusd::sdf::Path>, String> {
        check_property_name(prim, name)?;
        let targets = prim
            .relationship(name)
            .targets()
            .map_err(|e| format!("{}: cannot read its targets: {e:#}", attr_path(prim, name)))?;
        for target in &targets {
            walkable_path(target).map_err(|e| format!("{}: {e}", attr_path(prim, name)))?;
        }
        Ok(targets)
    }
}

/// Attribute `name` of `prim`, once `name` is known to name a property
/// ([`check_property_name`]).
pub(super) fn attribute(prim: &Prim, name: &str) -> Result<openusd::usd::Attribute, String> {
    check_property_name(prim, name)?;
    Ok(prim.attribute(name))
}

/// An error unless `name` is a property name as USD spells them: identifiers (a letter or
/// `_`, then letters, digits and `_`) joined by `:`. Names read from a file's values (an
/// `xformOpOrder` entry is a token, any string) can hold anything, and `openusd` walks
/// the ancestors of the path it makes from one: a `}` in the name made that walk return
/// the same path forever (a hang found by fuzzing).
pub(super) fn check_property_name(prim: &Prim, name: &str) -> Result<(), String> {
    if is_property_name(name) {
        return Ok(());
    }
    Err(format!(
        "{}: '{}' is not a property name (identifiers joined by ':')",
        prim.path().as_str(),
        name.escape_debug()
    ))
}

/// Whether `name` is identifiers joined by `:` (see [`check_property_name`]).
pub(super) fn is_property_name(name: &str) -> bool {
    !name.is_empty() && name.split(':').all(openusd::sdf::Path::is_valid_identifier)
}

/// An error unless every step up `path`'s ancestors, as `openusd` takes them, gives a
/// shorter path, so that a lookup of `path` (which walks them) ends. Paths in a text
/// layer are written between `<` and `>` and taken as written; one with a `}` and no
/// `{`, for example, is its own parent.
pub(super) fn walkable_path(path: &openusd::sdf::Path) -> Result<(), String> {
    let mut at = path.clone();
    while let Some(parent) = at.parent() {
        if parent.as_str().len() >= at.as_str().len() {
            return Err(format!(
                "the path <{}> is not a USD path",
                path.as_str().escape_debug()
            ));
        }
        at = parent;
    }
    Ok(())
}

/// `/Prim.attr`, for messages.
pub(super) fn attr_path(prim: &Prim, name: &str) -> String {
    format!("{}.{name}", prim.path().as_str())
}

pub(super) fn scalar(v: &Value) -> Option<f64> {
    Some(match v {
        Value::Double(x) => *x,
        Value::Float(x) => *x as f64,
        Value::Half(x) => x.to_f32() as f64,
        Value::Int(x) => *x as f64,
        Value::Int64(x) => *x as f64,
        Value::Uint(x) => *x as f64,
        Value::Uint64(x) => *x as f64,
        Value::Uchar(x) => *x as f64,
        Value::Bool(x) => f64::from(u8::from(*x)),
        _ => return None,
    })
}

pub(super) fn vec2(v: &Value) -> Option<Vec2> {
    Some(match v {
        Value::Vec2f(a) => Vec2::new(a.x, a.y),
        Value::Vec2d(a) => Vec2::new(a.x as f32, a.y as f32),
        Value::Vec2h(a) => Vec2::new(a.x.to_f32(), a.y.to_f32()),
        _ => return None,
    })
}

pub(super) fn dvec3(v: &Value) -> Option<DVec3> {
    Some(match v {
        Value::Vec3f(a) => DVec3::new(a.x as f64, a.y as f64, a.z as f64),
        Value::Vec3d(a) => DVec3::new(a.x, a.y, a.z),
        Value::Vec3h(a) => DVec3::new(
            a.x.to_f32() as f64,
            a.y.to_f32() as f64,
            a.z.to_f32() as f64,
        ),
        _ => return None,
    })
}

pub(super) fn vec3(v: &Value) -> Option<Vec3> {
    dvec3(v).map(|d| d.as_vec3())
}

/// A colour or vector with 3 or 4 components (the first three kept).
pub(super) fn vec3_or_4(v: &Value) -> Option<Vec3> {
    Some(match v {
        Value::Vec4f(a) => Vec3::new(a.x, a.y, a.z),
        Value::Vec4d(a) => Vec3::new(a.x as f32, a.y as f32, a.z as f32),
        Value::Vec4h(a) => Vec3::new(a.x.to_f32(), a.y.to_f32(), a.z.to_f32()),
        other => return vec3(other),
    })
}

/// A 4-component value (`float4` scale/bias).
pub(super) fn vec4(v: &Value) -> Option<[f32; 4]> {
    Some(match v {
        Value::Vec4f(a) => [a.x, a.y, a.z, a.w],
        Value::Vec4d(a) => [a.x as f32, a.y as f32, a.z as f32, a.w as f32],
        Value::Vec4h(a) => [a.x.to_f32(), a.y.to_f32(), a.z.to_f32(), a.w.to_f32()],
        _ => return None,
    })
}

/// A quaternion stored `(w, x, y, z)` as USD does, in f64.
pub(super) fn dquat(v: &Value) -> Option<DQuat> {
    Some(match v {
        Value::Quatf(q) => DQuat::from_xyzw(q.x as f64, q.y as f64, q.z as f64, q.w as f64),
        Value::Quatd(q) => {
            let [w, x, y, z] = <[f64; 4]>::from(*q);
            DQuat::from_xyzw(x, y, z, w)
        }
        Value::Quath(q) => DQuat::from_xyzw(
            q.x.to_f32() as f64,
            q.y.to_f32() as f64,
            q.z.to_f32() as f64,
            q.w.to_f32() as f64,
        ),
        _ => return None,
    })
}

/// A USD `matrix4d` (row-major, row vectors: translation in the last row) as the equivalent
/// column-vector glam matrix (its transpose, which is the same 16 numbers read by columns).
pub(super) fn dmat4(v: &Value) -> Option<DMat4> {
    match v {
        Value::Matrix4d(m) => Some(DMat4::from_cols_array(&m.0)),
        _ => None,
    }
}

pub(super) fn dmat4s(v: &Value) -> Option<Vec<DMat4>> {
    match v {
        Value::Matrix4dVec(ms) => Some(ms.iter().map(|m| DMat4::from_cols_array(&m.0)).collect()),
        _ => None,
    }
}

pub(super) fn floats(v: &Value) -> Option<Vec<f32>> {
    Some(match v {
        Value::FloatVec(a) => a.clone(),
        Value::DoubleVec(a) => a.iter().map(|&x| x as f32).collect(),
        Value::HalfVec(a) => a.iter().map(|x| x.to_f32()).collect(),
        _ => return None,
    })
}

pub(super) fn ints(v: &Value) -> Option<Vec<i64>> {
    Some(match v {
        Value::IntVec(a) => a.iter().map(|&x| x as i64).collect(),
        Value::Int64Vec(a) => a.clone(),
        Value::UintVec(a) => a.iter().map(|&x| x as i64).collect(),
        Value::Uint64Vec(a) => a.iter().map(|&x| x.min(i64::MAX as u64) as i64).collect(),
        Value::UcharVec(a) => a.iter().map(|&x| x as i64).collect(),
        _ => return None,
    })
}

pub(super) fn vec2s(v: &Value) -> Option<Vec<Vec2>> {
    Some(match v {
        Value::Vec2fVec(a) => a.iter().map(|p| Vec2::new(p.x, p.y)).collect(),
        Value::Vec2dVec(a) => a
            .iter()
            .map(|p| Vec2::new(p.x as f32, p.y as f32))
            .collect(),
        Value::Vec2hVec(a) => a
            .iter()
            .map(|p| Vec2::new(p.x.to_f32(), p.y.to_f32()))
            .collect(),
        _ => return None,
    })
}

pub(super) fn vec3s(v: &Value) -> Option<Vec<Vec3>> {
    Some(match v {
        Value::Vec3fVec(a) => a.iter().map(|p| Vec3::new(p.x, p.y, p.z)).collect(),
        Value::Vec3dVec(a) => a
            .iter()
            .map(|p| Vec3::new(p.x as f32, p.y as f32, p.z as f32))
            .collect(),
        Value::Vec3hVec(a) => a
            .iter()
            .map(|p| Vec3::new(p.x.to_f32(), p.y.to_f32(), p.z.to_f32()))
            .collect(),
        _ => return None,
    })
}

/// Colours given as 3 or 4 components per element (RGB kept).
pub(super) fn colors(v: &Value) -> Option<Vec<Vec3>> {
    Some(match v {
        Value::Vec4fVec(a) => a.iter().map(|p| Vec3::new(p.x, p.y, p.z)).collect(),
        other => return vec3s(other),
    })
}

pub(super) fn quats(v: &Value) -> Option<Vec<Quat>> {
    Some(match v {
        Value::QuatfVec(a) => a
            .iter()
            .map(|q| Quat::from_xyzw(q.x, q.y, q.z, q.w))
            .collect(),
        Value::QuatdVec(a) => a
            .iter()
            .map(|q| {
                let [w, x, y, z] = <[f64; 4]>::from(*q);
                Quat::from_xyzw(x as f32, y as f32, z as f32, w as f32)
            })
            .collect(),
        Value::QuathVec(a) => a
            .iter()
            .map(|q| Quat::from_xyzw(q.x.to_f32(), q.y.to_f32(), q.z.to_f32(), q.w.to_f32()))
            .collect(),
        _ => return None,
    })
}

pub(super) fn token(v: &Value) -> Option<String> {
    match v {
        Value::Token(t) => Some(t.as_str().to_string()),
        Value::String(s) => Some(s.clone()),
        _ => None,
    }
}

pub(super) fn tokens(v: &Value) -> Option<Vec<String>> {
    match v {
        Value::TokenVec(t) => Some(t.iter().map(|t| t.as_str().to_string()).collect()),
        Value::StringVec(s) => Some(s.clone()),
        Value::TokenListOp(op) => Some(
            op.flatten()
                .into_iter()
                .map(|t| t.as_str().to_string())
                .collect(),
        ),
        _ => None,
    }
}

/// A short name of a value's type for messages (`Vec3fVec`, `Float`, ...).
pub(super) fn kind(v: &Value) -> String {
    let debug = format!("{v:?}");
    debug
        .split(|c: char| !c.is_alphanumeric())
        .next()
        .unwrap_or("value")
        .to_string()
}

/// The index of the first non-finite vector, if any.
pub(super) fn first_nonfinite(values: &[Vec3]) -> Option<usize> {
    values.iter().position(|v| !v.is_finite())
}

/// The property part of a property path (`/A/B.outputs:rgb` -> `outputs:rgb`).
pub(super) fn property_name(path: &openusd::sdf::Path) -> &str {
    let full = path.as_str();
    let prim = path.prim_path();
    full.get(prim.as_str().len() + 1..).unwrap_or("")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_whose_ancestor_walk_would_not_end_are_refused() {
        let path = |s: &str| openusd::sdf::Path::new(s).unwrap();
        for good in [
            "/",
            "/A",
            "/A/B.xformOp:translate",
            "/A{v=s}B.attr",
            "/Mat/Tex.outputs:rgb",
        ] {
            assert_eq!(walkable_path(&path(good)), Ok(()), "{good}");
        }
        for bad in [
            "/Ma}t",
            "/Mat/Sh}.outputs:surface",
            "/A.xformOp:transl}ate",
            "/A}/B",
        ] {
            let error = walkable_path(&path(bad)).expect_err(bad);
            assert!(error.contains(&format!("<{bad}>")), "{error}");
        }
    }
}
