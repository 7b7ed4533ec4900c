//! The loader's edge against hostile files. `openusd` 0.6 trusts the counts a file declares
//! (it allocates `count` elements before reading them, so a 100-byte crate file claiming
//! 2^40 tokens asks for a terabyte), indexes tables with file-controlled indices, and its
//! text reader recurses once per nesting level. So every layer's bytes are checked before
//! `openusd` parses them, through a resolver that sees every file the stage opens (the
//! root layer, sublayers, references, payloads, the layers inside a `.usdz`):
//! - a `.usdz` must be a whole ZIP archive whose entries lie inside the file and are stored
//!   uncompressed (the USDZ rule), so a truncated package is an error and no entry
//!   inflates;
//! - a crate (`.usdc`) file's header, table of contents and sections must lie inside the
//!   file, and every count its structural sections and values declare must fit the bytes
//!   that follow it (compressed data may grow at most 255 times, LZ4's limit; 2-bit integer
//!   codes four times more), nested dictionaries and time samples at most [`MAX_DEPTH`]
//!   deep;
//! - a text (`.usda`) layer must be UTF-8, nest brackets at most [`MAX_DEPTH`] deep, and
//!   close each path literal `<...>` on its line without whitespace (openusd recursed
//!   without end on one that did not: a stack overflow the fuzz target found).
//!
//! What passes these checks can still make `openusd` panic (an index past a table, a
//! feature it leaves `todo!()`): [`without_panics`] turns that into an error, the last
//! resort. The fuzz target `usd` runs the checks and the reader on arbitrary bytes.

use std::io::{self, Cursor};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;

use openusd::ar::{Asset, DefaultResolver, ResolvedPath, Resolver};
use openusd::usdc::{CrateFile, version};

/// Deepest nesting of brackets (text) or of dictionaries and time samples (crate) accepted:
/// real layers nest a few dozen levels; `openusd` recurses once per level.
pub const MAX_DEPTH: usize = 128;

/// Largest growth of LZ4-compressed bytes.
const LZ4_RATIO: u64 = 255;
/// Integers per uncompressed byte at most in crate integer coding (2-bit codes).
const INTS_PER_BYTE: u64 = 4;

/// Checks a stage file's bytes before `openusd` reads them.
///
/// # Errors
/// A message saying what is wrong with the file.
pub(super) fn check_file(path: &Path) -> Result<(), String> {
    let bytes = crate::scene::sources::read(path).map_err(|e| format!("cannot read file: {e}"))?;
    check_bytes(&bytes)
}

/// Checks the bytes of a `.usda`, `.usdc`, `.usd` or `.usdz` layer (by content).
///
/// # Errors
/// A message saying what is wrong.
pub fn check_bytes(bytes: &[u8]) -> Result<(), String> {
    if bytes.is_empty() {
        return Err("file is empty".into());
    }
    if bytes.starts_with(openusd::usdc::MAGIC) {
        check_crate(bytes)
    } else if bytes.starts_with(b"PK") {
        check_package(bytes)
    } else {
        check_text(bytes)
    }
}

/// Runs `f`, turning a panic inside it into an error (the last resort: every check that can
/// be made on the bytes is made first).
///
/// Fuzz builds (`--cfg fuzzing`) let the panic through, so the fuzzer reports what the
/// byte checks missed instead of this catching it.
pub(super) fn without_panics<T>(f: impl FnOnce() -> Result<T, String>) -> Result<T, String> {
    if cfg!(fuzzing) {
        return f();
    }
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(result) => result,
        Err(panic) => {
            let what = panic
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| panic.downcast_ref::<&str>().copied())
                .unwrap_or("unknown failure");
            Err(format!("the USD reader failed on this file ({what})"))
        }
    }
}

/// The default resolver, with every layer's bytes checked before `openusd` sees them.
pub(super) struct CheckingResolver {
    inner: DefaultResolver,
    /// The text layers handed to `openusd` so far, in order (see [`TextLayers`]).
    text_layers: TextLayers,
}

impl CheckingResolver {
    pub(super) fn new(text_layers: TextLayers) -> Self {
        CheckingResolver {
            inner: DefaultResolver::new(),
            text_layers,
        }
    }
}

/// The text layers a [`CheckingResolver`] has handed to `openusd`, kept so that a parse
/// error (which `openusd` reports without a position) can be placed: see
/// [`TextLayers::place`].
#[derive(Clone, Default)]
pub(super) struct TextLayers(std::rc::Rc<std::cell::RefCell<Vec<ResolvedPath>>>);

impl TextLayers {
    /// An error message from `openusd`, led by `file:line` when it is a text parse error.
    pub(super) fn place(&self, message: &str) -> String {
        if !message.contains("failed to parse USDA layer") {
            return message.to_string();
        }
        match self.locate_parse_error() {
            Some(at) => format!("{at}: {message}"),
            None => message.to_string(),
        }
    }

    /// `file:line` of the text parse error that stopped the stage: the layers handed to
    /// `openusd` are parsed again, latest first (the failing one is the last opened), as
    /// `openusd` parsed them; the line is the original file's (the text pass keeps lines).
    fn locate_parse_error(&self) -> Option<String> {
        let resolver = DefaultResolver::new();
        self.0.borrow().iter().rev().find_map(|path| {
            let bytes = resolver.open_asset(path).ok()?.read_all().ok()?;
            let text = String::from_utf8(tolerate_text(bytes)).ok()?;
            let mut parser = openusd::usda::parser::Parser::new(&text);
            let failed = parser.parse().is_err();
            failed
                .then(|| parser.last_error_highlight())
                .flatten()
                .map(|at| format!("{path}:{}", at.line))
        })
    }
}

