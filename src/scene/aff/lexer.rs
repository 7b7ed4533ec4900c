//! Tokenizer: AFF bytes -> whitespace-separated tokens with their line numbers.
//!
//! Rules (FORMAT.md 1.1): the input is bytes (Latin-1 in comments is fine, nothing is
//! decoded as UTF-8); separators are ASCII whitespace (space, `\t`, `\r`, `\n`, `\f`, `\v`);
//! `#` and `%` start a comment that runs to the end of the line, wherever they appear (also
//! right after a token: `300%comment`); `{` and `}` are tokens of their own even when glued
//! to others. One pass over the bytes, no allocation: tokens borrow the input.

/// One token: its bytes and the 1-based line it starts on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Token<'a> {
    pub text: &'a [u8],
    pub line: u32,
}

impl Token<'_> {
    /// The token as text, bytes read as Latin-1 (for messages and names).
    pub fn to_text(&self) -> String {
        latin1(self.text)
    }
}

/// Bytes read as Latin-1 (every byte is the code point of the same value).
pub fn latin1(bytes: &[u8]) -> String {
    bytes.iter().map(|&b| b as char).collect()
}

/// A cursor over the tokens of one file. `Clone` is cheap (a position), which is how
/// [`Lexer::peek`] looks ahead.
#[derive(Debug, Clone)]
pub struct Lexer<'a> {
    bytes: &'a [u8],
    pos: usize,
    line: u32,
}

fn is_space(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\r' | b'\n' | 0x0b | 0x0c)
}

fn ends_token(b: u8) -> bool {
    is_space(b) || matches!(b, b'{' | b'}' | b'#' | b'%')
}

impl<'a> Lexer<'a> {
    pub fn new(bytes: &'a [u8]) -> Self {
        Lexer {
            bytes,
            pos: 0,
            line: 1,
        }
    }

    /// The line the cursor is on (after the last token read): for end-of-file messages.
    pub fn line(&self) -> u32 {
        self.line
    }

    /// The next token, or `None` at the end of the input.
    pub fn next_token(&mut self) -> Option<Token<'a>> {
        let bytes = self.bytes;
        loop {
            let &b = bytes.get(self.pos)?;
            if b == b'\n' {
                self.line += 1;
                self.pos += 1;
            } else if is_space(b) {
                self.pos += 1;
            } else if b == b'#' || b == b'%' {
                // Comment to the end of the line (the newline itself is counted above).
                while self.pos < bytes.len() && bytes[self.pos] != b'\n' {
                    self.pos += 1;
                }
            } else {
                break;
            }
        }
        let start = self.pos;
        let line = self.line;
        if matches!(bytes[start], b'{' | b'}') {
            self.pos += 1;
        } else {
            while self.pos < bytes.len() && !ends_token(bytes[self.pos]) {
                self.pos += 1;
            }
        }
        Some(Token {
            text: &bytes[start..self.pos],
            line,
        })
    }

    /// The next token without consuming it.
    pub fn peek(&self) -> Option<Token<'a>> {
        self.clone().next_token()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tokens(input: &[u8]) -> Vec<(String, u32)> {
        let mut lexer = Lexer::new(input);
        std::iter::from_fn(|| lexer.next_token())
            .map(|t| (t.to_text(), t.line))
            .collect()
    }

    #[test]
    fn splits_comments_braces_crlf() {
        let got = tokens(b"a -1.0 5.0 300  % the last\r\nx wheel{\r\n# f\xf6rslag\n}%c\n\tk");
        let want = [
            ("a", 1),
            ("-1.0", 1),
            ("5.0", 1),
            ("300", 1),
            ("x", 2),
            ("wheel", 2),
            ("{", 2),
            ("}", 4),
            ("k", 5),
        ];
        let want: Vec<(String, u32)> = want.iter().map(|(s, l)| (s.to_string(), *l)).collect();
        assert_eq!(got, want);
    }

    #[test]
    fn comment_glued_to_token_and_latin1_names() {
        let got = tokens(b"300%x\nna\xefve.ppm#y");
        assert_eq!(got, vec![("300".into(), 1), ("na\u{ef}ve.ppm".into(), 2)]);
        assert!(tokens(b"  % only a comment").is_empty());
    }
}
