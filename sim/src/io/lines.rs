//! The one tokenizer shared by the text readers: a cursor over the lines and
//! whitespace-separated tokens of a file that knows the 1-based line number of everything it
//! hands out, so every parse error can name the file and the line.
//!
//! Two ways to read, which may be mixed: line by line ([`Cursor::next_line`], for formats
//! with one record per line such as Gmsh and TetGen) and token by token across lines
//! ([`Cursor::token`], for formats whose arrays wrap freely such as VTK).

use std::path::Path;
use std::str::FromStr;

use crate::ReadError;

/// Upper bound for `Vec::with_capacity` taken from counts in file headers: a corrupt or
/// hostile header must not make us allocate gigabytes up front. Vectors still grow past it.
pub(crate) const MAX_PREALLOC: usize = 1 << 16;

/// `n` capped to [`MAX_PREALLOC`], for preallocating from an untrusted count.
pub(crate) fn capped(n: usize) -> usize {
    n.min(MAX_PREALLOC)
}

/// A parse error at `line` of `path`.
pub(crate) fn parse_error(path: &Path, line: usize, message: impl Into<String>) -> ReadError {
    ReadError::Parse {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

/// Shortens a token for quoting in an error message.
pub(crate) fn quoted(token: &str) -> String {
    const MAX: usize = 40;
    match token.char_indices().nth(MAX) {
        Some((cut, _)) => format!("`{}...`", &token[..cut]),
        None => format!("`{token}`"),
    }
}

/// Parses `token` as a `T`, naming `what` in the error.
pub(crate) fn parse_token<T: FromStr>(
    path: &Path,
    line: usize,
    token: &str,
    what: &str,
) -> Result<T, ReadError> {
    token
        .parse()
        .map_err(|_| parse_error(path, line, format!("invalid {what} {}", quoted(token))))
}

/// Parses `token` as a finite `f64` (NaN and infinities are errors).
pub(crate) fn parse_finite(
    path: &Path,
    line: usize,
    token: &str,
    what: &str,
) -> Result<f64, ReadError> {
    let v: f64 = parse_token(path, line, token, what)?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(parse_error(
            path,
            line,
            format!("{what} is not finite: {}", quoted(token)),
        ))
    }
}

/// One whitespace-separated token and the line it is on.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Token<'a> {
    pub line: usize,
    pub text: &'a str,
}

/// Splits the first whitespace-separated token off `s`: `(token, rest)`.
fn split_token(s: &str) -> Option<(&str, &str)> {
    let s = s.trim_start_matches(|c: char| c.is_ascii_whitespace());
    if s.is_empty() {
        return None;
    }
    let end = s.find(|c: char| c.is_ascii_whitespace()).unwrap_or(s.len());
    Some((&s[..end], &s[end..]))
}

/// A cursor over the lines and tokens of a text.
#[derive(Debug)]
pub(crate) struct Cursor<'a> {
    path: &'a Path,
    /// Text after the current line.
    rest: &'a str,
    /// Number of the current line; one less than the first line before anything was read.
    line: usize,
    /// Unread part of the current line (comments removed).
    current: &'a str,
    /// Everything from this character to the end of a line is a comment.
    comment: Option<char>,
}

impl<'a> Cursor<'a> {
    /// A cursor at the start of `text`, the contents of `path`.
    pub fn new(text: &'a str, path: &'a Path) -> Self {
        Self::starting_at_line(text, path, 1)
    }

    /// A cursor over `text`, an excerpt of `path` whose first character is on line
    /// `first_line` (used for the contents of XML elements).
    pub fn starting_at_line(text: &'a str, path: &'a Path, first_line: usize) -> Self {
        Self {
            path,
            rest: text,
            line: first_line.saturating_sub(1),
            current: "",
            comment: None,
        }
    }

    /// Treats everything from `c` to the end of a line as a comment.
    pub fn with_comments(mut self, c: char) -> Self {
        self.comment = Some(c);
        self
    }

