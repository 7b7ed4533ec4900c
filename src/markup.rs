//! Escaping text for XML and HTML (element content and double- or single-quoted
//! attributes), shared by the JUnit report and the HTML pages.

/// `text` with `& < > " '` replaced by entities (`'` as `&#39;`, valid in XML and HTML
/// alike) and the control characters XML forbids dropped (tab and line breaks kept).
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c if (c as u32) < 0x20 && c != '\n' && c != '\t' && c != '\r' => {}
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escapes_markup_quotes_and_drops_forbidden_controls() {
        assert_eq!(
            escape("a<b>&\"c'\u{1}\t\n"),
            "a&lt;b&gt;&amp;&quot;c&#39;\t\n"
        );
    }
}