impl Resolver for CheckingResolver {
    fn create_identifier(&self, asset_path: &str, anchor: Option<&ResolvedPath>) -> String {
        self.inner.create_identifier(asset_path, anchor)
    }
    fn resolve(&self, asset_path: &str) -> Option<ResolvedPath> {
        self.inner.resolve(asset_path)
    }
    fn resolve_for_new_asset(&self, asset_path: &str) -> Option<ResolvedPath> {
        self.inner.resolve_for_new_asset(asset_path)
    }
    fn open_asset(&self, resolved_path: &ResolvedPath) -> io::Result<Box<dyn Asset>> {
        let mut asset = self.inner.open_asset(resolved_path)?;
        let bytes = asset.read_all()?;
        crate::scene::sources::note(resolved_path, &bytes);
        check_bytes(&bytes).map_err(|e| {
            io::Error::new(io::ErrorKind::InvalidData, format!("{resolved_path}: {e}"))
        })?;
        if bytes.starts_with(b"#usda") {
            self.text_layers.0.borrow_mut().push(resolved_path.clone());
        }
        Ok(Box::new(Cursor::new(tolerate_text(bytes))))
    }
    fn identity(&self) -> String {
        self.inner.identity()
    }
}

/// A text layer as openusd 0.6 reads it, where USD's own text format allows more:
/// - the header line's trailing whitespace is dropped (`#usda 1.0 `);
/// - `//` and `/* */` comments become spaces (newlines kept, so lines keep their numbers);
/// - numbers USD writes without a digit on one side of the point get one: `.5` -> `0.5`,
///   `-.5` -> `-0.5`, `0.` -> `0.0`, `1.e5` -> `1.0e5`;
/// - legacy value type names USD still reads (`Vec3f`, `PointFloat`, `Color`, `Matrix4d`,
///   ...: [`LEGACY_TYPES`]) become the names they stand for, and `config` variability
///   becomes `uniform` (as USD reads it), where they stand as an attribute's or a dictionary
///   value's type: at the start of a statement or after `custom`, `uniform`, ..., and
///   followed by a name;
/// - `uint[]` and `uint64[]` in the same place become `int64[]` (openusd reads neither array
///   type; every `uint` value is an `int64` value, and a `uint64` value past the largest
///   `int64` is refused instead of altered).
///
/// Strings, asset paths and path literals are left alone. Crate files and packages pass
/// unchanged, and so does a text layer that needs none of this (without a copy).
pub(super) fn tolerate_text(bytes: Vec<u8>) -> Vec<u8> {
    if !bytes.starts_with(b"#usda") {
        return bytes;
    }
    let n = bytes.len();
    let mut edits = Edits::default();
    let header_end = skip_until(&bytes, 0, |b| b == b'\n');
    let trimmed = bytes[..header_end]
        .iter()
        .rposition(|b| !b.is_ascii_whitespace())
        .map_or(0, |i| i + 1);
    if trimmed < header_end {
        edits.replace(&bytes, trimmed, header_end, b"");
    }
    // Whether the next word may be an attribute's (or dictionary value's) type: at the start
    // of a line or of a block, or after a qualifier such as `custom` or `uniform`.
    let mut statement_start = true;
    let mut i = header_end;
    while i < n {
        let b = bytes[i];
        match b {
            b'\n' => {
                statement_start = true;
                i += 1;
            }
            b' ' | b'\t' | b'\r' => i += 1,
            b'#' => i = skip_until(&bytes, i + 1, |b| b == b'\n'),
            quote @ (b'"' | b'\'' | b'@') if bytes[i..].starts_with(&[quote; 3]) => {
                i = bytes[i + 3..]
                    .windows(3)
                    .position(|w| w == [quote; 3])
                    .map_or(n, |k| i + 3 + k + 3);
                statement_start = false;
            }
            quote @ (b'"' | b'\'' | b'@') => {
                let mut j = i + 1;
                while j < n && bytes[j] != quote {
                    j += if bytes[j] == b'\\' { 2 } else { 1 };
                }
                i = j + 1;
                statement_start = false;
            }
            b'<' => {
                i = skip_until(&bytes, i + 1, |b| b == b'>' || b.is_ascii_whitespace()) + 1;
                statement_start = false;
            }
            b'/' if bytes.get(i + 1) == Some(&b'/') => {
                let end = skip_until(&bytes, i, |b| b == b'\n');
                edits.blank(&bytes, i, end);
                i = end;
            }
            b'/' if bytes.get(i + 1) == Some(&b'*') => {
                let end = bytes[i + 2..]
                    .windows(2)
                    .position(|w| w == b"*/")
                    .map_or(n, |k| i + 2 + k + 2);
                if edits.blank(&bytes, i, end) {
                    statement_start = true;
                }
                i = end;
            }
            b'0'..=b'9' => {
                i = number(&bytes, i, &mut edits);
                statement_start = false;
            }
            b'.' if bytes.get(i + 1).is_some_and(u8::is_ascii_digit)
                && !bytes[..i]
                    .last()
                    .is_some_and(|&p| p.is_ascii_alphanumeric() || p == b'_' || p >= 0x80) =>
            {
                edits.replace(&bytes, i, i, b"0");
                i = number(&bytes, i, &mut edits);
                statement_start = false;
            }
            b if is_word_start(b) => {
                let end = skip_until(&bytes, i, |b| !is_word_byte(b));
                let word = &bytes[i..end];
                if let Some(with) = statement_start
                    .then(|| type_rewrite(word, &bytes[end..]))
                    .flatten()
                {
                    edits.replace(&bytes, i, end, with);
                }
                statement_start = statement_start && QUALIFIERS.contains(&word);
                i = end;
            }
            b'{' | b'(' | b';' => {
                statement_start = true;
                i += 1;
            }
            _ => {
                statement_start = false;
                i += 1;
            }
        }
    }
    edits.finish(bytes)
}

