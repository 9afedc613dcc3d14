//! Names that become file or folder names (a study's results folder, an inline scene's
//! file): one safe character set, checked where the name enters, so that every path
//! built from a name stays inside the folder the user chose.

/// The characters a name may use, as the error messages state them.
pub const SAFE_NAME_CHARACTERS: &str = "ASCII letters, digits, - and _";

/// The longest name accepted, in characters (file systems allow 255 bytes per name).
pub const MAX_NAME_LEN: usize = 100;

/// `Ok` when `name` is non-blank, at most [`MAX_NAME_LEN`] characters and uses only
/// [`SAFE_NAME_CHARACTERS`]: it can then never be `.`, `..`, hidden, or contain a path
/// separator. Otherwise, the reason, ready to follow the field it came from.
pub fn check_name(name: &str) -> Result<(), String> {
    if name.trim().is_empty() {
        return Err(format!(
            "is blank; give a name of {SAFE_NAME_CHARACTERS} (it names a file or folder)"
        ));
    }
    if let Some(bad) = name
        .chars()
        .find(|&c| !(c.is_ascii_alphanumeric() || c == '-' || c == '_'))
    {
        return Err(format!(
            "\"{}\" has the character {bad:?}; use {SAFE_NAME_CHARACTERS} only (it names a file or folder)",
            name.escape_default()
        ));
    }
    if name.chars().count() > MAX_NAME_LEN {
        return Err(format!(
            "has {} characters; keep it to {MAX_NAME_LEN} (it names a file or folder)",
            name.chars().count()
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_that_could_leave_their_folder_are_refused() {
        for good in ["tiny", "seed-1000", "gas_2", "A"] {
            assert_eq!(check_name(good), Ok(()), "{good}");
        }
        let long = "x".repeat(MAX_NAME_LEN + 1);
        for bad in [
            "",
            "  ",
            "..",
            ".",
            ".hidden",
            "../../victim",
            "a/b",
            "a\\b",
            "/etc",
            "a b",
            "naïve",
            "nul\0",
            "new\nline",
            &long,
        ] {
            assert!(check_name(bad).is_err(), "{bad:?} was accepted");
        }
    }
}
