//! The named-expression file format, read and written in one place: the
//! shipped filters (`data/expressions.txt`), a run's hall of fame and
//! `tune -o` are all this format, and `filter --expr @FILE:NAME` reads it.
//!
//! ```text
//! # A header: the comment lines before the first blank line, when one
//! # comes before the first entry.
//!
//! # An entry's own notes: the comment lines since the entry before.
//! # measured: what `filterjit list` shows for it
//! # pipeline: atrous=5
//! # radius: 3
//! name = exp(-distance2(color))
//! alias = @name
//! ```
//!
//! `# pipeline: SPEC` and `# radius: R` are not notes: each states what
//! applies to every entry after it, until the next such line (`none` states
//! nothing). `name = @other` is `other`'s weight under a name of its own,
//! with its own pipeline and notes.

use std::fmt;

use crate::pipeline::FilterPipeline;

/// The line that states the filter pipeline of the entries after it.
pub const PIPELINE_PREFIX: &str = "# pipeline:";

/// The line that states the window radius of the entries after it.
pub const RADIUS_PREFIX: &str = "# radius:";

/// The note, in an entry's own block, that says what the entry was measured
/// to do on the public renders (`filterjit list` shows it).
pub const MEASURED_NOTE: &str = "measured:";

/// What a `# pipeline:` or `# radius:` line says to turn a stated value off.
const NONE: &str = "none";

/// A named-expression file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NamedFile {
    /// The comment lines that open the file, without their `# `.
    pub header: Vec<String>,
    pub entries: Vec<Entry>,
}

/// One `name = expression` line with what applies to it.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    pub name: String,
    /// The expression's text as written; `@other` names another entry.
    pub text: String,
    /// The comment lines of the entry's own block, without their `# `.
    pub notes: Vec<String>,
    /// The pipeline the last `# pipeline:` line before it states.
    pub pipeline: Option<FilterPipeline>,
    /// The radius the last `# radius:` line before it states.
    pub radius: Option<u32>,
}

impl Entry {
    /// An entry with nothing stated for it.
    pub fn new(name: impl Into<String>, text: impl Into<String>) -> Entry {
        Entry { name: name.into(), text: text.into(), notes: Vec::new(), pipeline: None, radius: None }
    }

    /// What its `# measured:` note says, if it has one.
    pub fn measured(&self) -> Option<&str> {
        self.notes.iter().find_map(|n| n.strip_prefix(MEASURED_NOTE)).map(str::trim)
    }

    /// The entry its text names (`name = @other`), if it is an alias.
    pub fn alias_of(&self) -> Option<&str> {
        alias_target(&self.text)
    }
}

/// A line of a named-expression file that cannot be read (1-based `line`).
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum NamedFileError {
    #[error("line {line}: {source}")]
    Pipeline { line: usize, source: crate::pipeline::PipelineError },
    #[error("line {line}: `{text}` is not a radius (a whole number of pixels, or `{NONE}`)")]
    Radius { line: usize, text: String },
    #[error("line {line}: `{text}` is neither a `#` comment nor `name = expression`")]
    NotAnEntry { line: usize, text: String },
    #[error("line {line}: `{text}` has no name before its `=`")]
    NoName { line: usize, text: String },
}

