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