/// Legacy value type names USD's text reader still accepts (`Sdf_ParserHelpers`' value
/// factories), with the names openusd knows them by. `Transform` is a `matrix4d`, and the
/// `PointIndex`, `EdgeIndex` and `FaceIndex` roles are `int`s (their roles are lost; nothing
/// mipray reads depends on them).
pub(super) const LEGACY_TYPES: [(&str, &str); 32] = [
    ("Vec2i", "int2"),
    ("Vec2h", "half2"),
    ("Vec2f", "float2"),
    ("Vec2d", "double2"),
    ("Vec3i", "int3"),
    ("Vec3h", "half3"),
    ("Vec3f", "float3"),
    ("Vec3d", "double3"),
    ("Vec4i", "int4"),
    ("Vec4h", "half4"),
    ("Vec4f", "float4"),
    ("Vec4d", "double4"),
    ("PointFloat", "point3f"),
    ("Point", "point3d"),
    ("NormalFloat", "normal3f"),
    ("Normal", "normal3d"),
    ("VectorFloat", "vector3f"),
    ("Vector", "vector3d"),
    ("ColorFloat", "color3f"),
    ("Color", "color3d"),
    ("Quath", "quath"),
    ("Quatf", "quatf"),
    ("Quatd", "quatd"),
    ("Matrix2d", "matrix2d"),
    ("Matrix3d", "matrix3d"),
    ("Matrix4d", "matrix4d"),
    ("Frame", "frame4d"),
    ("Transform", "matrix4d"),
    ("PointIndex", "int"),
    ("EdgeIndex", "int"),
    ("FaceIndex", "int"),
    ("Schema", "token"),
];

/// Words after which a statement's type may still follow.
const QUALIFIERS: [&[u8]; 8] = [
    b"custom", b"uniform", b"varying", b"config", b"add", b"delete", b"append", b"prepend",
];

/// What `word`, at the start of a statement and followed by `rest`, becomes, if it is a
/// type openusd does not read: a legacy type name or an unsigned integer array followed by
/// a name (an attribute's or a dictionary key), or `config` followed by a type.
fn type_rewrite(word: &[u8], rest: &[u8]) -> Option<&'static [u8]> {
    let blanks = |at: usize| {
        at + rest[at.min(rest.len())..]
            .iter()
            .take_while(|&&b| b == b' ' || b == b'\t')
            .count()
    };
    let name_at = |at: usize| {
        rest.get(at)
            .is_some_and(|&b| is_word_start(b) || b == b'"' || b == b'\'')
    };
    let mut at = blanks(0);
    if word == b"config" {
        return rest
            .get(at)
            .is_some_and(|&b| is_word_start(b))
            .then_some(b"uniform".as_slice());
    }
    let array = rest.get(at) == Some(&b'[') && rest.get(blanks(at + 1)) == Some(&b']');
    if array {
        at = blanks(blanks(at + 1) + 1);
    }
    if !name_at(at) {
        return None;
    }
    match word {
        b"uint" | b"uint64" if array => Some(b"int64"),
        _ => LEGACY_TYPES
            .iter()
            .find(|(legacy, _)| legacy.as_bytes() == word)
            .map(|(_, name)| name.as_bytes()),
    }
}

/// Copies the number at `i` (digits, a point and its digits), giving a bare point a `0`
/// after it (`0.` -> `0.0`, `1.e5` -> `1.0e5`); returns where it ends.
fn number(bytes: &[u8], i: usize, edits: &mut Edits) -> usize {
    let digits = |from: usize| skip_until(bytes, from, |b| !b.is_ascii_digit());
    let end = digits(i);
    if bytes.get(end) != Some(&b'.') {
        return end;
    }
    if bytes.get(end + 1).is_some_and(u8::is_ascii_digit) {
        return digits(end + 1);
    }
    edits.replace(bytes, end + 1, end + 1, b"0");
    end + 1
}

/// A byte that starts a word (an identifier or keyword; UTF-8 letters included).
fn is_word_start(b: u8) -> bool {
    b.is_ascii_alphabetic() || b == b'_' || b >= 0x80
}

/// A byte inside a word (namespaced identifiers included: `primvars:st`).
fn is_word_byte(b: u8) -> bool {
    b.is_ascii_alphanumeric() || b == b'_' || b == b':' || b >= 0x80
}

/// The rewritten layer, built only once the first edit is made.
#[derive(Default)]
struct Edits {
    out: Vec<u8>,
    /// Input bytes before this are in `out`.
    copied: usize,
    edited: bool,
}

impl Edits {
    /// Replaces `bytes[start..end]` (after the last edit) by `with`.
    fn replace(&mut self, bytes: &[u8], start: usize, end: usize, with: &[u8]) {
        if !self.edited {
            self.out.reserve(bytes.len() + bytes.len() / 16 + 16);
            self.edited = true;
        }
        self.out.extend_from_slice(&bytes[self.copied..start]);
        self.out.extend_from_slice(with);
        self.copied = end;
    }

    /// Turns `bytes[start..end]` into spaces, newlines kept; whether it held a newline.
    fn blank(&mut self, bytes: &[u8], start: usize, end: usize) -> bool {
        self.replace(bytes, start, start, b"");
        let mut newline = false;
        for &b in &bytes[start..end] {
            newline |= b == b'\n';
            self.out.push(if b == b'\n' { b'\n' } else { b' ' });
        }
        self.copied = end;
        newline
    }

    fn finish(mut self, bytes: Vec<u8>) -> Vec<u8> {
        if !self.edited {
            return bytes;
        }
        self.out
            .extend_from_slice(&bytes[self.copied.min(bytes.len())..]);
        self.out
    }
}

/// The index of the first byte from `from` on that `stop` accepts (the length if none).
fn skip_until(bytes: &[u8], from: usize, stop: impl Fn(u8) -> bool) -> usize {
    bytes
        .get(from..)
        .and_then(|rest| rest.iter().position(|&b| stop(b)))
        .map_or(bytes.len(), |k| from + k)
}