    /// The file being read.
    pub fn path(&self) -> &'a Path {
        self.path
    }

    /// A parse error at `line`.
    pub fn error(&self, line: usize, message: impl Into<String>) -> ReadError {
        parse_error(self.path, line, message)
    }

    /// The line number to report for "unexpected end of file": the line after the last one
    /// read.
    pub fn eof_line(&self) -> usize {
        self.line + 1
    }

    /// An "unexpected end of file" error saying what was expected.
    pub fn eof_error(&self, expected: &str) -> ReadError {
        self.error(
            self.eof_line(),
            format!("unexpected end of file: expected {expected}"),
        )
    }

    /// The next raw line (line ending removed, comments kept, blank lines included),
    /// discarding unread tokens of the current line. For lines whose position matters even
    /// when blank, such as the title line of a legacy VTK file.
    pub fn raw_line(&mut self) -> Option<(usize, &'a str)> {
        if self.rest.is_empty() {
            return None;
        }
        let (line, rest) = match self.rest.find('\n') {
            Some(i) => (&self.rest[..i], &self.rest[i + 1..]),
            None => (self.rest, ""),
        };
        self.rest = rest;
        self.line += 1;
        self.current = "";
        Some((self.line, line.strip_suffix('\r').unwrap_or(line)))
    }

    /// The next line that is not blank after removing comments, trimmed, discarding unread
    /// tokens of the current line (including a token only peeked at). `None` at the end of
    /// the text.
    pub fn next_line(&mut self) -> Option<Line<'a>> {
        while let Some((no, raw)) = self.raw_line() {
            let text = match self.comment.and_then(|c| raw.find(c)) {
                Some(i) => &raw[..i],
                None => raw,
            }
            .trim();
            if !text.is_empty() {
                return Some(Line::new(self.path, no, text));
            }
        }
        None
    }

    /// Like [`Cursor::next_line`], but the end of the text is an error saying `expected`.
    pub fn line(&mut self, expected: &str) -> Result<Line<'a>, ReadError> {
        self.next_line().ok_or_else(|| self.eof_error(expected))
    }

    /// The unread tokens of the current line, as a [`Line`]; they count as read.
    pub fn rest_of_line(&mut self) -> Line<'a> {
        let rest = std::mem::take(&mut self.current);
        Line::new(self.path, self.line, rest.trim())
    }

    /// The next token without consuming it, crossing lines as needed.
    pub fn peek_token(&mut self) -> Option<Token<'a>> {
        loop {
            if let Some((text, _)) = split_token(self.current) {
                return Some(Token {
                    line: self.line,
                    text,
                });
            }
            let line = self.next_line()?;
            self.current = line.text;
        }
    }

    /// The next token, crossing lines as needed. `None` at the end of the text.
    pub fn next_token(&mut self) -> Option<Token<'a>> {
        let token = self.peek_token()?;
        if let Some((_, rest)) = split_token(self.current) {
            self.current = rest;
        }
        Some(token)
    }

    /// The next token, or an error saying `expected` at the end of the text.
    pub fn token(&mut self, expected: &str) -> Result<Token<'a>, ReadError> {
        self.next_token().ok_or_else(|| self.eof_error(expected))
    }

    /// The next token parsed as a `T`, with its line.
    pub fn parse<T: FromStr>(&mut self, what: &str) -> Result<(T, usize), ReadError> {
        let t = self.token(what)?;
        Ok((parse_token(self.path, t.line, t.text, what)?, t.line))
    }

    /// The next token parsed as a finite `f64`.
    pub fn finite(&mut self, what: &str) -> Result<f64, ReadError> {
        let t = self.token(what)?;
        parse_finite(self.path, t.line, t.text, what)
    }
}

/// One line of a file and its unread tokens.
#[derive(Debug, Clone)]
pub(crate) struct Line<'a> {
    path: &'a Path,
    /// 1-based line number.
    pub no: usize,
    /// The (trimmed, comment-free) text of the line.
    pub text: &'a str,
    /// Unread part of `text`.
    rest: &'a str,
}

impl<'a> Line<'a> {
    fn new(path: &'a Path, no: usize, text: &'a str) -> Self {
        Self {
            path,
            no,
            text,
            rest: text,
        }
    }

    /// A parse error on this line.
    pub fn error(&self, message: impl Into<String>) -> ReadError {
        parse_error(self.path, self.no, message)
    }

    /// The next token, if any.
    pub fn next_token(&mut self) -> Option<&'a str> {
        let (token, rest) = split_token(self.rest)?;
        self.rest = rest;
        Some(token)
    }

    /// The next token, or an error saying the line ends before `what`.
    pub fn token(&mut self, what: &str) -> Result<&'a str, ReadError> {
        self.next_token()
            .ok_or_else(|| self.error(format!("line ends early: expected {what}")))
    }

    /// The next token parsed as a `T`.
    pub fn parse<T: FromStr>(&mut self, what: &str) -> Result<T, ReadError> {
        let t = self.token(what)?;
        parse_token(self.path, self.no, t, what)
    }

    /// The next token, if any, parsed as a `T`.
    pub fn parse_opt<T: FromStr>(&mut self, what: &str) -> Result<Option<T>, ReadError> {
        match self.next_token() {
            Some(t) => parse_token(self.path, self.no, t, what).map(Some),
            None => Ok(None),
        }
    }

    /// The next token parsed as a finite `f64`.
    pub fn finite(&mut self, what: &str) -> Result<f64, ReadError> {
        let t = self.token(what)?;
        parse_finite(self.path, self.no, t, what)
    }

    /// Checks that no token is left; `after` names what the line should have ended with.
    pub fn finish(&mut self, after: &str) -> Result<(), ReadError> {
        match self.next_token() {
            None => Ok(()),
            Some(t) => Err(self.error(format!(
                "unexpected extra value {} after {after}",
                quoted(t)
            ))),
        }
    }
}