impl NamedFile {
    pub fn parse(text: &str) -> Result<NamedFile, NamedFileError> {
        let mut file = NamedFile::default();
        let (mut notes, mut pipeline, mut radius) = (Vec::new(), None, None);
        for (index, raw) in text.lines().enumerate() {
            let (line, trimmed) = (index + 1, raw.trim());
            if trimmed.is_empty() {
                // The block that opens the file, when a blank line closes it
                // before any entry, is the file's own, not the first entry's.
                if file.entries.is_empty() && file.header.is_empty() {
                    file.header = std::mem::take(&mut notes);
                }
            } else if let Some(spec) = trimmed.strip_prefix(PIPELINE_PREFIX).map(str::trim) {
                pipeline = match spec {
                    NONE => None,
                    _ => Some(spec.parse().map_err(|source| NamedFileError::Pipeline { line, source })?),
                };
            } else if let Some(spec) = trimmed.strip_prefix(RADIUS_PREFIX).map(str::trim) {
                radius = match spec {
                    NONE => None,
                    _ => Some(spec.parse().map_err(|_| NamedFileError::Radius { line, text: trimmed.into() })?),
                };
            } else if let Some(comment) = trimmed.strip_prefix('#') {
                notes.push(comment.strip_prefix(' ').unwrap_or(comment).to_string());
            } else {
                let (name, expr) =
                    trimmed.split_once('=').ok_or_else(|| NamedFileError::NotAnEntry { line, text: trimmed.into() })?;
                if name.trim().is_empty() {
                    return Err(NamedFileError::NoName { line, text: trimmed.into() });
                }
                file.entries.push(Entry {
                    name: name.trim().to_string(),
                    text: expr.trim().to_string(),
                    notes: std::mem::take(&mut notes),
                    pipeline,
                    radius,
                });
            }
        }
        Ok(file)
    }

    pub fn get(&self, name: &str) -> Option<&Entry> {
        self.entries.iter().find(|e| e.name == name)
    }

    /// The expression text entry `name` stands for, aliases followed: an
    /// alias of a name the file does not hold, or of itself through others,
    /// stays `@other` (it then fails to parse, which names it).
    pub fn expression(&self, name: &str) -> Option<&str> {
        let written = self.get(name)?.text.as_str();
        let mut text = written;
        // As many steps as entries: a longer chain is a cycle.
        for _ in 0..self.entries.len() {
            let Some(other) = alias_target(text) else { return Some(text) };
            match self.get(other) {
                Some(entry) => text = &entry.text,
                None => return Some(written),
            }
        }
        Some(written)
    }

    /// `(name, expression text)` of every entry in file order, aliases followed.
    pub fn resolved(&self) -> Vec<(&str, &str)> {
        self.entries.iter().map(|e| (e.name.as_str(), self.expression(&e.name).expect("its own entry"))).collect()
    }
}

/// The file as [`NamedFile::parse`] reads it back: a stated line is written
/// only where what applies changes.
impl fmt::Display for NamedFile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let comment = |f: &mut fmt::Formatter<'_>, note: &str| match note {
            "" => writeln!(f, "#"),
            _ => writeln!(f, "# {note}"),
        };
        for note in &self.header {
            comment(f, note)?;
        }
        if !self.header.is_empty() {
            writeln!(f)?;
        }
        let (mut pipeline, mut radius) = (None, None);
        for entry in &self.entries {
            for note in &entry.notes {
                comment(f, note)?;
            }
            if entry.pipeline != pipeline {
                match &entry.pipeline {
                    Some(p) => writeln!(f, "{PIPELINE_PREFIX} {p}")?,
                    None => writeln!(f, "{PIPELINE_PREFIX} {NONE}")?,
                }
                pipeline = entry.pipeline;
            }
            if entry.radius != radius {
                match entry.radius {
                    Some(r) => writeln!(f, "{RADIUS_PREFIX} {r}")?,
                    None => writeln!(f, "{RADIUS_PREFIX} {NONE}")?,
                }
                radius = entry.radius;
            }
            writeln!(f, "{} = {}", entry.name, entry.text)?;
        }
        Ok(())
    }
}