/// Text: UTF-8, the `#usda` header, brackets nested at most [`MAX_DEPTH`] deep (outside
/// strings and comments).
fn check_text(bytes: &[u8]) -> Result<(), String> {
    let text = std::str::from_utf8(bytes)
        .map_err(|e| format!("not a USD file: neither a crate, a package nor UTF-8 text ({e})"))?;
    if !text.trim_start().starts_with("#usda") {
        return Err("not a USD file: text layers start with '#usda'".into());
    }
    let mut depth = 0usize;
    let mut chars = text.char_indices().peekable();
    let mut line = 1;
    while let Some((start, c)) = chars.next() {
        match c {
            '\n' => line += 1,
            '#' => {
                for (_, c) in chars.by_ref() {
                    if c == '\n' {
                        line += 1;
                        break;
                    }
                }
            }
            '"' | '\'' | '@' => {
                // Skip the quoted string (triple quotes included: they pair up the same).
                let mut escaped = false;
                for (_, d) in chars.by_ref() {
                    if d == '\n' {
                        line += 1;
                    }
                    if escaped {
                        escaped = false;
                    } else if d == '\\' {
                        escaped = true;
                    } else if d == c {
                        break;
                    }
                }
            }
            '<' => {
                // A path literal: openusd 0.6 recursed without end on one that ran over
                // lines (found by the fuzz target); real paths hold no whitespace. Nor may
                // its walk up the path's ancestors fail to end (a `}` without its `{`):
                // openusd walks them while composing, before the loader sees the path.
                let mut end = None;
                for (at, d) in chars.by_ref() {
                    if d == '>' {
                        end = Some(at);
                        break;
                    }
                    if d.is_whitespace() {
                        break;
                    }
                }
                let Some(end) = end else {
                    return Err(format!(
                        "line {line}: a path '<...>' is not closed on its line or holds whitespace"
                    ));
                };
                let path = openusd::sdf::Path::new(&text[start + 1..end])
                    .map_err(|e| format!("line {line}: {e}"))?;
                super::values::walkable_path(&path).map_err(|e| format!("line {line}: {e}"))?;
            }
            '{' | '[' | '(' => {
                depth += 1;
                if depth > MAX_DEPTH {
                    return Err(format!(
                        "line {line}: brackets nest more than {MAX_DEPTH} levels deep"
                    ));
                }
            }
            '}' | ']' | ')' => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    Ok(())
}

/// A ZIP archive (a `.usdz`): its end record and central directory inside the file, every
/// entry inside the file and stored uncompressed; the layers it holds are checked when the
/// stage opens them.
fn check_package(bytes: &[u8]) -> Result<(), String> {
    const END: [u8; 4] = [0x50, 0x4b, 0x05, 0x06];
    const ENTRY: [u8; 4] = [0x50, 0x4b, 0x01, 0x02];
    const LOCAL: [u8; 4] = [0x50, 0x4b, 0x03, 0x04];
    let truncated = || {
        "the .usdz package is truncated or not a ZIP archive (no end of central directory)"
            .to_string()
    };
    let search_from = bytes.len().saturating_sub(22 + 65535);
    let end = (search_from..=bytes.len().saturating_sub(22))
        .rev()
        .find(|&i| bytes[i..i + 4] == END)
        .ok_or_else(truncated)?;
    let u16_at = |i: usize| {
        bytes
            .get(i..i + 2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]) as u64)
    };
    let u32_at = |i: usize| {
        bytes
            .get(i..i + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as u64)
    };
    let entries = u16_at(end + 10).ok_or_else(truncated)?;
    let directory_size = u32_at(end + 12).ok_or_else(truncated)?;
    let directory = u32_at(end + 16).ok_or_else(truncated)?;
    if directory + directory_size > end as u64 {
        return Err(format!(
            "the .usdz package's central directory ({directory_size} bytes at {directory}) lies outside the file: it is truncated or corrupt"
        ));
    }
    let mut at = directory as usize;
    for k in 0..entries {
        let bad =
            |what: &str| format!("the .usdz package's entry {k} {what}: the package is corrupt");
        if bytes.get(at..at + 4) != Some(&ENTRY[..]) {
            return Err(bad("is not where the central directory says"));
        }
        let method = u16_at(at + 10).ok_or_else(|| bad("is cut off"))?;
        let compressed = u32_at(at + 20).ok_or_else(|| bad("is cut off"))?;
        let size = u32_at(at + 24).ok_or_else(|| bad("is cut off"))?;
        let name_len = u16_at(at + 28).ok_or_else(|| bad("is cut off"))? as usize;
        let extra_len = u16_at(at + 30).ok_or_else(|| bad("is cut off"))? as usize;
        let comment_len = u16_at(at + 32).ok_or_else(|| bad("is cut off"))? as usize;
        let local = u32_at(at + 42).ok_or_else(|| bad("is cut off"))? as usize;
        let name = bytes
            .get(at + 46..at + 46 + name_len)
            .map(String::from_utf8_lossy)
            .ok_or_else(|| bad("is cut off"))?;
        if method != 0 || compressed != size {
            return Err(format!(
                "the .usdz package's file '{name}' is compressed (method {method}); USDZ packages store their files uncompressed"
            ));
        }
        if bytes.get(local..local + 4) != Some(&LOCAL[..]) {
            return Err(format!(
                "the .usdz package's file '{name}' has no local header where the directory says: the package is corrupt"
            ));
        }
        let local_name = u16_at(local + 26).unwrap_or(0) as usize;
        let local_extra = u16_at(local + 28).unwrap_or(0) as usize;
        let data = (local + 30 + local_name + local_extra) as u64;
        if data + size > bytes.len() as u64 {
            return Err(format!(
                "the .usdz package's file '{name}' ({size} bytes) runs past the end of the package: it is truncated"
            ));
        }
        at += 46 + name_len + extra_len + comment_len;
    }
    Ok(())
}

/// A little-endian cursor over the file's bytes that never reads past them.
struct Bytes<'a> {
    bytes: &'a [u8],
}

