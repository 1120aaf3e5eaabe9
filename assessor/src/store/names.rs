//! What a user's name may be: names reach other people's screens (the dashboard, a hub's
//! operator's terminal through `cutlab user list`) and tell staff from trainees, so they are
//! short, printable, and never a look-alike of another user's.

use crate::error::{AssessError, Result};

/// The longest user name, in characters.
pub const MAX_NAME_CHARS: usize = 64;

/// The characters a name may hold besides letters and digits (of any script).
const SEPARATORS: &[char] = &[' ', '.', '-', '_', '\''];

/// `name` trimmed, if it is a name a user may have: 1 to [`MAX_NAME_CHARS`] characters,
/// letters and digits of any script, and the separators `space . - _ '` (so no control or
/// format characters, and no Unicode dashes or other punctuation that only look like a
/// hyphen).
pub fn check_name(name: &str) -> Result<&str> {
    let name = name.trim();
    let bad = |why: &str| {
        let shown: String = name.chars().take(MAX_NAME_CHARS).collect();
        Err(AssessError::InvalidInput(format!(
            "the user name {:?}: {why}",
            shown.escape_default().to_string()
        )))
    };
    let count = name.chars().count();
    if count == 0 {
        return bad("empty");
    }
    if count > MAX_NAME_CHARS {
        return bad(&format!("more than {MAX_NAME_CHARS} characters"));
    }
    if let Some(c) = name
        .chars()
        .find(|&c| !(c.is_alphanumeric() || SEPARATORS.contains(&c)))
    {
        return bad(&format!(
            "{:?} is not allowed (letters, digits, space . - _ ' only)",
            c.escape_unicode().to_string()
        ));
    }
    Ok(name)
}

/// What two names that look alike have in common: lower case, separators dropped
/// (`DR-KIM`, `dr kim` and `dr_kim` are all `drkim`).
pub fn skeleton(name: &str) -> String {
    name.chars()
        .filter(|c| !SEPARATORS.contains(c))
        .flat_map(char::to_lowercase)
        .collect()
}

/// `name` safe to print on a terminal or a page as it is: control characters and the
/// invisible ones that reorder or hide text (bidirectional overrides, zero-width) shown as
/// U+FFFD. For names stored before [`check_name`] kept them out.
pub fn printable(name: &str) -> String {
    name.chars()
        .map(|c| {
            let hidden = matches!(c, '\u{200B}'..='\u{200F}' | '\u{202A}'..='\u{202E}' | '\u{2066}'..='\u{2069}' | '\u{FEFF}');
            if c.is_control() || hidden { '\u{FFFD}' } else { c }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_printable_and_short() {
        assert_eq!(check_name("  ana  ").ok(), Some("ana"));
        assert!(check_name("José O'Neil-Smith").is_ok());
        assert!(check_name("dr.kim_2").is_ok());
        for bad in [
            "",
            "   ",
            "ana\u{1b}[2J",
            "line\nbreak",
            "dr\u{2010}kim",
            "zero\u{200b}width",
            "a;b",
            "<script>",
        ] {
            assert!(check_name(bad).is_err(), "{bad:?}");
        }
        assert!(check_name(&"x".repeat(MAX_NAME_CHARS)).is_ok());
        let long = check_name(&"x".repeat(2_000_000)).unwrap_err().to_string();
        assert!(long.len() < 400, "the error quotes a bounded part: {long}");
    }

    #[test]
    fn stored_names_print_without_their_control_characters() {
        assert_eq!(printable("ana\u{1b}[2J"), "ana\u{fffd}[2J");
        assert_eq!(printable("a\u{202e}b"), "a\u{fffd}b");
        assert_eq!(printable("José O'Neil"), "José O'Neil");
    }

    #[test]
    fn look_alikes_share_a_skeleton() {
        assert_eq!(skeleton("DR-KIM"), skeleton("dr-kim"));
        assert_eq!(skeleton("dr kim"), skeleton("Dr_Kim"));
        assert_ne!(skeleton("dr-kim"), skeleton("dr-kin"));
    }
}
