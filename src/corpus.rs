//! Named expressions shipped with filterjit (`data/expressions.txt`).

/// The shipped file's text.
pub const EXPRESSIONS: &str = include_str!("../data/expressions.txt");

/// `(name, expression text)` pairs in file order.
pub fn named() -> Vec<(&'static str, &'static str)> {
    parse_named(EXPRESSIONS)
}

/// Parse `name = expression` lines; `#` starts a comment line. An entry
/// `name = @other` is another entry's expression under a name of its own
/// (its own pipeline and measurements: the same weight in another pipeline
/// is written once); it reads as that entry's text. An alias of a name the
/// text does not hold, or of itself through others, stays `@other`: it
/// fails to parse, and [`resolve`] names it.
pub fn parse_named<'t>(text: &'t str) -> Vec<(&'t str, &'t str)> {
    let raw = entries(text);
    let target = |mut expr: &'t str| -> Option<&'t str> {
        // As many steps as entries: a longer chain is a cycle.
        for _ in 0..raw.len() {
            let Some(other) = alias_target(expr) else { return Some(expr) };
            expr = raw.iter().find(|(n, _)| *n == other)?.1;
        }
        None
    };
    raw.iter().map(|&(name, expr)| (name, target(expr).unwrap_or(expr))).collect()
}

/// The `name = expression` lines of `text` as written, aliases unresolved.
fn entries(text: &str) -> Vec<(&str, &str)> {
    text.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .filter_map(|l| l.split_once('='))
        .map(|(name, expr)| (name.trim(), expr.trim()))
        .collect()
}

/// The entry whose expression entry `name` of `text` is written as (`name = @other`), if it is an alias.
pub fn alias_of<'t>(text: &'t str, name: &str) -> Option<&'t str> {
    entries(text).into_iter().find(|(n, _)| *n == name).and_then(|(_, expr)| alias_target(expr))
}

/// The entry an expression text `@name` stands for, if it is one.
fn alias_target(expr: &str) -> Option<&str> {
    expr.strip_prefix('@').map(str::trim)
}

/// The text of a shipped expression.
pub fn lookup(name: &str) -> Option<&'static str> {
    named().into_iter().find(|(n, _)| *n == name).map(|(_, e)| e)
}

/// The line that states the filter pipeline of the entries after it (until the next such line).
pub const PIPELINE_PREFIX: &str = "# pipeline:";

/// A named-expression file's line stating the window radius of the entries after it.
pub const RADIUS_PREFIX: &str = "# radius:";

/// The line, in an entry's comment block, that states what the entry was
/// measured to do on the public renders (`filterjit list` shows it).
pub const MEASURED_PREFIX: &str = "# measured:";

/// What the `# measured:` line of entry `name`'s own comment block says, if it has one.
pub fn measured_of<'t>(text: &'t str, name: &str) -> Option<&'t str> {
    let mut current = None;
    for line in text.lines().map(str::trim) {
        if let Some(said) = line.strip_prefix(MEASURED_PREFIX) {
            current = Some(said.trim());
        } else if !line.starts_with('#') {
            if line.split_once('=').is_some_and(|(n, _)| n.trim() == name) {
                return current;
            }
            // An entry ends the block its line belonged to.
            if !line.is_empty() {
                current = None;
            }
        }
    }
    None
}

/// What the last `PREFIX value` line before entry `name` says, if any: how
/// a named-expression file states what applies to the entries after it.
fn stated_for<'t>(text: &'t str, prefix: &str, name: &str) -> Option<&'t str> {
    let mut current = None;
    for line in text.lines().map(str::trim) {
        if let Some(spec) = line.strip_prefix(prefix) {
            current = Some(spec.trim());
        } else if !line.starts_with('#') && line.split_once('=').is_some_and(|(n, _)| n.trim() == name) {
            return current;
        }
    }
    None
}

/// The radius stated for entry `name`: the last `# radius: R` line before it, if any.
pub fn radius_of(text: &str, name: &str) -> Option<anyhow::Result<u32>> {
    stated_for(text, RADIUS_PREFIX, name).map(|spec| {
        spec.parse().map_err(|_| anyhow::anyhow!("`{RADIUS_PREFIX} {spec}` before `{name}` is not a radius"))
    })
}

