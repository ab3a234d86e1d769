//! Named expressions shipped with filterjit (`data/expressions.txt`), and
//! expression arguments resolved: a shipped name, a file's entry or a text.

use anyhow::{bail, Context};

use crate::named::{Entry, NamedFile, NamedFileError};

/// The shipped file's text.
pub const EXPRESSIONS: &str = include_str!("../data/expressions.txt");

/// The shipped file, read once.
pub fn shipped() -> &'static NamedFile {
    static SHIPPED: std::sync::OnceLock<NamedFile> = std::sync::OnceLock::new();
    SHIPPED.get_or_init(|| NamedFile::parse(EXPRESSIONS).expect("the shipped file reads (tested)"))
}

/// `(name, expression text)` pairs in file order, aliases followed.
pub fn named() -> Vec<(&'static str, &'static str)> {
    shipped().resolved()
}

/// The text of a shipped expression.
pub fn lookup(name: &str) -> Option<&'static str> {
    shipped().expression(name)
}

/// A resolved expression argument.
pub struct Resolved {
    pub name: Option<String>,
    pub expr: crate::lang::Expr,
    /// The pipeline the expression was stored with (a hall of fame states the run's).
    pub pipeline: Option<crate::pipeline::FilterPipeline>,
    /// The window radius it was stored with (a multi-objective run's front states each member's).
    pub radius: Option<u32>,
}

/// An expression argument: `@name` for a shipped expression, `@FILE[:NAME]`
/// for one in a file of `name = expression` lines (the first without
/// `:NAME`), or the expression's text. Returns the name, when it has one.
pub fn resolve(arg: &str) -> anyhow::Result<(Option<String>, crate::lang::Expr)> {
    let resolved = resolve_with_pipeline(arg)?;
    Ok((resolved.name, resolved.expr))
}

/// [`resolve`], with the pipeline the file states for the expression.
pub fn resolve_with_pipeline(arg: &str) -> anyhow::Result<Resolved> {
    let Some(reference) = arg.strip_prefix('@') else {
        return Ok(Resolved { name: None, expr: parse_checked(arg)?, pipeline: None, radius: None });
    };
    if let Some(entry) = shipped().get(reference) {
        return resolve_entry(shipped(), entry);
    }
    let Some((path, name)) = file_reference(reference) else {
        let path = reference.rsplit_once(':').map_or(reference, |(path, _)| path);
        if reference.contains(['/', '\\']) || path.ends_with(".txt") || path.ends_with(".json") {
            bail!("@{reference}: no file {path} (from {})", std::env::current_dir()?.display());
        }
        let names: Vec<String> = named().iter().map(|(n, _)| format!("@{n}")).collect();
        let hint = closest_name(reference).map(|n| format!(" (did you mean `@{n}`?)")).unwrap_or_default();
        bail!("no shipped expression `@{reference}`{hint}; there are: {}", names.join(", "))
    };
    let content = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let file = NamedFile::parse(&content).map_err(|e: NamedFileError| anyhow::anyhow!("{}: {e}", path.display()))?;
    let found = match &name {
        Some(n) => file.get(n),
        None => file.entries.first(),
    };
    let Some(entry) = found else {
        bail!("{} has no expression{}", path.display(), name.map(|n| format!(" named `{n}`")).unwrap_or_default())
    };
    resolve_entry(&file, entry).with_context(|| path.display().to_string())
}

/// Entry `entry` of `file`, its alias followed, parsed, with what the file states for it.
fn resolve_entry(file: &NamedFile, entry: &Entry) -> anyhow::Result<Resolved> {
    let text = file.expression(&entry.name).expect("its own entry");
    if text.starts_with('@') {
        bail!("`{} = {}` names an entry the file does not hold (or one that names it back)", entry.name, entry.text);
    }
    let expr = parse_checked(text).with_context(|| format!("`{}`", entry.name))?;
    Ok(Resolved { name: Some(entry.name.clone()), expr, pipeline: entry.pipeline, radius: entry.radius })
}

fn parse_checked(text: &str) -> anyhow::Result<crate::lang::Expr> {
    crate::lang::parse_expr(text).with_context(|| {
        // A shipped filter's name written without its `@` reads as an unknown name.
        let word = text.trim();
        match closest_name(word).filter(|_| word.chars().all(|c| c.is_ascii_alphanumeric())) {
            Some(name) => format!("invalid expression (a shipped filter is written with an @: `@{name}`)"),
            None => "invalid expression".to_string(),
        }
    })
}

/// The shipped name nearest `asked` in spelling, where it is a slip.
fn closest_name(asked: &str) -> Option<&'static str> {
    crate::spelling::nearest(asked, named().into_iter().map(|(n, _)| n))
}

/// `PATH` or `PATH:NAME` of an existing file of named expressions.
fn file_reference(reference: &str) -> Option<(std::path::PathBuf, Option<String>)> {
    let whole = std::path::PathBuf::from(reference);
    if whole.is_file() {
        return Some((whole, None));
    }
    let (path, name) = reference.rsplit_once(':')?;
    let path = std::path::PathBuf::from(path);
    path.is_file().then(|| (path, Some(name.to_string())))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_misspelt_name_is_answered_with_the_nearest_and_a_path_with_the_missing_file() {
        assert_eq!(closest_name("realtme"), Some("realtime"));
        assert_eq!(closest_name("REALTIME"), Some("realtime"));
        assert_eq!(closest_name("somethingElseEntirely"), None);
        let err = resolve("@realtme").unwrap_err().to_string();
        assert!(err.contains("no shipped expression `@realtme` (did you mean `@realtime`?)"), "{err}");
        let err = resolve("realtime").unwrap_err().to_string();
        assert!(err.contains("a shipped filter is written with an @: `@realtime`"), "{err}");
        // Not runs/evolve's: the README's main command, run first, writes that one.
        let err = resolve("@runs/no-such-run/hall_of_fame.txt:best").unwrap_err().to_string();
        assert!(err.contains("no file runs/no-such-run/hall_of_fame.txt"), "{err}");
        // A file named with an entry, in the folder it is run from.
        let err = resolve("@nope.txt:best").unwrap_err().to_string();
        assert!(err.contains("no file nope.txt"), "{err}");
    }
}