impl Bytes<'_> {
    fn u64_at(&self, at: u64) -> Result<u64, String> {
        let at =
            usize::try_from(at).map_err(|_| "an offset past the end of the file".to_string())?;
        self.bytes
            .get(at..at.saturating_add(8))
            .and_then(|b| b.try_into().ok())
            .map(u64::from_le_bytes)
            .ok_or_else(|| {
                format!(
                    "a read at byte {at} runs past the end of the file ({} bytes)",
                    self.bytes.len()
                )
            })
    }
    fn u32_at(&self, at: u64) -> Result<u64, String> {
        let at =
            usize::try_from(at).map_err(|_| "an offset past the end of the file".to_string())?;
        self.bytes
            .get(at..at.saturating_add(4))
            .and_then(|b| b.try_into().ok())
            .map(|b| u32::from_le_bytes(b) as u64)
            .ok_or_else(|| {
                format!(
                    "a read at byte {at} runs past the end of the file ({} bytes)",
                    self.bytes.len()
                )
            })
    }
    fn len(&self) -> u64 {
        self.bytes.len() as u64
    }
}

/// A crate file: structure before `openusd` opens it, then every field's value.
fn check_crate(bytes: &[u8]) -> Result<(), String> {
    let file = Bytes { bytes };
    let corrupt = |e: String| format!("corrupt crate (.usdc) file: {e}");
    check_crate_structure(&file).map_err(corrupt)?;
    let crate_file = without_panics(|| {
        CrateFile::open(Cursor::new(bytes))
            .map_err(|e| format!("corrupt crate (.usdc) file: {e:#}"))
    })?;
    let v = crate_file.version();
    let values = Values {
        visited: std::cell::Cell::new(0),
        file: &file,
        old_arrays: v < version(0, 5, 0),
        u32_counts: v < version(0, 7, 0),
    };
    for (k, field) in crate_file.fields.iter().enumerate() {
        values
            .check(field.value_rep.0, 0)
            .map_err(|e| corrupt(format!("field {k}: {e}")))?;
    }
    for path in &crate_file.paths {
        if path.as_str().matches('/').count() > MAX_DEPTH {
            return Err(corrupt(format!(
                "a path nests more than {MAX_DEPTH} prims deep"
            )));
        }
    }
    Ok(())
}

/// Bootstrap, table of contents, and the counts of the structural sections (what
/// `openusd` allocates when it opens the file).
fn check_crate_structure(file: &Bytes) -> Result<(), String> {
    if file.len() < 88 {
        return Err(format!(
            "{} bytes, shorter than the 88-byte header",
            file.len()
        ));
    }
    let b = file.bytes;
    if b[8] == 0 && b[9] < 4 {
        return Err(format!(
            "version 0.{}.{} is older than this reader supports (0.4.0)",
            b[9], b[10]
        ));
    }
    let toc = file.u64_at(16)?;
    let sections = file.u64_at(toc)?;
    if sections == 0 || sections >= 64 || toc + 8 + sections * 32 > file.len() {
        return Err(format!(
            "the table of contents declares {sections} sections that do not fit the file"
        ));
    }
    for s in 0..sections {
        let at = toc + 8 + s * 32;
        let name_bytes = &b[at as usize..at as usize + 16];
        let name = String::from_utf8_lossy(name_bytes.split(|&c| c == 0).next().unwrap_or(&[]))
            .to_string();
        let start = file.u64_at(at + 16)?;
        let size = file.u64_at(at + 24)?;
        let end = start.checked_add(size).filter(|&e| e <= file.len()).ok_or_else(|| {
            format!("section {name} ({size} bytes at {start}) runs past the end of the file ({} bytes)", file.len())
        })?;
        let section = Section {
            file,
            name: &name,
            end,
        };
        match name.as_str() {
            "TOKENS" => {
                let count = file.u64_at(start)?;
                let uncompressed = file.u64_at(start + 8)?;
                let compressed = section.compressed(start + 16)?;
                if uncompressed > compressed.saturating_mul(LZ4_RATIO) + 64
                    || count > uncompressed + 1
                {
                    return Err(format!(
                        "section TOKENS declares {count} tokens in {uncompressed} bytes, more than its {compressed} compressed bytes hold"
                    ));
                }
            }
            "STRINGS" => {
                let count = file.u64_at(start)?;
                section.fits(count, 4, start + 8, "strings")?;
            }
            "FIELDS" => {
                let count = file.u64_at(start)?;
                let next = section.encoded_ints(count, start + 8, "field names")?;
                let reps = section.compressed(next)?;
                if count.saturating_mul(8) > reps.saturating_mul(LZ4_RATIO) + 64 {
                    return Err(format!(
                        "section FIELDS declares {count} values, more than {reps} compressed bytes hold"
                    ));
                }
            }
            "FIELDSETS" => {
                let count = file.u64_at(start)?;
                section.encoded_ints(count, start + 8, "field sets")?;
            }
            "PATHS" => {
                let count = file.u64_at(start)?;
                let encoded = file.u64_at(start + 8)?;
                let mut at = start + 16;
                for what in ["path indices", "path elements", "path jumps"] {
                    at = section.encoded_ints(encoded, at, what)?;
                }
                if count > encoded.saturating_mul(2) + 1 {
                    return Err(format!(
                        "section PATHS declares {count} paths but encodes {encoded}"
                    ));
                }
            }
            "SPECS" => {
                let count = file.u64_at(start)?;
                let mut at = start + 8;
                for what in ["spec paths", "spec field sets", "spec types"] {
                    at = section.encoded_ints(count, at, what)?;
                }
            }
            _ => {}
        }
    }
    Ok(())
}

/// One section of a crate file, for its count checks.
struct Section<'a> {
    file: &'a Bytes<'a>,
    name: &'a str,
    end: u64,
}