/// The pipeline stated for entry `name` of a named-expression file: the last
/// `# pipeline: SPEC` line before it, if any.
pub fn pipeline_of(text: &str, name: &str) -> Option<anyhow::Result<crate::pipeline::FilterPipeline>> {
    stated_for(text, PIPELINE_PREFIX, name).map(|spec| spec.parse().map_err(anyhow::Error::from))
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
    use anyhow::{bail, Context};
    let mut radius = None;
    let (name, text, pipeline) = match arg.strip_prefix('@') {
        Some(reference) if lookup(reference).is_none() && file_reference(reference).is_some() => {
            let (path, name) = file_reference(reference).expect("checked");
            let content = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
            let entries = parse_named(&content);
            let found = match &name {
                Some(n) => entries.iter().find(|(k, _)| k == n),
                None => entries.first(),
            };
            match found {
                Some((name, text)) if alias_target(text).is_some() => bail!(
                    "{}: `{name} = {text}` names an entry the file does not hold (or one that names it back)",
                    path.display()
                ),
                Some((name, text)) => {
                    let pipeline = pipeline_of(&content, name)
                        .transpose()
                        .with_context(|| format!("{}: the pipeline of `{name}`", path.display()))?;
                    radius = radius_of(&content, name)
                        .transpose()
                        .with_context(|| format!("{}: the radius of `{name}`", path.display()))?;
                    let expr = parse_checked(text).with_context(|| format!("{}: `{name}`", path.display()))?;
                    return Ok(Resolved { name: Some(name.to_string()), expr, pipeline, radius });
                }
                None => bail!(
                    "{} has no expression{}",
                    path.display(),
                    name.map(|n| format!(" named `{n}`")).unwrap_or_default()
                ),
            }
        }
        Some(name) => match lookup(name) {
            Some(text) => {
                let pipeline = pipeline_of(EXPRESSIONS, name).transpose().expect("shipped pipelines parse");
                (name.to_string(), text.to_string(), pipeline)
            }
            None => {
                let names: Vec<String> = named().iter().map(|(n, _)| format!("@{n}")).collect();
                bail!("no shipped expression `@{name}`; there are: {}", names.join(", "))
            }
        },
        None => return Ok(Resolved { name: None, expr: parse_checked(arg)?, pipeline: None, radius: None }),
    };
    Ok(Resolved { name: Some(name), expr: parse_checked(&text)?, pipeline, radius })
}

fn parse_checked(text: &str) -> anyhow::Result<crate::lang::Expr> {
    crate::lang::parse_expr(text).map_err(|e| anyhow::anyhow!("invalid expression:\n{e}"))
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
    fn a_measured_line_belongs_to_its_own_entry_only() {
        let text = "# measured: A did this\na = 1\nb = 2\n# note\n# measured: C did that\n# more\nc = 3\n";
        assert_eq!(measured_of(text, "a"), Some("A did this"));
        assert_eq!(measured_of(text, "b"), None, "not carried over from the entry before");
        assert_eq!(measured_of(text, "c"), Some("C did that"));
        assert_eq!(measured_of(text, "d"), None);
    }

    #[test]
    fn an_alias_reads_as_its_entry_with_its_own_pipeline() {
        let text = "# pipeline: atrous=4\na = exp(-color)\n# pipeline: atrous3x3=4\nb = @a\nc = @b\nd = @missing\ne = @f\nf = @e\n";
        let entries = parse_named(text);
        let of = |n: &str| entries.iter().find(|(k, _)| *k == n).unwrap().1;
        assert_eq!(of("b"), "exp(-color)");
        assert_eq!(of("c"), "exp(-color)", "through another alias");
        assert_eq!(of("d"), "@missing", "left to fail");
        assert_eq!(of("e"), "@f", "a cycle is left to fail");
        assert_eq!(pipeline_of(text, "b").unwrap().unwrap().to_string(), "atrous3x3=4");
        assert_eq!(pipeline_of(text, "a").unwrap().unwrap().to_string(), "atrous=4");
        assert_eq!((alias_of(text, "a"), alias_of(text, "c")), (None, Some("b")));
    }

    #[test]
    fn stated_lines_apply_to_the_entries_after_them() {
        let text = "a = 1\n# pipeline: atrous=3\n# radius: 2\nb = 2\n# radius: 4\nc = 3\n# radius: x\nd = 4\n";
        assert!(pipeline_of(text, "a").is_none() && radius_of(text, "a").is_none());
        assert_eq!(radius_of(text, "b").unwrap().unwrap(), 2);
        assert_eq!(radius_of(text, "c").unwrap().unwrap(), 4);
        assert_eq!(pipeline_of(text, "c").unwrap().unwrap().to_string(), "atrous=3");
        let bad = radius_of(text, "d").unwrap().unwrap_err().to_string();
        assert!(bad.contains("`# radius: x` before `d`"), "{bad}");
        assert!(radius_of(text, "missing").is_none());
    }
}
