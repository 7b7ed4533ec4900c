//! Typed reads over the tokens of one file, with `file:line:` error messages.

use glam::{Vec2, Vec3};

use super::lexer::{Lexer, Token};

/// The tokens of one file plus its display name (for messages).
pub struct Reader<'a> {
    pub lexer: Lexer<'a>,
    pub name: &'a str,
}

impl<'a> Reader<'a> {
    pub fn new(bytes: &'a [u8], name: &'a str) -> Self {
        Reader {
            lexer: Lexer::new(bytes),
            name,
        }
    }

    /// `name:line: message`.
    pub fn error_at(&self, line: u32, message: impl std::fmt::Display) -> String {
        format!("{}:{line}: {message}", self.name)
    }

    pub fn next(&mut self) -> Option<Token<'a>> {
        self.lexer.next_token()
    }

    pub fn peek(&self) -> Option<Token<'a>> {
        self.lexer.peek()
    }

    /// The next token; at the end of the file an error saying what was expected.
    pub fn token(&mut self, what: &str, after: &str) -> Result<Token<'a>, String> {
        match self.lexer.next_token() {
            Some(t) => Ok(t),
            None => Err(self.error_at(
                self.lexer.line(),
                format!("expected {what} after '{after}', found the end of the file"),
            )),
        }
    }

    /// A finite C `%f`-style number (`1.6699999E-4`, `0.`, `-.5`).
    pub fn number(&mut self, after: &str) -> Result<f32, String> {
        let t = self.token("a number", after)?;
        parse_number(t.text).ok_or_else(|| {
            let text = t.to_text();
            // A number f64 reads that f32 cannot hold (or a NaN): said as such.
            let problem = match text.parse::<f64>() {
                Ok(x) if x.is_nan() => "not a number (NaN)",
                Ok(_) => "outside the range of single precision (about ±3.4e38)",
                Err(_) => "not a number",
            };
            self.error_at(
                t.line,
                format!("expected a number after '{after}', found '{text}': {problem}"),
            )
        })
    }

    /// A non-negative integer (`%d`) no larger than `max`.
    pub fn count(&mut self, after: &str, max: usize) -> Result<usize, String> {
        let t = self.token("a count", after)?;
        let text = std::str::from_utf8(t.text).unwrap_or("");
        match text.parse::<i64>() {
            Ok(n) if n >= 0 && (n as u64) <= max as u64 => Ok(n as usize),
            Ok(n) => Err(self.error_at(
                t.line,
                format!("count {n} after '{after}' is out of range (0..={max})"),
            )),
            Err(_) => Err(self.error_at(
                t.line,
                format!(
                    "expected an integer after '{after}', found '{}'",
                    t.to_text()
                ),
            )),
        }
    }

    /// An integer (`%d`, may be negative).
    pub fn int(&mut self, after: &str) -> Result<i64, String> {
        let t = self.token("an integer", after)?;
        let text = std::str::from_utf8(t.text).unwrap_or("");
        text.parse::<i64>().map_err(|_| {
            self.error_at(
                t.line,
                format!(
                    "expected an integer after '{after}', found '{}'",
                    t.to_text()
                ),
            )
        })
    }

    pub fn vec3(&mut self, after: &str) -> Result<Vec3, String> {
        Ok(Vec3::new(
            self.number(after)?,
            self.number(after)?,
            self.number(after)?,
        ))
    }

    /// Three numbers of 0 or more after `after`: a colour (a light's, the background's, the
    /// ambient light's). A negative component is an error naming its line: a light of
    /// negative power has no meaning, and its shading would subtract light.
    pub fn colour(&mut self, after: &str) -> Result<Vec3, String> {
        let line = self.peek().map_or(0, |t| t.line);
        let colour = self.vec3(after)?;
        if colour.min_element() < 0.0 {
            return Err(self.error_at(
                line,
                format!(
                    "'{after}' colour {:?} has a negative component (colours are 0 or more)",
                    colour.to_array()
                ),
            ));
        }
        Ok(colour)
    }

    pub fn vec2(&mut self, after: &str) -> Result<Vec2, String> {
        Ok(Vec2::new(self.number(after)?, self.number(after)?))
    }

    /// A name token (transform, texture, include file), read as Latin-1.
    pub fn name(&mut self, after: &str) -> Result<(String, u32), String> {
        let t = self.token("a name", after)?;
        if t.text == b"{" || t.text == b"}" {
            return Err(self.error_at(
                t.line,
                format!("expected a name after '{after}', found '{}'", t.to_text()),
            ));
        }
        Ok((t.to_text(), t.line))
    }

    /// Exactly the token `word`.
    pub fn expect(&mut self, word: &str, after: &str) -> Result<u32, String> {
        let t = self.token(&format!("'{word}'"), after)?;
        if t.text != word.as_bytes() {
            return Err(self.error_at(
                t.line,
                format!("expected '{word}' after '{after}', found '{}'", t.to_text()),
            ));
        }
        Ok(t.line)
    }

    /// Whether the next token is a number (optional trailing arguments such as a light's
    /// colour: no command starts with a digit, sign or dot).
    pub fn next_is_number(&self) -> bool {
        self.peek().is_some_and(|t| parse_number(t.text).is_some())
    }

    /// Consumes the next token if it is exactly `word`.
    pub fn accept(&mut self, word: &str) -> bool {
        if self.peek().is_some_and(|t| t.text == word.as_bytes()) {
            self.next();
            true
        } else {
            false
        }
    }
}

/// A finite number in C `%f` syntax, else `None` (`inf`, `nan` and words are rejected).
pub fn parse_number(text: &[u8]) -> Option<f32> {
    let first = *text.first()?;
    if !(first.is_ascii_digit() || matches!(first, b'-' | b'+' | b'.')) {
        return None;
    }
    let s = std::str::from_utf8(text).ok()?;
    s.parse::<f32>().ok().filter(|x| x.is_finite())
}