impl Section<'_> {
    /// A compressed block at `at` (its u64 size, then the bytes) inside the section;
    /// returns its size.
    fn compressed(&self, at: u64) -> Result<u64, String> {
        let size = self.file.u64_at(at)?;
        if at + 8 + size > self.end {
            return Err(format!(
                "section {} declares a {size}-byte compressed block at byte {at}, past the section's end",
                self.name
            ));
        }
        Ok(size)
    }

    /// `count` integers compressed at `at`; returns the offset after them.
    fn encoded_ints(&self, count: u64, at: u64, what: &str) -> Result<u64, String> {
        if count == 0 {
            return Ok(at);
        }
        let size = self.compressed(at)?;
        if count > (size.saturating_mul(LZ4_RATIO) + 64).saturating_mul(INTS_PER_BYTE) {
            return Err(format!(
                "section {} declares {count} {what}, more than its {size} compressed bytes can hold",
                self.name
            ));
        }
        Ok(at + 8 + size)
    }

    /// `count` elements of `size` bytes from `at` inside the section.
    fn fits(&self, count: u64, size: u64, at: u64, what: &str) -> Result<(), String> {
        if count.saturating_mul(size) > self.end.saturating_sub(at) {
            return Err(format!(
                "section {} declares {count} {what}, more than its {} bytes hold",
                self.name,
                self.end.saturating_sub(at)
            ));
        }
        Ok(())
    }
}

/// Walks value representations as `openusd` reads them, checking every count against the
/// bytes after it.
struct Values<'a> {
    /// Values visited so far (bounded by [`MAX_VALUES_VISITED`]).
    visited: std::cell::Cell<u64>,
    file: &'a Bytes<'a>,
    /// Crate versions before 0.5.0 store a u32 shape before array counts.
    old_arrays: bool,
    /// Versions before 0.7.0 store array counts as u32.
    u32_counts: bool,
}

/// Crate value type codes (`openusd::usdc::Type`) with a payload the walk follows.
mod ty {
    pub const STRING: u64 = 10;
    pub const ASSET_PATH: u64 = 12;
    pub const DICTIONARY: u64 = 31;
    pub const TOKEN_LIST_OP: u64 = 32;
    pub const STRING_LIST_OP: u64 = 33;
    pub const PATH_LIST_OP: u64 = 34;
    pub const REFERENCE_LIST_OP: u64 = 35;
    pub const INT_LIST_OP: u64 = 36;
    pub const INT64_LIST_OP: u64 = 37;
    pub const UINT_LIST_OP: u64 = 38;
    pub const UINT64_LIST_OP: u64 = 39;
    pub const PATH_VECTOR: u64 = 40;
    pub const TOKEN_VECTOR: u64 = 41;
    pub const VARIANT_SELECTION_MAP: u64 = 45;
    pub const TIME_SAMPLES: u64 = 46;
    pub const DOUBLE_VECTOR: u64 = 48;
    pub const LAYER_OFFSET_VECTOR: u64 = 49;
    pub const STRING_VECTOR: u64 = 50;
    pub const UNREGISTERED_VALUE_LIST_OP: u64 = 54;
    pub const PAYLOAD_LIST_OP: u64 = 55;
    pub const TIME_CODE: u64 = 56;
    pub const PATH_EXPRESSION: u64 = 57;
    pub const RELOCATES: u64 = 58;
}

/// Bytes per element of an uncompressed array of crate type `t` (1 for types without a
/// fixed size: the most permissive bound).
fn element_size(t: u64) -> u64 {
    match t {
        1 | 2 => 1,                     // bool, uchar
        3 | 4 | 8 => 4,                 // int, uint, float
        5 | 6 | 9 | ty::TIME_CODE => 8, // int64, uint64, double, time code
        7 => 2,                         // half
        13 => 32,                       // matrix2d
        14 => 72,                       // matrix3d
        15 => 128,                      // matrix4d
        16 => 32,                       // quatd
        17 => 16,                       // quatf
        18 => 8,                        // quath
        19 => 16,
        20 => 8,
        21 => 4,
        22 => 8, // vec2 d f h i
        23 => 24,
        24 => 12,
        25 => 6,
        26 => 12, // vec3 d f h i
        27 => 32,
        28 => 16,
        29 => 8,
        30 => 16, // vec4 d f h i
        _ => 1,
    }
}

/// Most values one crate file may make the walk visit (a file of values pointing at each
/// other could otherwise make it, and `openusd` after it, run for ever).
const MAX_VALUES_VISITED: u64 = 1 << 24;

