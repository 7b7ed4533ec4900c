//! Buffer and image bytes: the GLB BIN chunk, base64 data URIs and relative files.
//!
//! Invariant after [`Buffers::load`]: buffer `i`'s data is at least its declared
//! `byteLength` long, so ranges checked against the declaration are also in the data.
//! Only relative paths (percent-decoded, resolved against the glTF file's folder) and
//! `data:` URIs are read; a loader that fetched URLs would make rendering depend on the
//! network.

use std::borrow::Cow;
use std::path::Path;

use base64::Engine as _;
use gltf::buffer::View;

/// The bytes of every buffer of a document, by buffer index.
pub(super) struct Buffers {
    data: Vec<Vec<u8>>,
}

impl Buffers {
    /// Loads every buffer. `blob` is the GLB BIN chunk, if any; `base_dir` the folder
    /// relative URIs are resolved against.
    pub(super) fn load(
        document: &gltf::Document,
        mut blob: Option<Vec<u8>>,
        base_dir: &Path,
    ) -> Result<Self, String> {
        let mut data = Vec::with_capacity(document.buffers().len());
        for buffer in document.buffers() {
            let what = format!("buffer {}", buffer.index());
            let bytes = match buffer.source() {
                gltf::buffer::Source::Bin => blob.take().ok_or_else(|| {
                    format!("{what} refers to the GLB BIN chunk, but the file has none")
                })?,
                gltf::buffer::Source::Uri(uri) => read_uri(uri, base_dir, &what)?.into_owned(),
            };
            if bytes.len() < buffer.length() {
                return Err(format!(
                    "{what}{} has {} bytes but declares byteLength {}",
                    uri_suffix(buffer.source()),
                    bytes.len(),
                    buffer.length()
                ));
            }
            data.push(bytes);
        }
        Ok(Buffers { data })
    }

    /// The whole data of buffer `index`.
    pub(super) fn bytes(&self, index: usize) -> Option<&[u8]> {
        self.data.get(index).map(Vec::as_slice)
    }

    /// The bytes of a buffer view, or an error naming the view if it does not fit its
    /// buffer.
    pub(super) fn view_bytes(&self, view: &View) -> Result<&[u8], String> {
        let buffer = view.buffer();
        let data = self.bytes(buffer.index()).unwrap_or_default();
        let range = view
            .offset()
            .checked_add(view.length())
            .map(|end| view.offset()..end)
            .filter(|range| range.end <= buffer.length());
        range.and_then(|range| data.get(range)).ok_or_else(|| {
            format!(
                "buffer view {} (bytes {}..{}) does not fit buffer {} of {} bytes",
                view.index(),
                view.offset(),
                view.offset().saturating_add(view.length()),
                buffer.index(),
                buffer.length()
            )
        })
    }
}

/// ` ('file.bin')` for a buffer read from a file, empty otherwise (for messages).
fn uri_suffix(source: gltf::buffer::Source) -> String {
    match source {
        gltf::buffer::Source::Uri(uri) if !uri.starts_with("data:") => format!(" ('{uri}')"),
        _ => String::new(),
    }
}

/// Reads the bytes a URI names: a `data:` URI is decoded in place, anything else is a
/// relative file path. `what` names the referencing object for messages.
pub(super) fn read_uri<'u>(
    uri: &'u str,
    base_dir: &Path,
    what: &str,
) -> Result<Cow<'u, [u8]>, String> {
    if let Some(data) = uri.strip_prefix("data:") {
        return decode_data_uri(data).map_err(|e| format!("{what}: invalid data URI: {e}"));
    }
    if has_scheme(uri) {
        return Err(format!(
            "{what}: URI '{uri}' is not supported (only relative file paths and data URIs are)"
        ));
    }
    let relative = percent_encoding::percent_decode_str(uri)
        .decode_utf8()
        .map_err(|_| format!("{what}: URI '{uri}' is not valid UTF-8 after percent-decoding"))?;
    let full = base_dir.join(relative.as_ref());
    crate::scene::sources::read(&full)
        .map(Cow::Owned)
        .map_err(|e| format!("{what}: cannot read '{uri}' ({}): {e}", full.display()))
}

/// True for `scheme:...` URIs (RFC 3986: a letter, then letters, digits, `+-.`, then `:`),
/// which are not relative paths. One letter before the colon is taken as a Windows drive.
fn has_scheme(uri: &str) -> bool {
    let Some(colon) = uri.find(':') else {
        return false;
    };
    let scheme = &uri[..colon];
    scheme.len() > 1
        && scheme.starts_with(|c: char| c.is_ascii_alphabetic())
        && scheme
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "+-.".contains(c))
}

/// Decodes the part of a data URI after `data:`: `[<mediatype>][;base64],<data>`.
fn decode_data_uri(data: &str) -> Result<Cow<'static, [u8]>, String> {
    let (header, payload) = data.split_once(',').ok_or("no ',' before the data")?;
    if header.ends_with(";base64") {
        base64::engine::general_purpose::STANDARD
            .decode(payload)
            .map(Cow::Owned)
            .map_err(|e| format!("bad base64: {e}"))
    } else {
        Ok(Cow::Owned(
            percent_encoding::percent_decode_str(payload).collect(),
        ))
    }
}

/// The encoded bytes of an image and a name for it (its glTF name, file or index).
pub(super) fn image_bytes<'b>(
    image: &gltf::Image,
    buffers: &'b Buffers,
    base_dir: &Path,
) -> Result<(Cow<'b, [u8]>, String), String> {
    let what = format!("image {}", image.index());
    match image.source() {
        gltf::image::Source::View { view, .. } => {
            let name = image.name().map_or_else(|| what.clone(), str::to_string);
            let bytes = buffers
                .view_bytes(&view)
                .map_err(|e| format!("{what}: {e}"))?;
            Ok((Cow::Borrowed(bytes), name))
        }
        gltf::image::Source::Uri { uri, .. } => {
            let name = match image.name() {
                Some(name) => name.to_string(),
                None if uri.starts_with("data:") => what.clone(),
                None => uri.to_string(),
            };
            let bytes = read_uri(uri, base_dir, &what)?.into_owned();
            Ok((Cow::Owned(bytes), name))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn data_uris_decode_base64_and_percent_forms() {
        assert_eq!(
            decode_data_uri("application/octet-stream;base64,AAEC")
                .unwrap()
                .as_ref(),
            [0, 1, 2]
        );
        assert_eq!(decode_data_uri(",a%20b").unwrap().as_ref(), b"a b");
        assert!(decode_data_uri("application/octet-stream;base64").is_err());
    }

    #[test]
    fn schemes_are_told_from_relative_paths_and_drives() {
        assert!(has_scheme("http://example.com/a.bin"));
        assert!(has_scheme("file:///a.bin"));
        assert!(!has_scheme("a.bin"));
        assert!(!has_scheme("C:/models/a.bin"));
        assert!(!has_scheme("sub dir/a:b.bin"));
    }
}
