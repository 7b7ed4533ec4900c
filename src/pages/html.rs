//! The pieces every page is built from: escaping, the document shell with the inline CSS
//! and JavaScript, embedded JSON data, links relative to the page, and readers for the CSV
//! and Markdown files the pages show.
//!
//! Invariant: a page is one file that needs nothing but the files it links, which are
//! addressed relative to the page's folder, so the folder can be copied or opened from
//! `file://` as it is.

use std::fmt::Write as _;
use std::path::{Component, Path, PathBuf};

use percent_encoding::{AsciiSet, CONTROLS, utf8_percent_encode};

use super::PageError;

const PAGE_CSS: &str = include_str!("assets/page.css");
const COMMON_JS: &str = include_str!("assets/common.js");

pub use crate::markup::escape;

/// A complete HTML document: the shared style and script, then `body`, then the page's own
/// script (which runs after the body is parsed).
pub fn document(title: &str, body: &str, page_js: &str) -> String {
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>{title}</title>\n<style>\n{PAGE_CSS}</style>\n<script>\n{COMMON_JS}</script>\n\
         </head>\n<body>\n{body}\n<script>\n{page_js}</script>\n</body>\n</html>\n",
        title = escape(title)
    )
}

/// `value` as JSON inside `<script type="application/json" id=...>`; `</` is escaped so the
/// data cannot close the script element early.
pub fn json_data(id: &str, value: &serde_json::Value) -> String {
    let text = value.to_string().replace("</", "<\\/");
    format!("<script type=\"application/json\" id=\"{id}\">{text}</script>\n")
}

/// Characters escaped in a URL path segment (`/` is added between segments).
const SEGMENT: &AsciiSet = &CONTROLS
    .add(b' ')
    .add(b'"')
    .add(b'#')
    .add(b'%')
    .add(b'<')
    .add(b'>')
    .add(b'?')
    .add(b'`')
    .add(b'{')
    .add(b'}')
    .add(b'/')
    .add(b'\\');

/// The URL of `file` relative to the folder `page_dir` (`../a/frame_0001.png`), percent-
/// encoded. Both are resolved against the file system first, so `.`/`..` and symlinks do not
/// matter; without a common root (another drive) an absolute `file://` URL.
///
/// # Errors
/// `page_dir` or `file` does not exist.
pub fn relative_url(page_dir: &Path, file: &Path) -> Result<String, PageError> {
    let from = canonical(page_dir)?;
    let to = canonical(file)?;
    let (from_parts, to_parts) = (parts(&from), parts(&to));
    if from_parts.first() != to_parts.first() {
        let segments: Vec<String> = to_parts.iter().skip(1).map(|s| encode(s)).collect();
        return Ok(format!("file:///{}", segments.join("/")));
    }
    let common = from_parts
        .iter()
        .zip(&to_parts)
        .take_while(|(a, b)| a == b)
        .count();
    let mut segments: Vec<String> = vec!["..".to_string(); from_parts.len() - common];
    segments.extend(to_parts[common..].iter().map(|s| encode(s)));
    Ok(segments.join("/"))
}

fn canonical(path: &Path) -> Result<PathBuf, PageError> {
    path.canonicalize().map_err(|source| PageError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// The path's components as strings, the root (or drive prefix) first.
fn parts(path: &Path) -> Vec<String> {
    path.components()
        .filter(|c| !matches!(c, Component::CurDir))
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect()
}

fn encode(segment: &str) -> String {
    utf8_percent_encode(segment, SEGMENT).to_string()
}

/// A CSV file as rows of fields (RFC 4180 quoting: `"a,b"`, `""` for a quote), header first.
///
/// # Errors
/// The file cannot be read, is empty, or a row has a different number of fields than the
/// header (the error names the file and the line).
pub fn read_csv(path: &Path) -> Result<Vec<Vec<String>>, PageError> {
    let text = std::fs::read_to_string(path).map_err(|source| PageError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let rows: Vec<Vec<String>> = text
        .lines()
        .filter(|l| !l.is_empty())
        .map(csv_fields)
        .collect();
    let Some(header) = rows.first() else {
        return Err(PageError::input(path, "empty CSV file (no header)"));
    };
    if let Some(bad) = rows.iter().position(|r| r.len() != header.len()) {
        return Err(PageError::input(
            path,
            format!(
                "line {}: {} fields, the header has {}",
                bad + 1,
                rows[bad].len(),
                header.len()
            ),
        ));
    }
    Ok(rows)
}

fn csv_fields(line: &str) -> Vec<String> {
    let mut fields = vec![String::new()];
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        let field = fields.last_mut().expect("starts with one field");
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                field.push('"');
                chars.next();
            }
            ('"', _) => quoted = !quoted,
            (',', false) => fields.push(String::new()),
            (c, _) => field.push(c),
        }
    }
    fields
}

/// An HTML table of `rows` (the first row is the header). Each body row gets
/// `data-key="<value of column key_column>"` so scripts can find it.
pub fn table(id: &str, rows: &[Vec<String>], key_column: usize) -> String {
    let mut html = format!("<table id=\"{id}\">\n");
    if let Some((header, body)) = rows.split_first() {
        html.push_str("<tr>");
        for cell in header {
            let _ = write!(html, "<th>{}</th>", escape(cell));
        }
        html.push_str("</tr>\n");
        for row in body {
            let key = row.get(key_column).map_or(String::new(), |k| escape(k));
            let _ = write!(html, "<tr data-key=\"{key}\">");
            for cell in row {
                let _ = write!(html, "<td>{}</td>", escape(cell));
            }
            html.push_str("</tr>\n");
        }
    }
    html.push_str("</table>\n");
    html
}

