//! One policy for the text people type that other people read (on the dashboard, in a
//! terminal through the CLI, in an exported statement), on every path it comes in by: the
//! forms, the API, the hub's imports and the CLI all reach the store, which checks it here.
//!
//! - A **label** (a name of a cohort, curriculum, module, exercise, scene or station token):
//!   trimmed, 1 to `max` characters, no control characters and no invisible characters that
//!   reorder or hide text (bidirectional overrides and isolates, zero-width characters, the
//!   byte-order mark: [`hidden`]).
//! - A **text** (a description, a note, a comment, a reason): up to `max` characters, may be
//!   empty and span lines (line feeds, carriage returns and tabs), otherwise as a label.
//!
//! User names have a stricter rule of their own ([`super::names`]).

use crate::error::{AssessError, Result};

/// The longest label, in characters.
pub const MAX_LABEL_CHARS: usize = 200;
/// The longest description of an exercise or curriculum, in characters.
pub const MAX_DESCRIPTION_CHARS: usize = 2000;
/// The longest note or comment, in characters.
pub const MAX_NOTE_CHARS: usize = 4000;

/// Characters that change how the text around them is shown while showing nothing
/// themselves: bidirectional marks, embeddings, overrides and isolates, zero-width
/// characters and the byte-order mark.
pub fn hidden(c: char) -> bool {
    matches!(
        c,
        '\u{061C}'
            | '\u{200B}'..='\u{200F}'
            | '\u{202A}'..='\u{202E}'
            | '\u{2060}'..='\u{2069}'
            | '\u{FEFF}'
    )
}

fn refuse(what: &str, why: String) -> AssessError {
    AssessError::InvalidInput(format!("{what}: {why}"))
}

/// The first character of `s` that no label or text may hold (`lines`: line breaks and tabs
/// are allowed).
fn forbidden(s: &str, lines: bool) -> Option<char> {
    s.chars().find(|&c| {
        let spacing = matches!(c, '\n' | '\r' | '\t');
        (c.is_control() && !(lines && spacing)) || hidden(c)
    })
}

fn check(what: &str, s: &str, max: usize, lines: bool) -> Result<()> {
    let count = s.chars().count();
    if count > max {
        return Err(refuse(what, format!("{count} characters, at most {max}")));
    }
    if let Some(c) = forbidden(s, lines) {
        return Err(refuse(
            what,
            format!(
                "the character {} is not allowed (control and invisible characters)",
                c.escape_unicode()
            ),
        ));
    }
    Ok(())
}

/// `s` trimmed if it is a label of 1 to `max` characters (see the module documentation).
pub fn label<'a>(what: &str, s: &'a str, max: usize) -> Result<&'a str> {
    let s = s.trim();
    if s.is_empty() {
        return Err(refuse(what, "empty".into()));
    }
    check(what, s, max, false)?;
    Ok(s)
}

/// `s` trimmed if it is a text of at most `max` characters (see the module documentation).
pub fn text<'a>(what: &str, s: &'a str, max: usize) -> Result<&'a str> {
    let s = s.trim();
    check(what, s, max, true)?;
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_are_one_line_of_visible_characters() {
        assert_eq!(
            label("a cohort", "  spring 2027 ", 64).unwrap(),
            "spring 2027"
        );
        assert!(label("a cohort", "Ärzte – Kohorte «B»", 64).is_ok());
        for bad in [
            "",
            "  ",
            "esc\u{1b}[2J",
            "nul\0",
            "bell\u{7}",
            "two\nlines",
            "rtl\u{202e}txt.exe",
            "iso\u{2067}late",
            "zero\u{200b}width",
            "bom\u{feff}",
        ] {
            let e = label("a cohort", bad, 64).unwrap_err().to_string();
            assert!(e.contains("a cohort: "), "{bad:?}: {e}");
        }
        assert!(label("x", &"x".repeat(64), 64).is_ok());
        let long = label("x", &"x".repeat(100_000), 64)
            .unwrap_err()
            .to_string();
        assert!(
            long.contains("100000 characters") && long.len() < 100,
            "{long}"
        );
    }

    #[test]
    fn texts_may_span_lines_and_be_empty() {
        assert_eq!(
            text("a note", " line one\r\n\tline two ", 100).unwrap(),
            "line one\r\n\tline two"
        );
        assert_eq!(text("a note", "", 100).unwrap(), "");
        for bad in ["nul\0", "esc\u{1b}", "bell\u{7}", "a\u{202d}b", "del\u{7f}"] {
            assert!(text("a note", bad, 100).is_err(), "{bad:?}");
        }
        assert!(text("a description", &"é".repeat(2001), MAX_DESCRIPTION_CHARS).is_err());
        assert!(text("a description", &"é".repeat(2000), MAX_DESCRIPTION_CHARS).is_ok());
    }
}