impl Values<'_> {
    fn check(&self, rep: u64, depth: usize) -> Result<(), String> {
        const ARRAY: u64 = 1 << 63;
        const INLINED: u64 = 1 << 62;
        const COMPRESSED: u64 = 1 << 61;
        if depth > MAX_DEPTH {
            return Err(format!("values nest more than {MAX_DEPTH} levels deep"));
        }
        self.visited.set(self.visited.get() + 1);
        if self.visited.get() > MAX_VALUES_VISITED {
            return Err("its values refer to each other more than a real file's do".into());
        }
        let t = (rep >> 48) & 0xff;
        let payload = rep & ((1 << 48) - 1);
        let is_array = rep & ARRAY != 0;
        if rep & INLINED != 0 || payload == 0 {
            return Ok(());
        }
        if payload >= self.file.len() {
            return Err(format!(
                "a value at byte {payload} lies past the end of the file ({} bytes)",
                self.file.len()
            ));
        }
        let remaining = |at: u64| self.file.len().saturating_sub(at);
        match t {
            // Arrays of string, token and asset path indices: a u64 count, then u32s.
            ty::STRING..=ty::ASSET_PATH if is_array => self.indices(payload, 4).map(drop)?,
            ty::PATH_EXPRESSION if is_array => self.indices(payload, 4).map(drop)?,
            _ if is_array || t == ty::DOUBLE_VECTOR => {
                let mut at = payload;
                if self.old_arrays {
                    at += 4;
                }
                let count = if self.u32_counts {
                    self.file.u32_at(at)?
                } else {
                    self.file.u64_at(at)?
                };
                at += if self.u32_counts { 4 } else { 8 };
                let limit = if rep & COMPRESSED != 0 {
                    (remaining(at).saturating_mul(LZ4_RATIO) + 64).saturating_mul(INTS_PER_BYTE)
                } else {
                    let element = if t == ty::DOUBLE_VECTOR {
                        8
                    } else {
                        element_size(t)
                    };
                    remaining(at) / element
                };
                if count > limit {
                    return Err(format!(
                        "an array at byte {payload} declares {count} elements, more than the {} bytes after it hold",
                        remaining(at)
                    ));
                }
            }
            ty::TOKEN_VECTOR | ty::PATH_VECTOR | ty::STRING_VECTOR => {
                self.indices(payload, 4).map(drop)?
            }
            ty::LAYER_OFFSET_VECTOR => self.indices(payload, 16).map(drop)?,
            ty::VARIANT_SELECTION_MAP | ty::RELOCATES => self.indices(payload, 8).map(drop)?,
            ty::TOKEN_LIST_OP
            | ty::STRING_LIST_OP
            | ty::PATH_LIST_OP
            | ty::UINT_LIST_OP
            | ty::INT_LIST_OP
            | ty::UNREGISTERED_VALUE_LIST_OP => self.list_op(payload, 4)?,
            ty::INT64_LIST_OP | ty::UINT64_LIST_OP => self.list_op(payload, 8)?,
            ty::REFERENCE_LIST_OP | ty::PAYLOAD_LIST_OP => {
                // Each item: a string and a path index and a layer offset; references
                // also a dictionary, which holds further values.
                let mut at = payload + 1;
                for _ in 0..list_count(self.file.bytes.get(payload as usize).copied()) {
                    let count = self.indices(at, 8)?;
                    at += 8;
                    for _ in 0..count {
                        at += 24;
                        if t == ty::REFERENCE_LIST_OP {
                            at = self.dictionary(at, depth + 1)?;
                        }
                    }
                }
            }
            ty::DICTIONARY => {
                self.dictionary(payload, depth + 1)?;
            }
            ty::TIME_SAMPLES => {
                let times_at = self.jump(payload)?;
                self.check(self.file.u64_at(times_at)?, depth + 1)?;
                let values_at = self.jump(times_at + 8)?;
                let count = self.indices(values_at, 8)?;
                for k in 0..count {
                    self.check(self.file.u64_at(values_at + 8 + 8 * k)?, depth + 1)?;
                }
            }
            _ => {}
        }
        Ok(())
    }

    /// Follows the relative jump (an i64 counted from its own position) stored at `at`.
    fn jump(&self, at: u64) -> Result<u64, String> {
        let offset = self.file.u64_at(at)? as i64;
        (at as i64)
            .checked_add(offset)
            .filter(|&a| a >= 0 && (a as u64) < self.file.len())
            .map(|a| a as u64)
            .ok_or_else(|| format!("a jump at byte {at} leaves the file"))
    }

    /// A u64 count at `at` of elements of `size` bytes that must follow it; the count.
    fn indices(&self, at: u64, size: u64) -> Result<u64, String> {
        let count = self.file.u64_at(at)?;
        let room = self.file.len().saturating_sub(at + 8);
        if count.saturating_mul(size) > room {
            return Err(format!(
                "a list at byte {at} declares {count} elements, more than the {room} bytes after it hold"
            ));
        }
        Ok(count)
    }

    /// A list op: a header byte, then one counted list per flag set in it.
    fn list_op(&self, at: u64, size: u64) -> Result<(), String> {
        let header = self.file.bytes.get(at as usize).copied();
        let mut at = at + 1;
        for _ in 0..list_count(header) {
            let count = self.indices(at, size)?;
            at += 8 + count * size;
        }
        Ok(())
    }

    /// A dictionary at `at`: count, then per entry a key index, a jump to its value rep;
    /// returns where the stream continues.
    fn dictionary(&self, at: u64, depth: usize) -> Result<u64, String> {
        if depth > MAX_DEPTH {
            return Err(format!(
                "dictionaries nest more than {MAX_DEPTH} levels deep"
            ));
        }
        let count = self.indices(at, 12)?;
        let mut at = at + 8;
        for _ in 0..count {
            at += 4;
            let rep_at = self.jump(at)?;
            let rep = self.file.u64_at(rep_at)?;
            self.check(rep, depth + 1)?;
            at = rep_at + 8;
        }
        Ok(at)
    }
}

