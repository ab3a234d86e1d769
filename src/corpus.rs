//! Named expressions shipped with filterjit (`data/expressions.txt`).

/// The shipped file's text.
pub const EXPRESSIONS: &str = include_str!("../data/expressions.txt");

/// `(name, expression text)` pairs in file order.
pub fn named() -> Vec<(&'static str, &'static str)> {
    parse_named(EXPRESSIONS)
}

/// Parse `name = expression` lines; `#` starts a comment line.
pub fn parse_named(text: &str) -> Vec<(&str, &str)> {
    text.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .filter_map(|l| l.split_once('='))
        .map(|(name, expr)| (name.trim(), expr.trim()))
        .collect()
}

/// The text of a shipped expression.
pub fn lookup(name: &str) -> Option<&'static str> {
    named().into_iter().find(|(n, _)| *n == name).map(|(_, e)| e)
}

/// An expression argument: `@name` for a shipped expression, `@FILE[:NAME]`
/// for one in a file of `name = expression` lines (the first without
/// `:NAME`), or the expression's text. Returns the name, when it has one.
pub fn resolve(arg: &str) -> anyhow::Result<(Option<String>, crate::Expr)> {
    use anyhow::{bail, Context};
    let (name, text) = match arg.strip_prefix('@') {
        Some(reference) if lookup(reference).is_none() && file_reference(reference).is_some() => {
            let (path, name) = file_reference(reference).expect("checked");
            let content = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
            let entries = parse_named(&content);
            let found = match &name {
                Some(n) => entries.iter().find(|(k, _)| k == n),
                None => entries.first(),
            };
            match found {
                Some((name, text)) => (name.to_string(), text.to_string()),
                None => bail!(
                    "{} has no expression{}",
                    path.display(),
                    name.map(|n| format!(" named `{n}`")).unwrap_or_default()
                ),
            }
        }
        Some(name) => match lookup(name) {
            Some(text) => (name.to_string(), text.to_string()),
            None => {
                let names: Vec<String> = named().iter().map(|(n, _)| format!("@{n}")).collect();
                bail!("no shipped expression `@{name}`; there are: {}", names.join(", "))
            }
        },
        None => return Ok((None, parse_checked(arg)?)),
    };
    Ok((Some(name), parse_checked(&text)?))
}

fn parse_checked(text: &str) -> anyhow::Result<crate::Expr> {
    crate::parse_expr(text).map_err(|e| anyhow::anyhow!("invalid expression:\n{e}"))
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
