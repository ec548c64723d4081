//! A model's notes ([`ModelNotes`]) as they cross the boundary: UTF-8 lines
//! `name<TAB>value`, the value as Rust prints an `f64` (which parses back
//! to the same number; `NaN`, `inf` and `-inf` included).

use voxflex_core::deformation::ModelNotes;

/// Bytes the host offers for a model's notes (far above the few hundred
/// a model writes; a model that needs more gets an error, not a cut list).
pub const HOST_CAPACITY: usize = 64 * 1024;

/// The lines for `notes`; fails on a name holding a tab or a line break,
/// naming it.
pub fn encode(notes: &ModelNotes) -> Result<String, String> {
    let mut text = String::new();
    for (name, value) in notes {
        if name.is_empty() || name.contains(['\t', '\n', '\r']) {
            return Err(format!(
                "note name {name:?} is empty or holds a tab or line break"
            ));
        }
        text.push_str(name);
        text.push('\t');
        text.push_str(&value.to_string());
        text.push('\n');
    }
    Ok(text)
}

/// The notes in `bytes`; fails on text that is not UTF-8 or a line that
/// is not `name<TAB>number`, naming the line.
pub fn decode(bytes: &[u8]) -> Result<ModelNotes, String> {
    let text = std::str::from_utf8(bytes).map_err(|e| format!("not UTF-8 ({e})"))?;
    let mut notes = ModelNotes::new();
    for (i, line) in text.lines().enumerate() {
        let parsed = line
            .split_once('\t')
            .filter(|(name, _)| !name.is_empty())
            .and_then(|(name, value)| Some((name, value.parse::<f64>().ok()?)));
        let Some((name, value)) = parsed else {
            return Err(format!("line {} is {line:?}, not `name<TAB>number`", i + 1));
        };
        notes.insert(name.to_owned(), value);
    }
    Ok(notes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn notes_round_trip_exactly_and_bad_text_is_named() {
        let mut notes = ModelNotes::new();
        notes.insert("bound_points".into(), 2_097_152.0);
        notes.insert("last_residual".into(), 1.234_567_890_123_456_7e-7);
        notes.insert("odd".into(), f64::NEG_INFINITY);
        notes.insert("tiny".into(), f64::MIN_POSITIVE);
        let back = decode(encode(&notes).unwrap().as_bytes()).unwrap();
        assert_eq!(back, notes);
        let nan: ModelNotes = [("n".to_owned(), f64::NAN)].into();
        assert!(decode(encode(&nan).unwrap().as_bytes()).unwrap()["n"].is_nan());

        let bad: ModelNotes = [("a\tb".to_owned(), 1.0)].into();
        assert!(encode(&bad).unwrap_err().contains("a\\tb"));
        let e = decode(b"steps\t3\nsubsteps three\n").unwrap_err();
        assert!(e.contains("line 2"), "{e}");
        assert!(decode(b"x\tfast\n").unwrap_err().contains("line 1"));
        assert!(decode(&[0xff, 0xfe]).unwrap_err().contains("UTF-8"));
        assert!(decode(b"").unwrap().is_empty());
    }
}