/// How many item lists a list op's header byte announces (bit 0 only marks it explicit).
fn list_count(header: Option<u8>) -> u32 {
    header.map_or(0, |h| (h & !1).count_ones())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn c_comments_and_a_loose_header_are_tolerated_and_strings_kept() {
        let text = "#usda 1.0 \t\n// line\ndef \"A//B\" /* block\nspans */ {\n  string s = \"\"\"x \"y // z\"\"\"\n  asset a = @//server/x.png@\n  rel r = </A/B> // after\n}\n";
        let out = String::from_utf8(tolerate_text(text.as_bytes().to_vec())).unwrap();
        assert_eq!(
            out,
            "#usda 1.0\n       \ndef \"A//B\"         \n         {\n  string s = \"\"\"x \"y // z\"\"\"\n  asset a = @//server/x.png@\n  rel r = </A/B>         \n}\n"
        );
        // Crate files and packages pass unchanged.
        let crate_bytes = b"PXR-USDC// not text".to_vec();
        assert_eq!(tolerate_text(crate_bytes.clone()), crate_bytes);
    }

    /// The pass's output as text.
    fn tolerated(text: &str) -> String {
        String::from_utf8(tolerate_text(text.as_bytes().to_vec())).unwrap()
    }

    #[test]
    fn numbers_get_a_digit_beside_a_bare_point_and_nothing_else_changes() {
        let text = r#"#usda 1.0
(
    doc = "version 1. of .5"
    startTimeCode = 0.
    endTimeCode = 1.e2
)
def Mesh "M" (
    references = @./v1.0/a.5.usda@</A.5>
)
{
    point3f[] points = [(.5, -.5, 0.), (1.e5, 5.E-3, -0.), (2.5, 1e3, -3)]
    float2[] primvars:st2 = [(0.25, .75)]
    float3 inputs:uv2.connect = </M/Reader2.5.outputs:result>
    double xformOp:translate:x.timeSamples = { 0.: .5, 1.5: 2., 3: -.25 }
    asset a = @@@x .5 @ 1.@@@
    string s = """two
lines 1. and .2"""
    token t = '.5'
    # a comment 1. .5
    // a comment 1. .5
}
"#;
        let expected = r#"#usda 1.0
(
    doc = "version 1. of .5"
    startTimeCode = 0.0
    endTimeCode = 1.0e2
)
def Mesh "M" (
    references = @./v1.0/a.5.usda@</A.5>
)
{
    point3f[] points = [(0.5, -0.5, 0.0), (1.0e5, 5.0E-3, -0.0), (2.5, 1e3, -3)]
    float2[] primvars:st2 = [(0.25, 0.75)]
    float3 inputs:uv2.connect = </M/Reader2.5.outputs:result>
    double xformOp:translate:x.timeSamples = { 0.0: 0.5, 1.5: 2.0, 3: -0.25 }
    asset a = @@@x .5 @ 1.@@@
    string s = """two
lines 1. and .2"""
    token t = '.5'
    # a comment 1. .5
                      
}
"#;
        assert_eq!(tolerated(text), expected);
        // openusd reads the result, with the values USD gives the original.
        let data = openusd::usda::parse(expected).unwrap();
        let points = openusd::sdf::path("/M.points").unwrap();
        let value = openusd::sdf::AbstractData::get_field(&data, &points, "default")
            .unwrap()
            .into_owned();
        let openusd::sdf::Value::Vec3fVec(points) = value else {
            panic!("points read as {value:?}");
        };
        assert_eq!(points[0].x, 0.5);
        assert_eq!(points[0].y, -0.5);
        assert_eq!(points[1].x, 1.0e5);
        assert_eq!(points[1].y, 5.0e-3);
        // A layer that needs nothing keeps its bytes.
        let clean =
            "#usda 1.0\ndef Xform \"A\"\n{\n    double3 xformOp:translate = (0.5, 1, -0.25)\n}\n";
        assert_eq!(tolerated(clean), clean);
    }

    #[test]
    fn legacy_type_names_become_current_ones_only_where_they_are_types() {
        let text = r#"#usda 1.0
(
    customData = {
        Vec3f v = (1, 2, 3)
        Color "key" = (0.5, 0.5, 0.5)
        string Color = "Vec3f a"
    }
)
def Color "Vec3f"
{
    Vec3f a = (1, 2, 3)
    custom PointFloat[] b = [(0, 0, 0)]
    uniform Color c
    config float d = 1
    custom config Matrix4d []  e
    prepend Vec2f f.connect = </Vec3f.Normal>
    uint u = 5
    uint[] us = [1, 4294967295]
    uint64 [] ul = [1]
    Normal
    rel Color
    rel Vector = </Point>
    float3 Point.connect = </Color.outputs:Vec3f>
    token Frame = "Point"
    asset g = @Vec3f h.usda@
    custom uint[]
}
"#;
        let expected = r#"#usda 1.0
(
    customData = {
        float3 v = (1, 2, 3)
        color3d "key" = (0.5, 0.5, 0.5)
        string Color = "Vec3f a"
    }
)
def Color "Vec3f"
{
    float3 a = (1, 2, 3)
    custom point3f[] b = [(0, 0, 0)]
    uniform color3d c
    uniform float d = 1
    custom uniform matrix4d []  e
    prepend float2 f.connect = </Vec3f.Normal>
    uint u = 5
    int64[] us = [1, 4294967295]
    int64 [] ul = [1]
    Normal
    rel Color
    rel Vector = </Point>
    float3 Point.connect = </Color.outputs:Vec3f>
    token Frame = "Point"
    asset g = @Vec3f h.usda@
    custom uint[]
}
"#;
        assert_eq!(tolerated(text), expected);
        // Every name a legacy one becomes is one openusd reads (an unknown type's value is an
        // error there).
        for (legacy, name) in LEGACY_TYPES {
            let layer = format!("#usda 1.0\ndef \"A\"\n{{\n    {legacy}[] x = []\n}}\n");
            let out = tolerated(&layer);
            assert_eq!(
                out,
                format!("#usda 1.0\ndef \"A\"\n{{\n    {name}[] x = []\n}}\n")
            );
            assert!(openusd::usda::parse(&layer).is_err(), "{legacy}");
            openusd::usda::parse(&out).unwrap_or_else(|e| panic!("{name}: {e}"));
        }
    }

    #[test]
    fn text_checks_accept_real_layers_and_refuse_runaway_paths_and_nesting() {
        let good = "#usda 1.0\n(\n  doc = \"a <b> (\"\n)\n# a comment with <\ndef \"A\" {\n  rel r = </A/B.c:d>\n  rel s = <../B{v=x}C.rel[/D].e>\n}\n";
        assert_eq!(check_text(good.as_bytes()), Ok(()));
        let runaway = "#usda 1.0\ndef \"A\" {\n  rel r = </ME\n}\n";
        assert!(
            check_text(runaway.as_bytes())
                .unwrap_err()
                .contains("line 3")
        );
        let deep = format!(
            "#usda 1.0\n{}{}",
            "[".repeat(MAX_DEPTH + 1),
            "]".repeat(MAX_DEPTH + 1)
        );
        assert!(check_text(deep.as_bytes()).unwrap_err().contains("nest"));
        assert!(check_text(b"not usd").is_err());
    }
}
