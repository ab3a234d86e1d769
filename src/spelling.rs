//! The one rule for "did you mean": the known name nearest a misspelt one,
//! where it is near enough to be a slip. Shipped filters' names and
//! pipeline stages' answer by it.

/// The name of `names` nearest `asked` in spelling (Levenshtein, case
/// aside), where at most a third of its letters (at least one) are off.
pub fn nearest<'a>(asked: &str, names: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    let asked = asked.to_lowercase();
    names
        .into_iter()
        .map(|n| (strsim::levenshtein(&n.to_lowercase(), &asked), n))
        .filter(|(distance, n)| *distance <= (n.len() / 3).max(1))
        .min()
        .map(|(_, n)| n)
}

#[cfg(test)]
mod tests {
    use super::nearest;

    #[test]
    fn a_slip_finds_its_name_and_a_stranger_none() {
        let names = ["outliers", "trim", "keep"];
        assert_eq!(nearest("outlier", names), Some("outliers"));
        assert_eq!(nearest("TRIM", names), Some("trim"));
        assert_eq!(nearest("blur", names), None);
    }
}