/// The entry an expression text `@name` stands for, if it is one.
fn alias_target(expr: &str) -> Option<&str> {
    expr.strip_prefix('@').map(str::trim)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_measured_note_belongs_to_its_own_entry_only() {
        let text = "# measured: A did this\na = 1\nb = 2\n# note\n# measured: C did that\n# more\nc = 3\n";
        let file = NamedFile::parse(text).unwrap();
        let measured = |n: &str| file.get(n).and_then(Entry::measured);
        assert_eq!(measured("a"), Some("A did this"));
        assert_eq!(measured("b"), None, "not carried over from the entry before");
        assert_eq!(measured("c"), Some("C did that"));
        assert_eq!(measured("d"), None);
    }

    #[test]
    fn an_alias_reads_as_its_entry_with_its_own_pipeline() {
        let text = "# pipeline: atrous=4\na = exp(-color)\n# pipeline: atrous3x3=4\nb = @a\nc = @b\nd = @missing\ne = @f\nf = @e\n";
        let file = NamedFile::parse(text).unwrap();
        let of = |n: &str| file.expression(n).unwrap();
        assert_eq!(of("b"), "exp(-color)");
        assert_eq!(of("c"), "exp(-color)", "through another alias");
        assert_eq!(of("d"), "@missing", "left to fail");
        assert_eq!(of("e"), "@f", "a cycle is left to fail");
        let pipeline = |n: &str| file.get(n).unwrap().pipeline.unwrap().to_string();
        assert_eq!((pipeline("a"), pipeline("b")), ("atrous=4".to_string(), "atrous3x3=4".to_string()));
        assert_eq!((file.get("a").unwrap().alias_of(), file.get("c").unwrap().alias_of()), (None, Some("b")));
    }

    #[test]
    fn stated_lines_apply_to_the_entries_after_them() {
        let text = "a = 1\n# pipeline: atrous=3\n# radius: 2\nb = 2\n# radius: 4\nc = 3\n# radius: none\nd = 4\n";
        let file = NamedFile::parse(text).unwrap();
        let stated = |n: &str| {
            let e = file.get(n).unwrap();
            (e.pipeline.map(|p| p.to_string()), e.radius)
        };
        assert_eq!(stated("a"), (None, None));
        assert_eq!(stated("b"), (Some("atrous=3".into()), Some(2)));
        assert_eq!(stated("c"), (Some("atrous=3".into()), Some(4)));
        assert_eq!(stated("d"), (Some("atrous=3".into()), None));
    }

    #[test]
    fn a_line_that_cannot_be_read_is_named_by_its_number() {
        let error = |text: &str| NamedFile::parse(text).unwrap_err().to_string();
        assert!(error("a = 1\n# radius: x\n").starts_with("line 2: `# radius: x` is not a radius"));
        assert!(error("a = 1\n\n# pipeline: atrous=zero\n").starts_with("line 3: pipeline `atrous=zero`"));
        assert!(error("a = 1\nexp(-color)\n").starts_with("line 2: `exp(-color)` is neither"));
        assert!(error(" = 1\n").starts_with("line 1: `= 1` has no name"));
    }

    #[test]
    fn what_is_written_reads_back_the_same() {
        let mut first = Entry::new("first", "exp(-distance2(color))");
        first.notes = vec!["fitness 0.1".into(), "".into(), "measured: well".into()];
        first.pipeline = Some("atrous=5".parse().unwrap());
        let mut second = Entry::new("second", "@first");
        second.pipeline = first.pipeline;
        second.radius = Some(3);
        let mut third = Entry::new("third", "1");
        third.pipeline = Some("atrous3x3=2".parse().unwrap());
        let file = NamedFile { header: vec!["A file of three".into()], entries: vec![first, second, third] };
        let text = file.to_string();
        assert_eq!(NamedFile::parse(&text).unwrap(), file, "{text}");
        assert_eq!(text.matches(PIPELINE_PREFIX).count(), 2, "stated where it changes only:\n{text}");
        assert!(text.contains("# radius: none\nthird"), "a radius turned off is said:\n{text}");
    }

    #[test]
    fn the_shipped_file_reads_back_the_same() {
        let shipped = NamedFile::parse(crate::corpus::EXPRESSIONS).unwrap();
        assert!(!shipped.header.is_empty() && shipped.entries.len() > 10);
        assert_eq!(NamedFile::parse(&shipped.to_string()).unwrap(), shipped);
    }
}