/// The subset of Markdown that mipray writes (`#` headings, `|` tables, paragraphs with
/// `` `code` `` and `**bold**`) as HTML; headings are shifted down one level (`#` -> h2).
pub fn markdown(text: &str) -> String {
    let mut html = String::new();
    let mut table_rows: Vec<Vec<String>> = Vec::new();
    for line in text.lines().chain(std::iter::once("")) {
        let trimmed = line.trim();
        if trimmed.starts_with('|') {
            let cells: Vec<String> = trimmed
                .trim_matches('|')
                .split('|')
                .map(|c| c.trim().to_string())
                .collect();
            // The alignment row (`| :--- | ---: |`) carries no data.
            if !cells
                .iter()
                .all(|c| !c.is_empty() && c.chars().all(|ch| "-: ".contains(ch)))
            {
                table_rows.push(cells);
            }
            continue;
        }
        if !table_rows.is_empty() {
            html.push_str(&markdown_table(&table_rows));
            table_rows.clear();
        }
        let level = trimmed.chars().take_while(|&c| c == '#').count();
        if level > 0 && trimmed[level..].starts_with(' ') {
            let h = (level + 1).min(6);
            let _ = writeln!(html, "<h{h}>{}</h{h}>", inline(trimmed[level..].trim()));
        } else if !trimmed.is_empty() {
            let _ = writeln!(html, "<p>{}</p>", inline(trimmed));
        }
    }
    html
}

fn markdown_table(rows: &[Vec<String>]) -> String {
    let mut html = String::from("<table>\n");
    for (i, row) in rows.iter().enumerate() {
        let tag = if i == 0 { "th" } else { "td" };
        html.push_str("<tr>");
        for cell in row {
            let _ = write!(html, "<{tag}>{}</{tag}>", inline(cell));
        }
        html.push_str("</tr>\n");
    }
    html.push_str("</table>\n");
    html
}

/// `` `code` `` and `**bold**` inside escaped text.
fn inline(text: &str) -> String {
    let mut html = String::new();
    for (i, piece) in escape(text).split('`').enumerate() {
        if i % 2 == 1 {
            let _ = write!(html, "<code>{piece}</code>");
            continue;
        }
        for (j, part) in piece.split("**").enumerate() {
            if j % 2 == 1 {
                let _ = write!(html, "<strong>{part}</strong>");
            } else {
                html.push_str(part);
            }
        }
    }
    html
}

/// The text of an SVG file without its XML declaration, for inlining into a page.
///
/// # Errors
/// The file cannot be read or does not contain an `<svg` element.
pub fn inline_svg(path: &Path) -> Result<String, PageError> {
    let text = std::fs::read_to_string(path).map_err(|source| PageError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let start = text
        .find("<svg")
        .ok_or_else(|| PageError::input(path, "no <svg> element"))?;
    Ok(text[start..].to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escapes_markup_and_quotes() {
        assert_eq!(
            escape("<a href=\"x\">&'"),
            "&lt;a href=&quot;x&quot;&gt;&amp;&#39;"
        );
    }

    #[test]
    fn embedded_json_cannot_close_its_script() {
        let html = json_data("d", &serde_json::json!({"s": "</script><b>"}));
        assert_eq!(html.matches("</script>").count(), 1, "{html}");
        assert!(html.contains("<\\/script>"));
    }

    #[test]
    fn csv_fields_follow_rfc4180_quoting() {
        assert_eq!(
            csv_fields("a,\"b,c\",\"d\"\"e\","),
            ["a", "b,c", "d\"e", ""]
        );
    }

    #[test]
    fn csv_with_a_short_row_names_the_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.csv");
        std::fs::write(&path, "a,b\n1,2\n3\n").unwrap();
        let message = read_csv(&path).unwrap_err().to_string();
        assert!(
            message.contains("x.csv") && message.contains("line 3"),
            "{message}"
        );
    }

    #[test]
    fn relative_urls_climb_out_of_the_page_folder_and_encode_names() {
        let dir = tempfile::tempdir().unwrap();
        let page = dir.path().join("out/diff");
        let frames = dir.path().join("out/a b");
        std::fs::create_dir_all(&page).unwrap();
        std::fs::create_dir_all(&frames).unwrap();
        let file = frames.join("frame_0001.png");
        std::fs::write(&file, b"x").unwrap();
        assert_eq!(
            relative_url(&page, &file).unwrap(),
            "../a%20b/frame_0001.png"
        );
        assert_eq!(
            relative_url(&frames, &file).unwrap(),
            "frame_0001.png",
            "a file in the page's own folder"
        );
        assert!(relative_url(&page, &frames.join("missing.png")).is_err());
    }

    #[test]
    fn markdown_tables_headings_and_inline_marks_become_html() {
        let html = markdown("# Title\n\n**Bold** `x<y`\n\n| a | b |\n| :--- | ---: |\n| 1 | 2 |\n");
        assert!(html.contains("<h2>Title</h2>"), "{html}");
        assert!(
            html.contains("<strong>Bold</strong> <code>x&lt;y</code>"),
            "{html}"
        );
        assert!(html.contains("<tr><th>a</th><th>b</th></tr>"), "{html}");
        assert!(html.contains("<tr><td>1</td><td>2</td></tr>"), "{html}");
        assert!(!html.contains(":---"), "{html}");
    }
}
